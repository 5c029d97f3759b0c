"""Generator G (docs/DESIGN.md §3.4): curve velocity + style code w -> root velocity and pose rows.

Layout NHWC = (B, T, W, C). The input velocity B x T x 3 enters as one channel over 3 width
rows. Every block is conv -> LeakyReLU -> AdaIN(w); the same w feeds all 14 AdaINs. The two
heads have neither. Skips are taken after AdaIN and tiled along the width, encoder first.
The reference's unused `dc0_1` is not built. c = `base_channels` (model.top), kt the time kernel.

    ec0_0  conv kt×1                 1 -> c    T     × 3
    ec1_0  conv kt×3 /(2,3)          c -> 2c   T/2   × 1
    ec1_1  conv kt×1                2c -> 2c   T/2   × 1   e1
    ec2_0  conv kt×1 /(2,1)         2c -> 4c   T/4   × 1
    ec2_1  conv kt×1                4c -> 4c   T/4   × 1   e2
    ec3_0  conv kt×1 /(2,1)         4c -> 8c   T/8   × 1
    ec3_1  conv kt×1                8c -> 8c   T/8   × 1
    dc_bottom tconv kt×3            8c -> 8c   T/8   × 3,  up x2 in time
    dc3_1  tconv kt×3               8c -> 8c   T/4   × 9
    dc3_0  conv kt×3 (w-reflect 1)  8c -> 4c   T/4   × 9   d2; [e2 tiled, d2], up
    dc2_1  tconv kt×3               8c -> 4c   T/2   × 27
    dc2_0  conv kt×3 (w-reflect 1)  4c -> 2c   T/2   × 27  d1; keep J columns; [e1 tiled, d1], up
    dc1_1  tconv kt×3               4c -> 2c   T     × 3J
    dc1_0  conv kt×3 (w-reflect 1)  2c -> c    T     × 3J  d0
    c_traj conv kt×3J                c -> 3    T     × 1   -> root velocity B x T x 3
    dc0_0  conv kt×1                 c -> 1    T     × 3J  -> pose B x T x 3J

Fewer than 27 joints (Bandai has 20). The decoder's width goes 1 -> 3 -> 9 -> 27, one column per
joint slot at the 27-column stage. For J < 27 joints we keep the first J columns of d1 (after
dc2_0's AdaIN, before the skip concat), so the per-coordinate stage (dc1_1, dc1_0, both heads)
works on exactly 3J rows and c_traj's kernel is kt × 3J. Joint k ≥ 1 still owns the column that
its position in the row layout gives it in the paper's grouping. For J = 27 the crop is the
identity and the network is the paper's. J > 27 would need another width stage: rejected.

Options of the small configs (the paper's G has none of them; docs/RESULTS.md §5-§10 says
why each was added and what it changed). None adds parameters except the stride head.

* Output prior (model.output_prior): the pose head adds the skeleton's rest
  pose (`rest_pose_R`, metres) and the root head the input curve velocity, so G starts as a rest
  pose gliding along the curve instead of a collapsed body standing still.
* Curve frame (model.g_frame = "curve"): G works in the walker's frame. Its input is each curve
  velocity seen from the previous one's heading, u[t] = R(-θ[t-1]) v[t]; its outputs are turned
  by the curve's smoothed heading (`curves.smooth_heading`) before the world curve velocity is
  added. Rotating the curve rotates the motion exactly, so G need not learn every direction
  the rotation augmentation draws.
* Exact bones (model.exact_bones): the pose head's bones keep their directions and take the
  skeleton's lengths, joint by joint from the root (`project_bones`), so no head of D can be
  answered with a stretched body.
* Gait phase (model.gait_phase): an equal-arc-length curve is nearly constant on straight
  stretches, so a convolutional G has nothing to hang a gait cycle on. With the option G keeps
  a clock in walked distance, φ[t] = φ0 + 2π s[t] / λ(w) (`walked_phase`), λ(w) the style's
  stride length from `stride_head` (trained on strides measured on real clips,
  `losses.stride_loss`), φ0 random per training sample (`train.objectives.sample_phase`), 0 at generation.
  sin and cos of φ and 2φ (`gait_phase`) enter ec0_0, the skips e1 and e2 and dc1_0's input.
  A clock in distance stays right under the FPS augmentation.
* Root height (model.root_height): the root head's y channel is the root's height (up to a
  constant), and the y velocity G returns is its difference, so a small bias cannot drift the
  body off the floor along a long curve.

Init: convs and tconvs N(0, 0.02²), zero bias (DESIGN.md §3.1); AdaIN and the Latent Transform as in
their modules. The Latent Transform lives inside G (it is trained with G's optimiser).

`impl="fast"` (default) computes the same function with less work (docs/PERFORMANCE.md):
the tiled skips' share of dc2_1 / dc1_1 is computed on one column and broadcast, and each
"upsample x2 then tconv" is one polyphase correlation of the un-upsampled input
(`ConvTranspose.upsampled`); the convolutions use `conv.conv2d`'s CPU schedule. `impl="xla"`
is the straightforward form above (tile, concatenate, upsample, lax.conv), kept as the reference
that tests/test_fast_equals_reference.py compares against. Parameters are identical.

`compute_dtype="bfloat16"` runs the convolutions and activations in bf16 (mixed precision, for
GPUs); parameters, AdaIN statistics, the Latent Transform and the outputs stay float32.
"""

from __future__ import annotations

import chex
import jax
import jax.numpy as jnp
from flax import nnx

from motiongan_jax.config import GFrame, LatentInit, choices
from motiongan_jax.data import curves
from motiongan_jax.nn.latent import LatentTransform
from motiongan_jax.nn.layers import (
    AdaIN,
    Conv,
    ConvTranspose,
    Dense,
    leaky_relu,
    upsample_time2,
    zeros_init,
)

MAX_JOINTS = 27


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


def walked_phase(curve_vel_BxTx3: jax.Array, stride_B: jax.Array, offset_B: jax.Array) -> jax.Array:
    """B x T gait phase (radians) φ[t] = φ0 + 2π s[t] / λ, where s[t] is the horizontal distance
    walked up to sample t (the sum of |v[1..t]|, metres; v[0] duplicates v[1] and is not walked, as
    in curves.integrate), λ = `stride_B` metres and φ0 = `offset_B` radians."""
    b = curve_vel_BxTx3.shape[0]
    chex.assert_shape((stride_B, offset_B), (b,))
    step_BxT = jnp.linalg.norm(curve_vel_BxTx3[..., ::2], axis=-1).at[:, 0].set(0.0)
    return offset_B[:, None] + 2 * jnp.pi * jnp.cumsum(step_BxT, axis=1) / stride_B[:, None]


def gait_phase(phase_BxT: jax.Array) -> jax.Array:
    """B x T x 4 channels of a phase: [sin φ, sin 2φ, cos φ, cos 2φ]."""
    k_H = jnp.arange(1, PHASE_HARMONICS + 1, dtype=jnp.float32)
    a_BxTxH = phase_BxT[..., None] * k_H
    return jnp.concatenate([jnp.sin(a_BxTxH), jnp.cos(a_BxTxH)], -1)


class StyledBlock(nnx.Module):
    """conv (or tconv) -> LeakyReLU -> AdaIN(w)."""

    def __init__(self, conv: nnx.Module, channels: int, w_dim: int, *, rngs: nnx.Rngs):
        self.conv = conv
        self.adain = AdaIN(channels, w_dim, rngs=rngs)

    def activate(self, h_BxTxWxC: jax.Array, w_BxD: jax.Array) -> jax.Array:
        """LeakyReLU then AdaIN(w) of the conv's output."""
        return self.adain(leaky_relu(h_BxTxWxC), w_BxD)

    def __call__(self, x_BxTxWxC: jax.Array, w_BxD: jax.Array) -> jax.Array:
        return self.activate(self.conv(x_BxTxWxC), w_BxD)


def _tile_w(x_BxTx1xC: jax.Array, width: int) -> jax.Array:
    return jnp.broadcast_to(x_BxTx1xC, (x_BxTx1xC.shape[0], x_BxTx1xC.shape[1], width, x_BxTx1xC.shape[3]))


class Generator(nnx.Module):
    # Names of the 14 AdaIN-carrying blocks in forward order.
    BLOCKS = ("ec0_0", "ec1_0", "ec1_1", "ec2_0", "ec2_1", "ec3_0", "ec3_1",
              "dc_bottom", "dc3_1", "dc3_0", "dc2_1", "dc2_0", "dc1_1", "dc1_0")

    def __init__(
        self,
        num_rel_joints: int = 27,
        *,
        base_channels: int = 64,
        kt: int = 5,
        w_dim: int = 64,
        z_dim: int = 64,
        num_styles: int,
        latent_init: LatentInit = "paper",
        length_unit: float = 1.0,
        rest_pose_R: tuple[float, ...] | None = None,
        residual_root: bool = False,
        frame: GFrame = "world",
        bones: tuple[tuple[int, int, float], ...] | None = None,
        gait_phase: bool = False,
        root_height: bool = False,
        impl: str = "fast",
        compute_dtype: str = "float32",
        rngs: nnx.Rngs,
    ):
        if not 1 <= num_rel_joints <= MAX_JOINTS:
            raise ValueError(f"num_rel_joints must be in 1..{MAX_JOINTS}, got {num_rel_joints}")
        if kt % 2 != 1:
            raise ValueError(f"the time kernel kt must be odd, got {kt}")
        self.num_rel_joints = num_rel_joints
        self.num_rows = 3 * num_rel_joints
        self.impl = impl
        # activations' dtype; parameters, normalisation statistics and outputs stay float32
        self.compute_dtype = str(jnp.dtype(compute_dtype))
        # inputs and outputs are in metres; the layers work in this unit (the paper's data unit)
        self.length_unit = float(length_unit)
        self.w_dim = w_dim
        self.z_dim = z_dim
        if rest_pose_R is not None and len(rest_pose_R) != self.num_rows:
            raise ValueError(f"rest_pose_R has {len(rest_pose_R)} rows, G makes {self.num_rows}")
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
        self.latent = LatentTransform(num_styles, z_dim=z_dim, w_dim=w_dim, init=latent_init, rngs=rngs)

        def conv(cin, cout, kwidth=1, stride=(1, 1), pad_w=0):
            return StyledBlock(Conv(cin, cout, (kt, kwidth), stride, pad_w=pad_w, impl=impl, rngs=rngs),
                               cout, w_dim, rngs=rngs)

        def tconv(cin, cout):
            return StyledBlock(ConvTranspose(cin, cout, (kt, 3), impl=impl, rngs=rngs), cout, w_dim, rngs=rngs)

        c = base_channels
        t1, t2, t4, t8 = c, 2 * c, 4 * c, 8 * c
        ph = PHASE_CHANNELS if self.gait_phase else 0
        self.ec0_0 = conv(1 + ph, t1)
        self.ec1_0 = conv(t1, t2, 3, (2, 3))
        self.ec1_1 = conv(t2, t2)
        self.ec2_0 = conv(t2, t4, 1, (2, 1))
        self.ec2_1 = conv(t4, t4)
        self.ec3_0 = conv(t4, t8, 1, (2, 1))
        self.ec3_1 = conv(t8, t8)
        self.dc_bottom = tconv(t8, t8)
        self.dc3_1 = tconv(t8, t8)
        self.dc3_0 = conv(t8, t4, 3, pad_w=1)
        self.dc2_1 = tconv(t4 + ph + t4, t4)
        self.dc2_0 = conv(t4, t2, 3, pad_w=1)
        self.dc1_1 = tconv(t2 + ph + t2, t2)
        self.dc1_0 = conv(t2 + ph, t1, 3, pad_w=1)
        self.c_traj = Conv(t1, 3, (kt, self.num_rows), impl=impl, rngs=rngs)
        self.dc0_0 = Conv(t1, 1, (kt, 1), impl=impl, rngs=rngs)
        # log stride length (metres) of the style; zero init: 1 m strides until trained
        self.stride_head = (Dense(w_dim, 1, kernel_init=zeros_init, bias_init=zeros_init, rngs=rngs)
                            if self.gait_phase else None)

    def style(self, labels_B: jax.Array, z_BxZ: jax.Array) -> jax.Array:
        """The style code w (B x w_dim) of the Latent Transform."""
        return self.latent(labels_B, z_BxZ)

    def log_stride(self, w_BxD: jax.Array) -> jax.Array:
        """log of the stride length λ(w) in metres (B), for a G with a gait phase."""
        if self.stride_head is None:
            raise ValueError("this G has no gait phase (model.gait_phase)")
        return STRIDE_GAIN * self.stride_head(w_BxD)[:, 0]

    def adain_styles(self, w_BxD: jax.Array) -> dict[str, tuple[jax.Array, jax.Array]]:
        """(scale, bias) of every AdaIN layer for a style code, keyed by block name."""
        return {name: getattr(self, name).adain.style(w_BxD) for name in self.BLOCKS}

    def walked_phase(self, curve_vel_BxTx3: jax.Array, w_BxD: jax.Array,
                     phase_offset_B: jax.Array | None = None) -> jax.Array:
        """B x T: the phase this G walks a curve with (`walked_phase` at its stride λ(w), offset
        default 0)."""
        b = curve_vel_BxTx3.shape[0]
        offset_B = jnp.zeros((b,), jnp.float32) if phase_offset_B is None else phase_offset_B
        # the stride is learned from measured strides alone (losses.stride_loss): the GAN's
        # gradient through sin(2π s / λ) is periodic in 1/λ and would only add noise
        stride_B = jax.lax.stop_gradient(jnp.exp(self.log_stride(w_BxD)))
        return walked_phase(curve_vel_BxTx3, stride_B, offset_B)

    def __call__(self, curve_vel_BxTx3: jax.Array, w_BxD: jax.Array, phase_offset_B: jax.Array | None = None,
                 phase_BxT: jax.Array | None = None) -> tuple[jax.Array, jax.Array]:
        """(root_vel_BxTx3, pose_BxTxR). A G with a gait phase walks with `self.walked_phase`
        (`phase_offset_B` radians, default 0), or with the given `phase_BxT` (radians: a real
        window's measured phase, for reconstruction)."""
        t = curve_vel_BxTx3.shape[1]
        if t % 8:
            raise ValueError(f"G needs T divisible by 8, got T={t}")
        w = w_BxD

        def block(name, x):
            with jax.named_scope(name):  # names the ops in profiles (bench/bench_profile.py)
                return getattr(self, name)(x, w)

        def up_block(name, d, e=None):
            """block(name, upsample_time2(concat[tile(e), d])), the fast way or the plain way."""
            with jax.named_scope(name):
                blk = getattr(self, name)
                if self.impl == "xla":
                    x = d if e is None else jnp.concatenate([_tile_w(e, d.shape[2]), d], axis=-1)
                    return blk(upsample_time2(x), w)
                return blk.activate(blk.conv.upsampled(d, e), w)

        vel_in = curve_vel_BxTx3
        if self.frame == "curve":
            theta_BxT = curves.heading(curve_vel_BxTx3)
            vel_in = curves.rotate_y(curve_vel_BxTx3, -jnp.concatenate([theta_BxT[:, :1], theta_BxT[:, :-1]], 1))
        x = (vel_in / self.length_unit)[..., None]  # B x T x 3 x 1
        b = curve_vel_BxTx3.shape[0]
        phase_BxTx1xP = None
        if self.gait_phase:
            if phase_BxT is None:
                phase_BxT = self.walked_phase(curve_vel_BxTx3, w_BxD, phase_offset_B)
            phase_BxTx1xP = gait_phase(phase_BxT)[:, :, None, :].astype(self.compute_dtype)
            x = jnp.concatenate([x, jnp.broadcast_to(phase_BxTx1xP, (b, t, 3, PHASE_CHANNELS))], -1)
        elif phase_offset_B is not None or phase_BxT is not None:
            raise ValueError("a phase given, but this G has no gait phase (model.gait_phase)")

        def with_phase(e_BxTxWxC, rate):
            """e with the phase channels of every `rate`-th sample appended (its time grid)."""
            if phase_BxTx1xP is None:
                return e_BxTxWxC
            p = jnp.broadcast_to(phase_BxTx1xP[:, ::rate], e_BxTxWxC.shape[:3] + (PHASE_CHANNELS,))
            return jnp.concatenate([e_BxTxWxC, p], -1)

        x = x.astype(self.compute_dtype)
        x = block("ec0_0", x)
        x = block("ec1_0", x)
        e1 = block("ec1_1", x)
        x = block("ec2_0", e1)
        e2 = block("ec2_1", x)
        x = block("ec3_0", e2)
        x = block("ec3_1", x)

        x = up_block("dc3_1", block("dc_bottom", x))
        d2 = block("dc3_0", x)
        x = up_block("dc2_1", d2, with_phase(e2, 4))
        d1 = block("dc2_0", x)[:, :, : self.num_rel_joints]
        x = up_block("dc1_1", d1, with_phase(e1, 2))
        d0 = block("dc1_0", with_phase(x, 1))

        with jax.named_scope("heads"):
            root_vel_BxTx3 = self.c_traj(d0)[:, :, 0, :].astype(jnp.float32) * self.length_unit
            if self.root_height:  # y is a height: its difference is the velocity (v[0] = v[1])
                h_BxT = root_vel_BxTx3[..., 1]
                dh_BxT = h_BxT[:, 1:] - h_BxT[:, :-1]
                root_vel_BxTx3 = root_vel_BxTx3.at[..., 1].set(jnp.concatenate([dh_BxT[:, :1], dh_BxT], 1))
            pose_BxTxR = self.dc0_0(d0)[..., 0].astype(jnp.float32) * self.length_unit
        if self.rest_pose_R is not None:
            pose_BxTxR = pose_BxTxR + jnp.asarray(self.rest_pose_R, pose_BxTxR.dtype)
        if self.bones is not None:
            pose_BxTxR = project_bones(pose_BxTxR, self.bones)
        if self.frame == "curve":
            out_BxT = curves.smooth_heading(curve_vel_BxTx3)
            root_vel_BxTx3 = curves.rotate_y(root_vel_BxTx3, out_BxT)
            b, t, r = pose_BxTxR.shape
            pose_BxTxR = curves.rotate_y(pose_BxTxR.reshape(b, t, r // 3, 3), out_BxT[..., None]).reshape(b, t, r)
        if self.residual_root:
            root_vel_BxTx3 = root_vel_BxTx3 + curve_vel_BxTx3
        return root_vel_BxTx3, pose_BxTxR
