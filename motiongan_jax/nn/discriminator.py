"""Discriminator D (docs/DESIGN.md §3.5): spectral norm on every layer, built for one window length T.

Input (B x T x 81 x 2, NHWC): channel 0 is the root velocity tiled across the rows (each
joint's xyz triple sees the root's xyz), channel 1 the pose rows. c = `base_channels`
(model.base_channels), kt the time kernel (model.time_kernel).

    c0_0  SN-conv kt×3 /(2,3)   2 -> c    T/2  × 27
    c1_0  SN-conv kt×3 /(2,3)   c -> 2c   T/4  × 9    (`features`)
    c2_0  SN-conv kt×3 /(2,3)  2c -> 4c   T/8  × 3
    c3_0  SN-conv kt×3 /(2,3)  4c -> 8c   T/16 × 1
    flatten channel-major (index ch·(T/16) + t, PyTorch's order)
    l_last SN-linear -> 1 (real/fake logit), l_cls SN-linear -> C (style logits)

All convs reflect-pad kt//2 frames in time and nothing in width. Inits: conv N(0, 0.02²) with
zero bias; linear weight N(0, 0.02²), bias U(±1/sqrt(fan_in)) (PyTorch default).

Fewer than 27 joints: the 3J rows of both channels are zero-padded to 81 so the three-way width
strides keep the paper's grouping of joints; the parameter count does not depend on J.

Spectral norm: each call with `update_stats=True` runs one power iteration per layer and stores
u, v (the reference calls D three times per training iteration, in train mode).

`ProjectionDiscriminator` (model.d_cond, small configs) is the paper's D with one more head: the
real/fake logit gains <V[y], flat>, V a spectral-norm linear map from the flattened features to
one row per style (Miyato & Koyama 2018), y the window's label: the real label for real windows,
the requested one for fakes. The class head still classifies; the verdict now asks "a real walk
of style y?", which a neighbouring style's posture should fail. V is built after the paper's
layers, so their initial values do not change.

`impl`: "fast" (default) or "xla", the convolution schedule of `conv.conv2d`; same results.
`compute_dtype="bfloat16"`: bf16 convolutions and activations, float32 parameters and heads.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
from flax import nnx

from motiongan_jax.nn.layers import (
    Conv,
    Dense,
    leaky_relu,
    normal_init,
    uniform_init,
    zeros_init,
)

PADDED_ROWS = 81


def flatten_channel_major(x_BxTx1xC: jax.Array) -> jax.Array:
    """B x T' x 1 x C -> B x (C·T'), index c·T' + t: PyTorch's flatten of B x C x T' x 1."""
    return jnp.transpose(x_BxTx1xC[:, :, 0, :], (0, 2, 1)).reshape(x_BxTx1xC.shape[0], -1)


class Discriminator(nnx.Module):
    """The paper's D."""

    def __init__(
        self,
        num_rel_joints: int = 27,
        *,
        num_styles: int,
        seq_len: int = 128,
        base_channels: int = 64,
        time_kernel: int = 5,
        length_unit: float = 1.0,
        impl: str = "fast",
        compute_dtype: str = "float32",
        rngs: nnx.Rngs,
    ):
        kt = time_kernel  # the layers' kernel along time (kt in the table above)
        if not 1 <= num_rel_joints <= PADDED_ROWS // 3:
            raise ValueError(f"num_rel_joints must be in 1..{PADDED_ROWS // 3}, got {num_rel_joints}")
        if seq_len % 16:
            raise ValueError(f"D needs T divisible by 16, got {seq_len}")
        self.num_rel_joints = num_rel_joints
        self.seq_len = seq_len
        # activations' dtype (bf16 compute); parameters, spectral norm and the heads stay float32
        self.compute_dtype = str(jnp.dtype(compute_dtype))
        self.length_unit = float(length_unit)

        def sn_conv(cin, cout):
            return Conv(cin, cout, (kt, 3), (2, 3), spectral_norm=True, impl=impl, rngs=rngs)

        c = base_channels
        self.c0_0 = sn_conv(2, c)
        self.c1_0 = sn_conv(c, 2 * c)
        self.c2_0 = sn_conv(2 * c, 4 * c)
        self.c3_0 = sn_conv(4 * c, 8 * c)
        feat = self.num_features = 8 * c * (seq_len // 16)
        bound = 1.0 / math.sqrt(feat)

        def sn_linear(out):
            return Dense(feat, out, kernel_init=normal_init(0.02), bias_init=uniform_init(bound),
                         spectral_norm=True, rngs=rngs)

        self.l_last = sn_linear(1)
        self.l_cls = sn_linear(num_styles)

    def _input(self, root_vel_BxTx3: jax.Array, pose_BxTxR: jax.Array) -> jax.Array:
        b, t, r = pose_BxTxR.shape
        if t != self.seq_len or r != 3 * self.num_rel_joints or root_vel_BxTx3.shape != (b, t, 3):
            raise ValueError(
                f"D built for T={self.seq_len}, {self.num_rel_joints} joints; got root velocity "
                f"{root_vel_BxTx3.shape} and pose {pose_BxTxR.shape}")
        x = jnp.stack([jnp.tile(root_vel_BxTx3, (1, 1, self.num_rel_joints)), pose_BxTxR], axis=-1)
        return jnp.pad(x, ((0, 0), (0, 0), (0, PADDED_ROWS - r), (0, 0)))

    def features(self, root_vel_BxTx3: jax.Array, pose_BxTxR: jax.Array, *,
                 update_stats: bool = False) -> jax.Array:
        """Activations after c1_0 and its LeakyReLU, B x T/4 x 9 x 2top (style search)."""
        # inputs in metres; the layers work in length_unit, like the generator
        with jax.named_scope("D"):
            x = self._input(root_vel_BxTx3 / self.length_unit, pose_BxTxR / self.length_unit)
            x = x.astype(self.compute_dtype)
            x = leaky_relu(self.c0_0(x, update_stats=update_stats))
            return leaky_relu(self.c1_0(x, update_stats=update_stats))

    def flat(self, root_vel_BxTx3: jax.Array, pose_BxTxR: jax.Array, *, update_stats: bool) -> jax.Array:
        """The flattened activations after c3_0 that the heads read, B x (8top·T/16), float32."""
        x = self.features(root_vel_BxTx3, pose_BxTxR, update_stats=update_stats)
        with jax.named_scope("D"):
            x = leaky_relu(self.c2_0(x, update_stats=update_stats))
            x = leaky_relu(self.c3_0(x, update_stats=update_stats))  # B x T/16 x 1 x 8top
            return flatten_channel_major(x).astype(jnp.float32)

    def __call__(self, root_vel_BxTx3: jax.Array, pose_BxTxR: jax.Array, *,
                 update_stats: bool, labels_B: jax.Array | None = None) -> tuple[jax.Array, jax.Array]:
        """(real/fake logit B, style logits B x C); sigmoid/softmax are the losses' business.
        `labels_B`, the style each window is judged as, is ignored by the paper's D (a
        ProjectionDiscriminator needs it)."""
        flat = self.flat(root_vel_BxTx3, pose_BxTxR, update_stats=update_stats)
        with jax.named_scope("D"):
            return self.l_last(flat, update_stats=update_stats)[:, 0], self.l_cls(flat, update_stats=update_stats)


class ProjectionDiscriminator(Discriminator):
    """The paper's D with a projection head V (the module docstring): the verdict on a window
    asks whether it is a real walk of the style it is judged as."""

    def __init__(self, num_rel_joints: int = 27, *, num_styles: int, rngs: nnx.Rngs, **paper):
        super().__init__(num_rel_joints, num_styles=num_styles, rngs=rngs, **paper)
        # a zero bias: the verdict starts without a per-style offset (it may learn one)
        self.l_proj = Dense(self.num_features, num_styles, kernel_init=normal_init(0.02), bias_init=zeros_init,
                            spectral_norm=True, rngs=rngs)

    def __call__(self, root_vel_BxTx3: jax.Array, pose_BxTxR: jax.Array, *,
                 update_stats: bool, labels_B: jax.Array | None = None) -> tuple[jax.Array, jax.Array]:
        if labels_B is None:
            raise ValueError("a projection D (model.d_cond) needs labels_B")
        flat = self.flat(root_vel_BxTx3, pose_BxTxR, update_stats=update_stats)
        with jax.named_scope("D"):
            adv_B = self.l_last(flat, update_stats=update_stats)[:, 0]
            cls_BxC = self.l_cls(flat, update_stats=update_stats)
            proj_BxC = self.l_proj(flat, update_stats=update_stats)
            adv_B = adv_B + jnp.take_along_axis(proj_BxC, labels_B.astype(jnp.int32)[:, None], axis=1)[:, 0]
        return adv_B, cls_BxC
