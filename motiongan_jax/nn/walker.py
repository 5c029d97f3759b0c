"""The small configs' G: the paper's network (nn/generator.py) with the departures around it.

`WalkerGenerator` keeps the paper's layers, parameter names and initial values (the stride head
is the one layer it adds, built after them) and changes only what goes into `Generator.network`
and what is done with its heads, in this order: the curve frame and gait phase on the way in;
root height, output prior, exact bones and the curve frame on the way out. docs/RESULTS.md
§5-§10 say why each was added and what it changed.

* Output prior (model.output_prior): the pose head adds the skeleton's rest
  pose (`rest_pose_R`, metres) and the root head the input curve velocity, so G starts as a rest
  pose gliding along the curve instead of a collapsed body standing still.
* Curve frame (model.g_frame = "curve"): G works in the walker's frame. Its input is each curve
  velocity seen from the previous one's heading, u[t] = R(-θ[t-1]) v[t]; its outputs are turned
  by the curve's smoothed heading (`trajectory.smooth_heading`) before the world curve velocity is
  added. Rotating the curve rotates the motion exactly, so G need not learn every direction
  the rotation augmentation draws.
* Exact bones (model.exact_bones): the pose head's bones keep their directions and take the
  skeleton's lengths, joint by joint from the root (`project_bones`), so no head of D can be
  answered with a stretched body.
* Gait phase (model.gait_phase): an equal-arc-length curve is nearly constant on straight
  stretches, so a convolutional G has nothing to hang a gait cycle on. With the option G keeps
  a clock in walked distance, φ[t] = φ0 + 2π Σ Δs / λ (`walked_phase`), λ(w) the style's
  stride length from `stride_head` (trained on strides measured on real clips,
  `losses.stride_loss`), φ0 random per training sample (`train.objectives.sample_draws`), 0 at generation.
* Stride that follows speed (model.walker.stride_speed): λ(w, v) = exp(a(w) + b(w) log v), so a
  style walked faster lengthens its stride as real walkers do (the data's relation,
  `data.gait_stats.stride_speed_slope`), instead of stepping faster at one stride.
  sin and cos of φ and 2φ (`gait_phase`) enter ec0_0, the skips e1 and e2 and dc1_0's input.
  A clock in distance stays right under the FPS augmentation.
* Root height (model.root_height): the root head's y channel is the root's height (up to a
  constant), and the y velocity G returns is its difference, so a small bias cannot drift the
  body off the floor along a long curve.
"""

from __future__ import annotations

import chex
import jax
import jax.numpy as jnp
from flax import nnx

from motiongan_jax.config import GFrame, WalkerConfig, choices
from motiongan_jax.motion import trajectory
from motiongan_jax.nn.generator import Generator
from motiongan_jax.nn.layers import Dense, zeros_init


def project_bones(pose_BxTxR: jax.Array, bones) -> jax.Array:
    """Root-relative rows whose bones keep the directions of `pose_BxTxR` and have the lengths of
    `bones` ((parent, child, length), joints numbered with the root as 0, parents first)."""
    b, t, r = pose_BxTxR.shape
    raw = jnp.concatenate([jnp.zeros((b, t, 1, 3), pose_BxTxR.dtype), pose_BxTxR.reshape(b, t, r // 3, 3)], axis=2)
    out = [raw[:, :, 0]] + [None] * (r // 3)
    for parent, child, length in sorted(bones, key=lambda x: x[1]):
        d = raw[:, :, child] - raw[:, :, parent]
        norm = jnp.sqrt(jnp.sum(d * d, axis=-1, keepdims=True) + 1e-12)
        out[child] = out[parent] + (length / norm) * d
    return jnp.stack(out[1:], axis=2).reshape(b, t, r)


PHASE_HARMONICS = 2  # φ and 2φ: a foot's cycle and the body's bounce, twice per stride
# Adam moves a parameter by about the learning rate per step, whatever its gradient; this gain on
# the stride head's output lets the stride reach its targets in hundreds of steps, not thousands.
STRIDE_GAIN = 10.0
PHASE_CHANNELS = 2 * PHASE_HARMONICS
# A stride that follows speed reads log speed centred here (metres per sample), so that the head's
# two outputs, level and slope, are not one and the same direction for Adam ...
STRIDE_STEP_CENTRE_M = 0.1
# ... and a sample slower than this (standing) counts as this: its stride stays finite.
STRIDE_MIN_STEP_M = 0.005


def walked_step(curve_vel_BxTx3: jax.Array) -> jax.Array:
    """B x T horizontal distance walked in each sample (metres, |v[t]| over the floor); 0 at t = 0,
    where v[0] duplicates v[1] and is not walked (as in trajectory.integrate)."""
    return jnp.linalg.norm(curve_vel_BxTx3[..., ::2], axis=-1).at[:, 0].set(0.0)


def walked_phase(curve_vel_BxTx3: jax.Array, stride: jax.Array, offset_B: jax.Array) -> jax.Array:
    """B x T gait phase (radians) φ[t] = φ0 + 2π Σ_{u<=t} Δs[u] / λ[u], Δs = `walked_step`, λ =
    `stride` metres (B: one per walk, or B x T: one per sample) and φ0 = `offset_B` radians."""
    b, t = curve_vel_BxTx3.shape[:2]
    chex.assert_shape(offset_B, (b,))
    chex.assert_shape(stride, (b,) if stride.ndim == 1 else (b, t))
    step_BxT = walked_step(curve_vel_BxTx3)
    if stride.ndim == 1:  # one stride: the distance walked over it
        return offset_B[:, None] + 2 * jnp.pi * jnp.cumsum(step_BxT, axis=1) / stride[:, None]
    return offset_B[:, None] + 2 * jnp.pi * jnp.cumsum(step_BxT / stride, axis=1)


def gait_phase(phase_BxT: jax.Array) -> jax.Array:
    """B x T x 4 channels of a phase: [sin φ, sin 2φ, cos φ, cos 2φ]."""
    k_H = jnp.arange(1, PHASE_HARMONICS + 1, dtype=jnp.float32)
    a_BxTxH = phase_BxT[..., None] * k_H
    return jnp.concatenate([jnp.sin(a_BxTxH), jnp.cos(a_BxTxH)], -1)


class WalkerGenerator(Generator):
    """The paper's G with the walker's parts (the module docstring), as `walker` (config.WalkerConfig)
    says: the skeleton's rest pose rows `rest_pose_R` (metres) for its output prior, and its bones
    `bones` ((parent, child, length in metres)) for exact bones. The other arguments are the paper's."""

    def __init__(self, num_rel_joints: int = 27, walker: WalkerConfig = WalkerConfig(), *,
                 rest_pose_R: tuple[float, ...] | None = None,
                 bones: tuple[tuple[int, int, float], ...] | None = None, rngs: nnx.Rngs, **paper):
        super().__init__(num_rel_joints, side_channels=PHASE_CHANNELS if walker.gait_phase else 0, rngs=rngs,
                         **paper)
        if rest_pose_R is not None and not walker.output_prior:
            raise ValueError("rest pose rows given, but the walker's output prior is off (walker.output_prior)")
        if (bones is None) == walker.exact_bones:
            raise ValueError("exact bones (walker.exact_bones) need the skeleton's bones, and only they")
        if rest_pose_R is not None and len(rest_pose_R) != self.num_rows:
            raise ValueError(f"rest_pose_R has {len(rest_pose_R)} rows, G makes {self.num_rows}")
        frame, gait_phase, root_height = walker.frame, walker.gait_phase, walker.root_height
        if walker.stride_speed and not gait_phase:
            raise ValueError("a stride that follows speed (walker.stride_speed) needs the gait clock "
                             "(walker.gait_phase)")
        residual_root = walker.output_prior
        # a tuple of floats: static (part of the graph definition), not a parameter
        self.rest_pose_R = None if rest_pose_R is None else tuple(float(v) for v in rest_pose_R)
        self.residual_root = bool(residual_root)
        if frame not in choices(GFrame):
            raise ValueError(f"frame must be one of {choices(GFrame)}, got {frame!r}")
        self.frame = frame
        if bones is not None:
            bones = tuple((int(a), int(b), float(length)) for a, b, length in bones)
            if sorted(b for _, b, _ in bones) != list(range(1, num_rel_joints + 1)) or any(a >= b for a, b, _ in bones):
                raise ValueError("bones must be (parent, child, length) with each joint 1..J a child once, "
                                 "parents before children")
        self.bones = bones  # static: part of the graph definition
        self.gait_phase = bool(gait_phase)  # static
        self.root_height = bool(root_height)
        self.stride_speed = bool(walker.stride_speed)  # static
        # log stride length (metres) of the style (and its slope in log speed); zero init: 1 m
        # strides until trained
        self.stride_head = (Dense(self.w_dim, 2 if self.stride_speed else 1, kernel_init=zeros_init,
                                  bias_init=zeros_init, rngs=rngs) if self.gait_phase else None)

    @property
    def has_gait_phase(self) -> bool:
        return self.gait_phase

    def log_stride(self, w_BxD: jax.Array, curve_vel_BxTx3: jax.Array | None = None) -> jax.Array:
        """log of the stride length in metres, for a G with a gait phase: λ(w) (B), or, for a
        stride that follows speed (walker.stride_speed), λ(w, v) at each sample's walked step
        along `curve_vel_BxTx3` (B x T; log λ = a(w) + b(w) log(v / STRIDE_STEP_CENTRE_M))."""
        if self.stride_head is None:
            raise ValueError("this G has no gait phase (model.gait_phase)")
        head_BxK = STRIDE_GAIN * self.stride_head(w_BxD)
        if not self.stride_speed:
            return head_BxK[:, 0]
        if curve_vel_BxTx3 is None:
            raise ValueError("this G's stride follows speed (walker.stride_speed): give the curve velocities")
        log_step_BxT = jnp.log(jnp.maximum(walked_step(curve_vel_BxTx3), STRIDE_MIN_STEP_M) / STRIDE_STEP_CENTRE_M)
        return head_BxK[:, :1] + head_BxK[:, 1:2] * log_step_BxT

    def walked_phase(self, curve_vel_BxTx3: jax.Array, w_BxD: jax.Array,
                     phase_offset_B: jax.Array | None = None) -> jax.Array:
        """B x T: the phase this G walks a curve with (`walked_phase` at its stride, `log_stride`,
        offset default 0)."""
        b = curve_vel_BxTx3.shape[0]
        offset_B = jnp.zeros((b,), jnp.float32) if phase_offset_B is None else phase_offset_B
        # the stride is learned from measured strides alone (losses.stride_loss): the GAN's
        # gradient through sin(2π s / λ) is periodic in 1/λ and would only add noise
        stride = jax.lax.stop_gradient(jnp.exp(self.log_stride(w_BxD, curve_vel_BxTx3)))
        return walked_phase(curve_vel_BxTx3, stride, offset_B)

    def __call__(self, curve_vel_BxTx3: jax.Array, w_BxD: jax.Array, phase_offset_B: jax.Array | None = None,
                 phase_BxT: jax.Array | None = None) -> tuple[jax.Array, jax.Array]:
        """(root_vel_BxTx3, pose_BxTxR). A G with a gait phase walks with `self.walked_phase`
        (`phase_offset_B` radians, default 0), or with the given `phase_BxT` (radians: a real
        window's measured phase, for reconstruction)."""
        b, t = curve_vel_BxTx3.shape[:2]
        vel_in = curve_vel_BxTx3
        if self.frame == "curve":
            theta_BxT = trajectory.heading(curve_vel_BxTx3)
            vel_in = trajectory.rotate_y(curve_vel_BxTx3, -jnp.concatenate([theta_BxT[:, :1], theta_BxT[:, :-1]], 1))
        x = (vel_in / self.length_unit)[..., None]  # B x T x 3 x 1
        phase_BxTx1xP = None
        if self.gait_phase:
            if phase_BxT is None:
                phase_BxT = self.walked_phase(curve_vel_BxTx3, w_BxD, phase_offset_B)
            phase_BxTx1xP = gait_phase(phase_BxT)[:, :, None, :].astype(self.compute_dtype)
            x = jnp.concatenate([x, jnp.broadcast_to(phase_BxTx1xP, (b, t, 3, PHASE_CHANNELS))], -1)
        elif phase_offset_B is not None or phase_BxT is not None:
            raise ValueError("a phase given, but this G has no gait phase (model.gait_phase)")

        root_vel_BxTx3, pose_BxTxR = self.network(x, w_BxD, phase_BxTx1xP)

        if self.root_height:  # y is a height: its difference is the velocity (v[0] = v[1])
            h_BxT = root_vel_BxTx3[..., 1]
            dh_BxT = h_BxT[:, 1:] - h_BxT[:, :-1]
            root_vel_BxTx3 = root_vel_BxTx3.at[..., 1].set(jnp.concatenate([dh_BxT[:, :1], dh_BxT], 1))
        if self.rest_pose_R is not None:
            pose_BxTxR = pose_BxTxR + jnp.asarray(self.rest_pose_R, pose_BxTxR.dtype)
        if self.bones is not None:
            pose_BxTxR = project_bones(pose_BxTxR, self.bones)
        if self.frame == "curve":
            out_BxT = trajectory.smooth_heading(curve_vel_BxTx3)
            root_vel_BxTx3 = trajectory.rotate_y(root_vel_BxTx3, out_BxT)
            pose_BxTxR = trajectory.rotate_rows_y(pose_BxTxR, out_BxT)
        if self.residual_root:
            root_vel_BxTx3 = root_vel_BxTx3 + curve_vel_BxTx3
        return root_vel_BxTx3, pose_BxTxR
