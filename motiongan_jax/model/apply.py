"""A model's G and D, and G run on curves and style codes: the one API of every user of a model.

`model` is anything holding G's graph definition and parameters as `g_def` and `g_params` (and D's
as `d_def`, `d_params`, `d_sn_state`): a train state, or one rebuilt from a checkpoint or an
export. To run other G parameters (e.g. the moving average), pass `model.replace(g_params=...)`.

G on a curve is `g_apply` (jitted; traced code calls it directly) or `apply_code` (the same, for
arrays from anywhere: it takes G's part of the model and numpy inputs, so that every caller shares
one compiled program per shape). A G with a gait clock walks at phase φ0 + 2π s / λ(w)
(`walked_phase`); generation asks the model for that clock, never recomputes it.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from flax import nnx

from motiongan_jax.motion import trajectory
from motiongan_jax.nn import Discriminator, Generator


def generator(model, g_params=None) -> Generator:
    """G as an NNX module (a fresh copy; mutating it does not touch the model)."""
    return nnx.merge(model.g_def, model.g_params if g_params is None else g_params, copy=True)


def discriminator(model) -> Discriminator:
    return nnx.merge(model.d_def, model.d_params, model.d_sn_state, copy=True)


def generator_state(model):
    """The model with only what G needs (its `g_params`), so that jitted inference neither copies
    nor keys on D, the optimisers or the moving average."""
    return model.replace(d_params=None, d_sn_state=None, opt_g_state=None, opt_d_state=None, g_ema_params=None)


def has_gait_phase(model) -> bool:
    """Whether the model's G keeps a gait clock (model.gait_phase), as its module says."""
    return bool(generator(model).has_gait_phase)


def z_dim(model) -> int:
    return int(generator(model).latent.z_dim)


def _style_codes(model, labels_B, z_BxZ):
    return generator(model).style(labels_B, z_BxZ)


_style_codes_jit = jax.jit(_style_codes)


def style_codes(model, labels_B, z_BxZ=None) -> jax.Array:
    """Style codes w (B x w_dim) of the Latent Transform; z defaults to zeros, as the reference's
    inference tools use. Traceable (under jit or grad it simply traces)."""
    labels_B = jnp.asarray(labels_B, jnp.int32)
    z = jnp.zeros((labels_B.shape[0], z_dim(model)), jnp.float32) if z_BxZ is None else z_BxZ
    if isinstance(labels_B, jax.core.Tracer) or isinstance(z, jax.core.Tracer):
        return _style_codes(model, labels_B, z)
    return _style_codes_jit(generator_state(model), labels_B, z)


def _f32(a):
    """numpy float32 (None stays None): the callers' arrays, whatever made them, share one compiled
    program per shape."""
    return None if a is None else np.asarray(a, np.float32)


@jax.jit
def g_apply(model, curve_vel_BxTx3, w_BxD, phase_offset_B=None, phase_BxT=None):
    """(root_vel_BxTx3, pose_BxTxR) of G for style codes w along curve velocities (metres per
    sample). A G with a gait clock starts at `phase_offset_B` (radians; None: 0), or walks at the
    given phase `phase_BxT` (radians: e.g. a real motion's measured phase) instead of its clock."""
    return generator(model)(curve_vel_BxTx3, w_BxD, phase_offset_B, phase_BxT)


def apply_code(model, curve_vel_BxTx3, w_BxD, phase_offset_B=None, phase_BxT=None):
    """`g_apply` on G's part of the model, inputs through numpy (arrays from any computation
    share one compiled program per shape)."""
    return g_apply(generator_state(model), _f32(curve_vel_BxTx3), _f32(w_BxD), _f32(phase_offset_B), _f32(phase_BxT))


@jax.jit
def _stride_m(model, w_BxD, curve_vel_BxTx3):
    return jnp.exp(generator(model).log_stride(w_BxD, curve_vel_BxTx3))


def stride_m(model, w_BxD, curve_vel_BxTx3=None) -> np.ndarray:
    """The stride length (metres) of each style code, for a G with a gait clock: λ(w) (B), or for a
    stride that follows speed (model.walker.stride_speed) λ(w, v) at each sample of the curve
    velocities (B x T)."""
    return np.asarray(_stride_m(generator_state(model), _f32(w_BxD), _f32(curve_vel_BxTx3)))


@jax.jit
def _walked_phase(model, curve_vel_BxTx3, w_BxD, phase_offset_B):
    return generator(model).walked_phase(curve_vel_BxTx3, w_BxD, phase_offset_B)


def walked_phase(model, curve_vel_BxTx3, w_BxD, phase_offset_B=None) -> np.ndarray:
    """B x T: the gait phase (radians) G walks the curve velocities with, from `phase_offset_B`
    (None: 0): G's own clock (nn.walker.walked_phase at its stride, `stride_m`)."""
    b = len(w_BxD)
    offset = np.zeros(b, np.float32) if phase_offset_B is None else np.asarray(phase_offset_B, np.float32)
    return np.asarray(_walked_phase(generator_state(model), np.asarray(curve_vel_BxTx3, np.float32),
                                    np.asarray(w_BxD, np.float32), offset))


@jax.jit
def _curve_clock(model, curve_BxTx3, w_BxD):
    vel = trajectory.velocity(curve_BxTx3)
    g = generator(model)
    if not g.has_gait_phase:
        return vel, None
    return vel, g.walked_phase(vel, w_BxD, jnp.zeros(curve_BxTx3.shape[0], jnp.float32))


def curve_clock(model, curve_BxTx3, w_BxD) -> tuple[np.ndarray, np.ndarray | None]:
    """(G's input: the velocities of curve points B x T x 3, `walked_phase` from 0 on them, B x T,
    or None for a G without a clock) in one compiled call: a streamed window's inputs, which
    would otherwise cost three dispatches and the velocity's operations one by one."""
    vel, phase = _curve_clock(generator_state(model), _f32(curve_BxTx3), _f32(w_BxD))
    return np.asarray(vel), None if phase is None else np.asarray(phase)
