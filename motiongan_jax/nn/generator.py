"""Generator G (spec §3.4): curve velocity + style code w -> root velocity and pose rows.

Layout NHWC = (B, T, W, C). The input velocity B x T x 3 enters as one channel over 3 width
rows. Every block is conv -> LeakyReLU -> AdaIN(w); the same w feeds all 14 AdaINs. The two
heads have neither. Skips are taken after AdaIN and tiled along the width, encoder first.
The reference's unused `dc0_1` is not built.

    ec0_0  conv kt×1           1 -> top        T     × 3
    ec1_0  conv kt×3 /(2,3)  top -> 2top       T/2   × 1
    ec1_1  conv kt×1        2top -> 2top       T/2   × 1   e1
    ec2_0  conv kt×1 /(2,1) 2top -> 4top       T/4   × 1
    ec2_1  conv kt×1        4top -> 4top       T/4   × 1   e2
    ec3_0  conv kt×1 /(2,1) 4top -> 8top       T/8   × 1
    ec3_1  conv kt×1        8top -> 8top       T/8   × 1
    dc_bottom tconv kt×3    8top -> 8top       T/8   × 3,  up x2 in time
    dc3_1  tconv kt×3       8top -> 8top       T/4   × 9
    dc3_0  conv kt×3 (w-reflect 1) -> 4top     T/4   × 9   d2; [e2 tiled, d2], up
    dc2_1  tconv kt×3       8top -> 4top       T/2   × 27
    dc2_0  conv kt×3 (w-reflect 1) -> 2top     T/2   × 27  d1; keep J columns; [e1 tiled, d1], up
    dc1_1  tconv kt×3       4top -> 2top       T     × 3J
    dc1_0  conv kt×3 (w-reflect 1) -> top      T     × 3J  d0
    c_traj conv kt×3J        top -> 3          T     × 1   -> root velocity B x T x 3
    dc0_0  conv kt×1         top -> 1          T     × 3J  -> pose B x T x 3J

Fewer than 27 joints (Bandai has 20). The decoder's width goes 1 -> 3 -> 9 -> 27, one column per
joint slot at the 27-column stage. For J < 27 joints we keep the first J columns of d1 (after
dc2_0's AdaIN, before the skip concat), so the per-coordinate stage (dc1_1, dc1_0, both heads)
works on exactly 3J rows and c_traj's kernel is kt × 3J. Joint k ≥ 1 still owns the column that
its position in the row layout gives it in the paper's grouping. For J = 27 the crop is the
identity and the network is the paper's. J > 27 would need another width stage: rejected.

Output prior (model.output_prior = "rest_and_curve", small configs only; off in the paper's G):
the pose head adds the skeleton's rest pose (`rest_pose_R`, metres) and the root-velocity head
adds the input curve velocity. The parameters are the same; G starts as a rest-pose skeleton
gliding along the curve instead of a collapsed one standing still.

Curve frame (model.g_frame = "curve", small configs only; "world" is the paper's G): G works in
the walker's own frame instead of the world's. Its input is each curve velocity seen from the
heading of the previous one, u[t] = R(-θ[t-1]) v[t] (forward speed and turn, the same for every
world rotation of the curve), and its outputs, root velocity and pose (with the rest pose prior,
which faces +z), are turned by the smoothed heading θs[t] of the curve (`curves.smooth_heading`)
before the world curve velocity is added. So rotating the curve rotates the motion exactly, and
the network need not learn to turn the body to the path for every direction the rotation
augmentation draws: with the world frame, the cpu config's bodies still faced a median 77
degrees away from their path after 6,000 steps (docs/RESULTS.md §5). Same parameters.

Exact bones (model.exact_bones, small configs only; the paper's G has only the bone loss): the
pose head's bones keep their directions and take the skeleton's lengths, joint by joint from the
root, p[b] = p[a] + L_ab (r[b] - r[a]) / |r[b] - r[a]| for raw rows r. A pose whose bones already
have the right lengths is unchanged; bone lengths cannot drift, so neither D's class head nor
its real/fake head can be answered with a stretched body.

Gait phase (model.phase_wavelengths_m, small configs; empty in the paper's G): G's input, a
curve resampled at equal arc length, is nearly constant (in the curve frame exactly so on a
straight path), and G is convolutional, so apart from the window's edges and the 8-sample period
of its strides it has nothing to hang a gait cycle on; the cpu config's bodies glide
(docs/RESULTS.md §5). With F wavelengths λ_k, ec0_0
takes 1 + 2F channels: the velocity plus sin and cos of 2π s[t] / λ_k + φ_k, tiled over the 3
width rows, where s[t] is the distance walked along the curve (`gait_phase`). The offsets φ_k
are drawn uniformly per training sample (`step.sample_phase`) so that no phase is favoured, and
are 0 unless given at generation. The channels depend on distance, not on time, so they stay
right under the FPS augmentation and rotate with nothing. Only ec0_0's kernel grows. Measured
on the cpu config: no gait after 10,000 steps either (docs/RESULTS.md §6), so it stays off.

Init: convs and tconvs N(0, 0.02²), zero bias (spec §3.1); AdaIN and the Latent Transform as in
their modules. The Latent Transform lives inside G (it is trained with G's optimiser).

`impl="fast"` (default) computes the same function with less work (docs/PERFORMANCE.md):
the tiled skips' share of dc2_1 / dc1_1 is computed on one column and broadcast, and each
"upsample x2 then tconv" is one polyphase correlation of the un-upsampled input
(`ConvTranspose.upsampled`); the convolutions use `conv.conv2d`'s CPU schedule. `impl="xla"`
is the straightforward form above (tile, concatenate, upsample, lax.conv), kept as the reference
that tests/test_speed.py compares against. Parameters are identical.

`compute_dtype="bfloat16"` runs the convolutions and activations in bf16 (mixed precision, for
GPUs); parameters, AdaIN statistics, the Latent Transform and the outputs stay float32.
"""

from __future__ import annotations

import chex
import jax
import jax.numpy as jnp
from flax import nnx

from motiongan_jax import curves
from motiongan_jax.nn.latent import LatentTransform
from motiongan_jax.nn.layers import AdaIN, Conv, ConvTranspose, leaky_relu, upsample_time2

MAX_JOINTS = 27
FRAMES = ("world", "curve")


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


def gait_phase(curve_vel_BxTx3: jax.Array, wavelengths_m, offset_BxF: jax.Array) -> jax.Array:
    """B x T x 2F: [sin(a_1..a_F), cos(a_1..a_F)], a_k[t] = 2π s[t] / λ_k + φ_k, where s[t] is the
    horizontal distance walked up to sample t (the sum of |v[0..t]|, metres)."""
    lam_F = jnp.asarray(wavelengths_m, jnp.float32)
    chex.assert_shape(offset_BxF, (curve_vel_BxTx3.shape[0], lam_F.shape[0]))
    dist_BxT = jnp.cumsum(jnp.linalg.norm(curve_vel_BxTx3[..., ::2], axis=-1), axis=1)
    angle_BxTxF = 2 * jnp.pi * dist_BxT[..., None] / lam_F + offset_BxF[:, None, :]
    return jnp.concatenate([jnp.sin(angle_BxTxF), jnp.cos(angle_BxTxF)], -1)


class StyledBlock(nnx.Module):
    """conv (or tconv) -> LeakyReLU -> AdaIN(w)."""

    def __init__(self, conv: nnx.Module, channels: int, w_dim: int, *, rngs: nnx.Rngs):
        self.conv = conv
        self.adain = AdaIN(channels, w_dim, rngs=rngs)

    def activate(self, h_BxTxWxC: jax.Array, w_BxW: jax.Array) -> jax.Array:
        """LeakyReLU then AdaIN(w) of the conv's output."""
        return self.adain(leaky_relu(h_BxTxWxC), w_BxW)

    def __call__(self, x_BxTxWxC: jax.Array, w_BxW: jax.Array) -> jax.Array:
        return self.activate(self.conv(x_BxTxWxC), w_BxW)


def _tile_w(x_BxTx1xC: jax.Array, width: int) -> jax.Array:
    return jnp.broadcast_to(x_BxTx1xC, (x_BxTx1xC.shape[0], x_BxTx1xC.shape[1], width, x_BxTx1xC.shape[3]))


class Generator(nnx.Module):
    # Names of the 14 AdaIN-carrying blocks in forward order.
    BLOCKS = ("ec0_0", "ec1_0", "ec1_1", "ec2_0", "ec2_1", "ec3_0", "ec3_1",
              "dc_bottom", "dc3_1", "dc3_0", "dc2_1", "dc2_0", "dc1_1", "dc1_0")

    def __init__(
        self,
        num_joints: int = 27,
        *,
        top: int = 64,
        kw: int = 5,
        w_dim: int = 64,
        z_dim: int = 64,
        num_styles: int,
        latent_init: str = "paper",
        length_unit: float = 1.0,
        rest_pose_R: tuple[float, ...] | None = None,
        residual_root: bool = False,
        frame: str = "world",
        bones: tuple[tuple[int, int, float], ...] | None = None,
        phase_wavelengths_m: tuple[float, ...] = (),
        impl: str = "fast",
        compute_dtype: str = "float32",
        rngs: nnx.Rngs,
    ):
        if not 1 <= num_joints <= MAX_JOINTS:
            raise ValueError(f"num_joints must be in 1..{MAX_JOINTS}, got {num_joints}")
        if kw % 2 != 1:
            raise ValueError(f"kw must be odd, got {kw}")
        self.num_joints = num_joints
        self.num_rows = 3 * num_joints
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
        if frame not in FRAMES:
            raise ValueError(f"frame must be one of {FRAMES}, got {frame!r}")
        self.frame = frame
        if bones is not None:
            bones = tuple((int(a), int(b), float(length)) for a, b, length in bones)
            if sorted(b for _, b, _ in bones) != list(range(1, num_joints + 1)) or any(a >= b for a, b, _ in bones):
                raise ValueError("bones must be (parent, child, length) with each joint 1..J a child once, "
                                 "parents before children")
        self.bones = bones  # static: part of the graph definition
        if any(not lam > 0 for lam in phase_wavelengths_m):
            raise ValueError(f"phase wavelengths must be positive, got {phase_wavelengths_m}")
        self.phase_wavelengths_m = tuple(float(lam) for lam in phase_wavelengths_m)  # static
        self.latent = LatentTransform(num_styles, z_dim=z_dim, w_dim=w_dim, init=latent_init, rngs=rngs)

        def conv(cin, cout, kwidth=1, stride=(1, 1), pad_w=0):
            return StyledBlock(Conv(cin, cout, (kw, kwidth), stride, pad_w=pad_w, impl=impl, rngs=rngs),
                               cout, w_dim, rngs=rngs)

        def tconv(cin, cout):
            return StyledBlock(ConvTranspose(cin, cout, (kw, 3), impl=impl, rngs=rngs), cout, w_dim, rngs=rngs)

        t1, t2, t4, t8 = top, 2 * top, 4 * top, 8 * top
        self.ec0_0 = conv(1 + 2 * len(self.phase_wavelengths_m), t1)
        self.ec1_0 = conv(t1, t2, 3, (2, 3))
        self.ec1_1 = conv(t2, t2)
        self.ec2_0 = conv(t2, t4, 1, (2, 1))
        self.ec2_1 = conv(t4, t4)
        self.ec3_0 = conv(t4, t8, 1, (2, 1))
        self.ec3_1 = conv(t8, t8)
        self.dc_bottom = tconv(t8, t8)
        self.dc3_1 = tconv(t8, t8)
        self.dc3_0 = conv(t8, t4, 3, pad_w=1)
        self.dc2_1 = tconv(t4 + t4, t4)
        self.dc2_0 = conv(t4, t2, 3, pad_w=1)
        self.dc1_1 = tconv(t2 + t2, t2)
        self.dc1_0 = conv(t2, t1, 3, pad_w=1)
        self.c_traj = Conv(t1, 3, (kw, self.num_rows), impl=impl, rngs=rngs)
        self.dc0_0 = Conv(t1, 1, (kw, 1), impl=impl, rngs=rngs)

    def style(self, labels_B: jax.Array, z_BxZ: jax.Array) -> jax.Array:
        """The style code w (B x w_dim) of the Latent Transform."""
        return self.latent(labels_B, z_BxZ)

    def adain_styles(self, w_BxW: jax.Array) -> dict[str, tuple[jax.Array, jax.Array]]:
        """(scale, bias) of every AdaIN layer for a style code, keyed by block name."""
        return {name: getattr(self, name).adain.style(w_BxW) for name in self.BLOCKS}

    def __call__(self, curve_vel_BxTx3: jax.Array, w_BxW: jax.Array,
                 phase_offset_BxF: jax.Array | None = None) -> tuple[jax.Array, jax.Array]:
        """(root_vel_BxTx3, pose_BxTxR); `phase_offset_BxF` (radians, default 0) only with a
        gait-phase input, one per wavelength."""
        t = curve_vel_BxTx3.shape[1]
        if t % 8:
            raise ValueError(f"G needs T divisible by 8, got T={t}")
        w = w_BxW

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
        if self.phase_wavelengths_m:
            b, f = curve_vel_BxTx3.shape[0], len(self.phase_wavelengths_m)
            offset = jnp.zeros((b, f), jnp.float32) if phase_offset_BxF is None else phase_offset_BxF
            phase_BxTx2F = gait_phase(curve_vel_BxTx3, self.phase_wavelengths_m, offset)
            x = jnp.concatenate([x, jnp.broadcast_to(phase_BxTx2F[:, :, None, :], (b, t, 3, 2 * f))], -1)
        elif phase_offset_BxF is not None:
            raise ValueError("phase_offset_BxF given, but this G has no gait-phase input")
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
        x = up_block("dc2_1", d2, e2)
        d1 = block("dc2_0", x)[:, :, : self.num_joints]
        x = up_block("dc1_1", d1, e1)
        d0 = block("dc1_0", x)

        with jax.named_scope("heads"):
            root_vel_BxTx3 = self.c_traj(d0)[:, :, 0, :].astype(jnp.float32) * self.length_unit
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
