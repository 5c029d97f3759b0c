"""G and D rebuilt from a train state, and G run with given parameters (previews, generation,
analysis, evaluation).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import nnx

from motiongan_jax.nn import Discriminator, Generator
from motiongan_jax.train.state import TrainState


def generator(state: TrainState, g_params=None) -> Generator:
    """G as an NNX module (a fresh copy; mutating it does not touch the state)."""
    return nnx.merge(state.g_def, state.g_params if g_params is None else g_params, copy=True)


def discriminator(state: TrainState) -> Discriminator:
    return nnx.merge(state.d_def, state.d_params, state.d_sn_state, copy=True)


def generator_state(state: TrainState) -> TrainState:
    """The state with only what G needs (its `g_params`), so that jitted inference neither copies
    nor keys on D, the optimisers or the moving average."""
    return state.replace(d_params=None, d_sn_state=None, opt_g_state=None, opt_d_state=None, g_ema_params=None)


def _zeros_z(state: TrainState, batch: int) -> jax.Array:
    return jnp.zeros((batch, generator_z_dim(state)), jnp.float32)


def has_gait_phase(state: TrainState) -> bool:
    """Whether the state's G keeps a gait phase (model.gait_phase): it then has a stride head."""
    return "stride_head" in state.g_params


def generator_z_dim(state: TrainState) -> int:
    return int(state.g_params["latent"]["embed"].shape[-1])


def latent_w(state: TrainState, labels_B: jax.Array, z_BxZ: jax.Array | None = None) -> jax.Array:
    """Style code w (B x w_dim); z defaults to zeros, as the reference's inference tools use."""
    labels_B = jnp.asarray(labels_B, jnp.int32)
    z = _zeros_z(state, labels_B.shape[0]) if z_BxZ is None else z_BxZ
    return generator(state).style(labels_B, z)


def generator_apply(state: TrainState, curve_vel_BxTx3: jax.Array, labels_B: jax.Array | None = None,
                    z_BxZ: jax.Array | None = None, *, w_BxD: jax.Array | None = None,
                    phase_offset_B: jax.Array | None = None):
    """(root_vel_BxTx3, pose_BxTxR) from G with the state's parameters.

    Give either labels (and optionally z, default zeros) or a style code `w_BxD` directly. To run
    other parameters, pass `state.replace(g_params=...)`. A G with a gait phase takes its phase
    offsets (radians, B) from `phase_offset_B`, default 0.
    """
    g = generator(state)
    if w_BxD is None:
        if labels_B is None:
            raise ValueError("generator_apply needs labels_B or w_BxD")
        labels_B = jnp.asarray(labels_B, jnp.int32)
        z = _zeros_z(state, labels_B.shape[0]) if z_BxZ is None else z_BxZ
        w_BxD = g.style(labels_B, z)
    if phase_offset_B is None:
        return g(curve_vel_BxTx3, w_BxD)
    if not getattr(g, "gait_phase", False):
        raise ValueError("a phase given, but this G has no gait phase (model.gait_phase)")
    return g(curve_vel_BxTx3, w_BxD, phase_offset_B)
