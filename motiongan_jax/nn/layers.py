"""Building blocks shared by G, D and the Latent Transform (spec §3.1, §3.2).

Layout is NHWC = (B, T, W, C): time is axis 1, the joint-coordinate rows are axis 2.
Parameters are stored so that they map 1:1 onto the PyTorch reference:

* `Conv.kernel`          (kt, kw, in, out)  = torch Conv2d weight (out, in, kt, kw).transpose(2, 3, 1, 0)
* `ConvTranspose.kernel` (kt, kw, in, out)  = torch ConvTranspose2d weight (in, out, kt, kw).transpose(2, 3, 0, 1)
* `Dense.kernel`         (in, out)          = torch weight (out, in).T (1x1 convs included)

Spectral norm is our own (`SpectralNorm`): it keeps the raw weight as the trainable `nnx.Param`
and holds u and v as non-trainable `SpectralNormState`, like `torch.nn.utils.spectral_norm`.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
from flax import nnx

LEAKY_SLOPE = 0.01  # PyTorch's nn.LeakyReLU default, used everywhere in the reference
NORM_EPS = 1e-8  # PixelNorm and AdaIN instance norm
SN_EPS = 1e-12  # torch.nn.utils.spectral_norm default


def leaky_relu(x: jax.Array) -> jax.Array:
    return jax.nn.leaky_relu(x, LEAKY_SLOPE)


# ---------------------------------------------------------------------------------------------
# Initialisers (jax.nn.initializers signature: key, shape, dtype)


def normal_init(std: float):
    def init(key, shape, dtype=jnp.float32):
        return std * jax.random.normal(key, shape, dtype)

    return init


def uniform_init(bound: float):
    """U(-bound, bound); PyTorch's default conv/linear init has bound = 1/sqrt(fan_in)."""

    def init(key, shape, dtype=jnp.float32):
        return jax.random.uniform(key, shape, dtype, -bound, bound)

    return init


def zeros_init(key, shape, dtype=jnp.float32):
    del key
    return jnp.zeros(shape, dtype)


# ---------------------------------------------------------------------------------------------
# Stateless ops


def reflect_pad(x_BxTxWxC: jax.Array, pad_t: int, pad_w: int = 0) -> jax.Array:
    """Reflection padding that excludes the edge sample (numpy / PyTorch 'reflect')."""
    if pad_t == 0 and pad_w == 0:
        return x_BxTxWxC
    return jnp.pad(x_BxTxWxC, ((0, 0), (pad_t, pad_t), (pad_w, pad_w), (0, 0)), mode="reflect")


def upsample_time2(x_BxTxWxC: jax.Array) -> jax.Array:
    """Linear x2 upsampling along time, PyTorch bilinear (2, 1) with align_corners=False.

    out[2i] = 3/4 x[i] + 1/4 x[i-1], out[2i+1] = 3/4 x[i] + 1/4 x[i+1], edges clamped. Equal to
    jax.image.resize(..., 'linear') (tested) without its dense T x 2T interpolation matrix.
    """
    prev = jnp.concatenate([x_BxTxWxC[:, :1], x_BxTxWxC[:, :-1]], axis=1)
    nxt = jnp.concatenate([x_BxTxWxC[:, 1:], x_BxTxWxC[:, -1:]], axis=1)
    even = 0.75 * x_BxTxWxC + 0.25 * prev
    odd = 0.75 * x_BxTxWxC + 0.25 * nxt
    b, t, w, c = x_BxTxWxC.shape
    return jnp.stack([even, odd], axis=2).reshape(b, 2 * t, w, c)


def pixel_norm(x: jax.Array, axis: int = -1) -> jax.Array:
    """x / sqrt(mean(x^2 over `axis`) + 1e-8)."""
    return x * jax.lax.rsqrt(jnp.mean(jnp.square(x), axis=axis, keepdims=True) + NORM_EPS)


def instance_norm(x_BxTxWxC: jax.Array) -> jax.Array:
    """Per sample and channel over time and width; biased variance, eps 1e-8, no affine."""
    mean = jnp.mean(x_BxTxWxC, axis=(1, 2), keepdims=True)
    var = jnp.mean(jnp.square(x_BxTxWxC - mean), axis=(1, 2), keepdims=True)
    return (x_BxTxWxC - mean) * jax.lax.rsqrt(var + NORM_EPS)


# ---------------------------------------------------------------------------------------------
# Spectral norm


class SpectralNormState(nnx.BatchStat):
    """Power-iteration vectors u, v of a spectral-normalised layer: state, never trained."""


def _l2_normalize(x: jax.Array, eps: float = SN_EPS) -> jax.Array:
    # torch.nn.functional.normalize: x / max(||x||, eps)
    return x / jnp.maximum(jnp.linalg.norm(x), eps)


class SpectralNorm(nnx.Module):
    """σ(W) by power iteration with PyTorch's `spectral_norm` semantics.

    W is the weight as a (out, in·kh·kw) matrix in PyTorch order. u (out,) and v (in·kh·kw,) start
    as normalised N(0, 1) draws. With `update_stats=True` one iteration runs:
    v ← normalize(Wᵀu), u ← normalize(Wv), both stored. σ = uᵀWv; no gradient flows into u or v,
    so dσ/dW = u vᵀ as in PyTorch. The caller divides its raw weight by σ; the raw weight is
    never written.
    """

    def __init__(self, rows: int, cols: int, *, rngs: nnx.Rngs):
        self.u = SpectralNormState(_l2_normalize(jax.random.normal(rngs.params(), (rows,))))
        self.v = SpectralNormState(_l2_normalize(jax.random.normal(rngs.params(), (cols,))))

    def __call__(self, w_mat: jax.Array, *, update_stats: bool) -> jax.Array:
        u, v = self.u[...], self.v[...]
        if update_stats:
            w_ng = jax.lax.stop_gradient(w_mat)
            v = _l2_normalize(w_ng.T @ u)
            u = _l2_normalize(w_ng @ v)
            self.u.set_value(u)
            self.v.set_value(v)
        u, v = jax.lax.stop_gradient(u), jax.lax.stop_gradient(v)
        return u @ (w_mat @ v)


# ---------------------------------------------------------------------------------------------
# Parametric layers


class Conv(nnx.Module):
    """Reflect-pad (kt//2 frames each side in time, `pad_w` rows in width), then a VALID conv.

    Init: weight N(0, 0.02²), bias 0 (spec §3.1). `spectral_norm=True` divides the kernel by
    σ from `SpectralNorm` on every call.
    """

    def __init__(
        self,
        in_ch: int,
        out_ch: int,
        kernel_size: tuple[int, int],
        stride: tuple[int, int] = (1, 1),
        *,
        pad_w: int = 0,
        spectral_norm: bool = False,
        rngs: nnx.Rngs,
    ):
        kt, kw = kernel_size
        self.stride = tuple(stride)
        self.pad_t = kt // 2
        self.pad_w = pad_w
        self.kernel = nnx.Param(normal_init(0.02)(rngs.params(), (kt, kw, in_ch, out_ch)))
        self.bias = nnx.Param(jnp.zeros((out_ch,)))
        self.sn = SpectralNorm(out_ch, in_ch * kt * kw, rngs=rngs) if spectral_norm else None

    def weight(self, *, update_stats: bool = False) -> jax.Array:
        """The kernel actually applied (W/σ under spectral norm)."""
        kernel = self.kernel[...]
        if self.sn is None:
            return kernel
        w_mat = jnp.transpose(kernel, (3, 2, 0, 1)).reshape(kernel.shape[3], -1)  # torch order
        return kernel / self.sn(w_mat, update_stats=update_stats)

    def __call__(self, x_BxTxWxC: jax.Array, *, update_stats: bool = False) -> jax.Array:
        x = reflect_pad(x_BxTxWxC, self.pad_t, self.pad_w)
        y = jax.lax.conv_general_dilated(
            x,
            self.weight(update_stats=update_stats),
            window_strides=self.stride,
            padding="VALID",
            dimension_numbers=("NHWC", "HWIO", "NHWC"),
        )
        return y + self.bias[...]


class ConvTranspose(nnx.Module):
    """PyTorch ConvTranspose2d kernel (kt, kw), stride (1, kw), no padding, then a crop of kt//2
    frames from each end of time: T is kept, the width is multiplied by kw (spec §3.1).

    Because the width stride equals the width kernel, each input column owns its kw output
    columns; with stride 1 in time the crop turns the transposed conv into a zero-padded
    correlation with the time-flipped kernel. So it runs as one ordinary conv with kw·out output
    channels, reshaped into width. Tested against an explicit loop and lax.conv_transpose.
    Init: N(0, 0.02²), bias 0.
    """

    def __init__(self, in_ch: int, out_ch: int, kernel_size: tuple[int, int], *, rngs: nnx.Rngs):
        kt, kw = kernel_size
        self.kernel = nnx.Param(normal_init(0.02)(rngs.params(), (kt, kw, in_ch, out_ch)))
        self.bias = nnx.Param(jnp.zeros((out_ch,)))

    def __call__(self, x_BxTxWxC: jax.Array) -> jax.Array:
        kernel = self.kernel[...]
        kt, kw, cin, cout = kernel.shape
        crop = kt // 2
        k = jnp.transpose(kernel[::-1], (0, 2, 1, 3)).reshape(kt, 1, cin, kw * cout)
        y = jax.lax.conv_general_dilated(
            x_BxTxWxC,
            k,
            window_strides=(1, 1),
            padding=((kt - 1 - crop, crop), (0, 0)),
            dimension_numbers=("NHWC", "HWIO", "NHWC"),
        )
        b, t, w, _ = y.shape
        return y.reshape(b, t, w * kw, cout) + self.bias[...]


class Dense(nnx.Module):
    """Linear map on the last axis (also the reference's 1x1 convs on B x C x 1 x 1)."""

    def __init__(
        self,
        in_features: int,
        out_features: int,
        *,
        kernel_init,
        bias_init,
        spectral_norm: bool = False,
        rngs: nnx.Rngs,
    ):
        self.kernel = nnx.Param(kernel_init(rngs.params(), (in_features, out_features)))
        self.bias = nnx.Param(bias_init(rngs.params(), (out_features,)))
        self.sn = SpectralNorm(out_features, in_features, rngs=rngs) if spectral_norm else None

    def weight(self, *, update_stats: bool = False) -> jax.Array:
        kernel = self.kernel[...]
        if self.sn is None:
            return kernel
        return kernel / self.sn(kernel.T, update_stats=update_stats)

    def __call__(self, x: jax.Array, *, update_stats: bool = False) -> jax.Array:
        return x @ self.weight(update_stats=update_stats) + self.bias[...]


def torch_default_dense(in_features: int, out_features: int, *, rngs: nnx.Rngs) -> Dense:
    """PyTorch's default conv/linear init: weight and bias U(±1/sqrt(fan_in))."""
    bound = 1.0 / math.sqrt(in_features)
    return Dense(in_features, out_features, kernel_init=uniform_init(bound),
                 bias_init=uniform_init(bound), rngs=rngs)


class AdaIN(nnx.Module):
    """instance_norm(h) · s + b with s = A_s w + a_s (used directly, no 1+s), b = A_b w + a_b.

    Init (spec §3.2): A_s, a_s PyTorch default U(±1/sqrt(w_dim)); A_b N(0, 0.02²), a_b 0.
    """

    def __init__(self, channels: int, w_dim: int, *, rngs: nnx.Rngs):
        self.scale = torch_default_dense(w_dim, channels, rngs=rngs)
        self.shift = Dense(w_dim, channels, kernel_init=normal_init(0.02), bias_init=zeros_init, rngs=rngs)

    def style(self, w_BxW: jax.Array) -> tuple[jax.Array, jax.Array]:
        """(s_BxC, b_BxC) for a style code; the analysis tools read these."""
        return self.scale(w_BxW), self.shift(w_BxW)

    def __call__(self, h_BxTxWxC: jax.Array, w_BxW: jax.Array) -> jax.Array:
        s, b = self.style(w_BxW)
        return instance_norm(h_BxTxWxC) * s[:, None, None, :] + b[:, None, None, :]
