"""Generator G (docs/DESIGN.md §3.4): curve velocity + style code w -> root velocity and pose rows.

Layout NHWC = (B, T, W, C). The input velocity B x T x 3 enters as one channel over 3 width
rows. Every block is conv -> LeakyReLU -> AdaIN(w); the same w feeds all 14 AdaINs. The two
heads have neither. Skips are taken after AdaIN and tiled along the width, encoder first.
The reference's unused `dc0_1` is not built. c = `base_channels`, kt the time kernel
(model.base_channels, model.time_kernel).

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

The small configs build `WalkerGenerator` (nn/walker.py) around this network: it feeds
`network` a rotated input and side channels (`side_channels`: per-sample features appended to
the input, both skips and dc1_0's input; none in the paper) and post-processes the heads.

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

import jax
import jax.numpy as jnp
from flax import nnx

from motiongan_jax.config import LatentInit
from motiongan_jax.nn.latent import LatentTransform
from motiongan_jax.nn.layers import (
    AdaIN,
    Conv,
    ConvTranspose,
    leaky_relu,
    upsample_time2,
)

MAX_JOINTS = 27


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
    """The paper's G: the network above, the Latent Transform and the two heads."""

    # Names of the 14 AdaIN-carrying blocks in forward order.
    BLOCKS = ("ec0_0", "ec1_0", "ec1_1", "ec2_0", "ec2_1", "ec3_0", "ec3_1",
              "dc_bottom", "dc3_1", "dc3_0", "dc2_1", "dc2_0", "dc1_1", "dc1_0")

    def __init__(
        self,
        num_rel_joints: int = 27,
        *,
        base_channels: int = 64,
        time_kernel: int = 5,
        w_dim: int = 64,
        z_dim: int = 64,
        num_styles: int,
        latent_init: LatentInit = "paper",
        length_unit: float = 1.0,
        side_channels: int = 0,
        impl: str = "fast",
        compute_dtype: str = "float32",
        rngs: nnx.Rngs,
    ):
        kt = time_kernel  # the layers' kernel along time (kt in the table above)
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
        self.side_channels = int(side_channels)  # static
        self.latent = LatentTransform(num_styles, z_dim=z_dim, w_dim=w_dim, init=latent_init, rngs=rngs)

        def conv(cin, cout, kwidth=1, stride=(1, 1), pad_w=0):
            return StyledBlock(Conv(cin, cout, (kt, kwidth), stride, pad_w=pad_w, impl=impl, rngs=rngs),
                               cout, w_dim, rngs=rngs)

        def tconv(cin, cout):
            return StyledBlock(ConvTranspose(cin, cout, (kt, 3), impl=impl, rngs=rngs), cout, w_dim, rngs=rngs)

        c = base_channels
        t1, t2, t4, t8 = c, 2 * c, 4 * c, 8 * c
        s = self.side_channels
        self.ec0_0 = conv(1 + s, t1)
        self.ec1_0 = conv(t1, t2, 3, (2, 3))
        self.ec1_1 = conv(t2, t2)
        self.ec2_0 = conv(t2, t4, 1, (2, 1))
        self.ec2_1 = conv(t4, t4)
        self.ec3_0 = conv(t4, t8, 1, (2, 1))
        self.ec3_1 = conv(t8, t8)
        self.dc_bottom = tconv(t8, t8)
        self.dc3_1 = tconv(t8, t8)
        self.dc3_0 = conv(t8, t4, 3, pad_w=1)
        self.dc2_1 = tconv(t4 + s + t4, t4)
        self.dc2_0 = conv(t4, t2, 3, pad_w=1)
        self.dc1_1 = tconv(t2 + s + t2, t2)
        self.dc1_0 = conv(t2 + s, t1, 3, pad_w=1)
        self.c_traj = Conv(t1, 3, (kt, self.num_rows), impl=impl, rngs=rngs)
        self.dc0_0 = Conv(t1, 1, (kt, 1), impl=impl, rngs=rngs)

    def style(self, labels_B: jax.Array, z_BxZ: jax.Array) -> jax.Array:
        """The style code w (B x w_dim) of the Latent Transform."""
        return self.latent(labels_B, z_BxZ)

    def adain_styles(self, w_BxD: jax.Array) -> dict[str, tuple[jax.Array, jax.Array]]:
        """(scale, bias) of every AdaIN layer for a style code, keyed by block name."""
        return {name: getattr(self, name).adain.style(w_BxD) for name in self.BLOCKS}

    # the paper's G keeps no gait clock; the walker (nn/walker.py) does when its option is on
    has_gait_phase = False

    def __call__(self, curve_vel_BxTx3: jax.Array, w_BxD: jax.Array, phase_offset_B: jax.Array | None = None,
                 phase_BxT: jax.Array | None = None) -> tuple[jax.Array, jax.Array]:
        """(root_vel_BxTx3, pose_BxTxR), metres: the curve velocity's three rows are the input. The
        phase arguments are the walker's call (one signature for every G); the paper's G takes none."""
        if phase_offset_B is not None or phase_BxT is not None:
            raise ValueError("a phase given, but this G has no gait phase (model.gait_phase)")
        return self.network((curve_vel_BxTx3 / self.length_unit)[..., None], w_BxD)

    def network(self, x_BxTx3xC: jax.Array, w_BxD: jax.Array,
                side_BxTx1xS: jax.Array | None = None) -> tuple[jax.Array, jax.Array]:
        """The heads' (root_vel_BxTx3, pose_BxTxR) in metres for an input in the layers' unit
        (C = 1 + side_channels) and the side channels (S = side_channels, None when 0), which
        enter the skips and dc1_0 on their time grids."""
        t = x_BxTx3xC.shape[1]
        if t % 8:
            raise ValueError(f"G needs T divisible by 8, got T={t}")
        if (side_BxTx1xS is None) != (self.side_channels == 0):
            raise ValueError(f"this G takes {self.side_channels} side channels")
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

        def with_side(e_BxTxWxC, rate):
            """e with the side channels of every `rate`-th sample appended (its time grid)."""
            if side_BxTx1xS is None:
                return e_BxTxWxC
            p = jnp.broadcast_to(side_BxTx1xS[:, ::rate], e_BxTxWxC.shape[:3] + (self.side_channels,))
            return jnp.concatenate([e_BxTxWxC, p], -1)

        x = x_BxTx3xC.astype(self.compute_dtype)
        x = block("ec0_0", x)
        x = block("ec1_0", x)
        e1 = block("ec1_1", x)
        x = block("ec2_0", e1)
        e2 = block("ec2_1", x)
        x = block("ec3_0", e2)
        x = block("ec3_1", x)

        x = up_block("dc3_1", block("dc_bottom", x))
        d2 = block("dc3_0", x)
        x = up_block("dc2_1", d2, with_side(e2, 4))
        d1 = block("dc2_0", x)[:, :, : self.num_rel_joints]
        x = up_block("dc1_1", d1, with_side(e1, 2))
        d0 = block("dc1_0", with_side(x, 1))

        with jax.named_scope("heads"):
            root_vel_BxTx3 = self.c_traj(d0)[:, :, 0, :].astype(jnp.float32) * self.length_unit
            pose_BxTxR = self.dc0_0(d0)[..., 0].astype(jnp.float32) * self.length_unit
        return root_vel_BxTx3, pose_BxTxR
