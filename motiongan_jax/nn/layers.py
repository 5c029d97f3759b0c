"""Building blocks shared by G, D and the Latent Transform (docs/DESIGN.md §3.1, §3.2).

Layout is NHWC = (B, T, W, C): time is axis 1, the joint-coordinate rows are axis 2.
Parameters are stored so that they map 1:1 onto the PyTorch reference:

* `Conv.kernel`          (kt, kwidth, in, out)  = torch Conv2d weight (out, in, kt, kwidth).transpose(2, 3, 1, 0)
* `ConvTranspose.kernel` (kt, kwidth, in, out)  = torch ConvTranspose2d weight (in, out, kt, kwidth)
                                                  .transpose(2, 3, 0, 1)
* `Dense.kernel`         (in, out)          = torch weight (out, in).T (1x1 convs included)

Spectral norm is our own (`SpectralNorm`): it keeps the raw weight as the trainable `nnx.Param`
and holds u and v as non-trainable `SpectralNormState`, like `torch.nn.utils.spectral_norm`.

`impl` (conv layers): "fast" runs the convolutions through `conv.conv2d`'s CPU-tuned schedule,
"xla" through plain `lax.conv_general_dilated`; same parameters, same results to float32
rounding (docs/PERFORMANCE.md, tests/test_fast_equals_reference.py).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
from flax import nnx

from motiongan_jax.nn.conv import conv2d

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


def _norm_stats(x):
    """(mean, 1/std) over time and width, in float32 whatever x's dtype."""
    x = x.astype(jnp.float32)
    mean = jnp.mean(x, axis=(1, 2), keepdims=True)
    var = jnp.mean(jnp.square(x - mean), axis=(1, 2), keepdims=True)
    return mean, jax.lax.rsqrt(var + NORM_EPS)


@jax.custom_vjp
def modulated_instance_norm(x_BxTxWxC: jax.Array, s_BxC: jax.Array, b_BxC: jax.Array) -> jax.Array:
    """instance_norm(x) · s + b (AdaIN's modulation), s and b per sample and channel.

    The same forward as the plain formula; the backward is written out: with x̂ the normalised
    input and N = T·W, dx = s·rstd·(dy - mean(dy) - x̂·mean(dy·x̂)), ds = Σ dy·x̂, db = Σ dy:
    one fused reduction and one elementwise pass, where autodiff of the formula takes several
    passes over the activation (tested against it in tests/test_fast_equals_reference.py).
    Statistics and arithmetic in float32; the result has x's dtype (bf16 compute).
    """
    return _mod_norm_fwd(x_BxTxWxC, s_BxC, b_BxC)[0]


def _mod_norm_fwd(x, s, b):
    mean, rstd = _norm_stats(x)
    y = (x.astype(jnp.float32) - mean) * rstd * s[:, None, None, :] + b[:, None, None, :]
    return y.astype(x.dtype), (x, mean, rstd, s)


def _mod_norm_bwd(res, dy):
    x, mean, rstd, s = res
    xhat = (x.astype(jnp.float32) - mean) * rstd
    dy = dy.astype(jnp.float32)
    db = jnp.sum(dy, axis=(1, 2))
    ds = jnp.sum(dy * xhat, axis=(1, 2))
    n = x.shape[1] * x.shape[2]
    dx = (s * rstd[:, 0, 0, :])[:, None, None, :] * (
        dy - (db / n)[:, None, None, :] - xhat * (ds / n)[:, None, None, :])
    return dx.astype(x.dtype), ds.astype(s.dtype), db.astype(s.dtype)


modulated_instance_norm.defvjp(_mod_norm_fwd, _mod_norm_bwd)


# ---------------------------------------------------------------------------------------------
# Spectral norm


class SpectralNormState(nnx.BatchStat):
    """Power-iteration vectors u, v of a spectral-normalised layer: state, never trained."""


def _l2_normalize(x: jax.Array, eps: float = SN_EPS) -> jax.Array:
    # torch.nn.functional.normalize: x / max(||x||, eps)
    return x / jnp.maximum(jnp.linalg.norm(x), eps)


class SpectralNorm(nnx.Module):
    """σ(M) by power iteration with PyTorch's `spectral_norm` semantics.

    M is the weight as a (out, in·kt·kwidth) matrix in PyTorch order. u (out,) and v (in·kt·kwidth,) start
    as normalised N(0, 1) draws. With `update_stats=True` one iteration runs:
    v ← normalize(Mᵀu), u ← normalize(Mv), both stored. σ = uᵀMv; no gradient flows into u or v,
    so dσ/dM = u vᵀ as in PyTorch. The caller divides its raw weight by σ; the raw weight is
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

    Init: weight N(0, 0.02²), bias 0 (DESIGN.md §3.1). `spectral_norm=True` divides the kernel by
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
        impl: str = "fast",
        rngs: nnx.Rngs,
    ):
        kt, kwidth = kernel_size
        self.impl = impl
        self.stride = tuple(stride)
        self.pad_t = kt // 2
        self.pad_w = pad_w
        self.kernel = nnx.Param(normal_init(0.02)(rngs.params(), (kt, kwidth, in_ch, out_ch)))
        self.bias = nnx.Param(jnp.zeros((out_ch,)))
        self.sn = SpectralNorm(out_ch, in_ch * kt * kwidth, rngs=rngs) if spectral_norm else None

    def weight(self, *, update_stats: bool = False) -> jax.Array:
        """The kernel actually applied (kernel / σ under spectral norm)."""
        kernel = self.kernel[...]
        if self.sn is None:
            return kernel
        w_mat = jnp.transpose(kernel, (3, 2, 0, 1)).reshape(kernel.shape[3], -1)  # torch order
        return kernel / self.sn(w_mat, update_stats=update_stats)

    def __call__(self, x_BxTxWxC: jax.Array, *, update_stats: bool = False) -> jax.Array:
        x = reflect_pad(x_BxTxWxC, self.pad_t, self.pad_w)
        # parameters stay float32; they are cast to the activations' dtype (bf16 compute)
        w = self.weight(update_stats=update_stats).astype(x.dtype)
        y = conv2d(x, w, self.stride, impl=self.impl)
        return y + self.bias[...].astype(y.dtype)


# Below this many input rows (batch x time x width) `ConvTranspose.upsampled` upsamples first:
# building the phase kernels (a pass over the weights) then costs more than the 1/5 it saves.
POLYPHASE_MIN_ROWS = 512


def _upsample_phase_coeffs(kt: int) -> tuple[np.ndarray, int, int]:
    """How a kt-tap time correlation (zero padding kt//2 each side) of upsample_time2(x) reads x.

    Returns (A, lo, shift): output 2i + r equals Σ_j Σ_k A[r, j, k] K[k] x[i + lo + r·shift + j]
    (j < kt//2 + 2) for x extended by repeating its edge samples, except near the two ends, where
    `_upsample_edge_rows` removes what the zero padding of the upsampled signal would not have
    contributed. Derived from u[2i] = 3/4 x[i] + 1/4 x[i-1], u[2i+1] = 3/4 x[i] + 1/4 x[i+1].
    """
    p = kt // 2
    taps = {}  # (r, x offset) -> {k: weight}
    for r in (0, 1):
        for k in range(kt):
            q = r + k - p  # output 2i + r reads u[2i + q]
            a, odd = divmod(q, 2)
            neighbour = a + 1 if odd else a - 1
            for off, wgt in ((a, 0.75), (neighbour, 0.25)):
                taps.setdefault((r, off), {}).setdefault(k, 0.0)
                taps[(r, off)][k] += wgt
    lo = [min(off for (rr, off) in taps if rr == r) for r in (0, 1)]
    n = [max(off for (rr, off) in taps if rr == r) - lo[r] + 1 for r in (0, 1)]
    assert n[0] == n[1] == p + 2 and lo[1] - lo[0] in (0, 1), (n, lo)
    A = np.zeros((2, n[0], kt), np.float32)
    for (r, off), ks in taps.items():
        for k, wgt in ks.items():
            A[r, off - lo[r], k] = wgt
    return A, lo[0], lo[1] - lo[0]


def _upsample_edge_rows(kt: int, t_out: int) -> dict[int, tuple[list[int], list[int]]]:
    """Output rows m (of t_out = 2T) that the zero padding touches: m -> (taps k reading before
    the start, taps k reading past the end). With edge-repeated x those phantom samples equal
    x[0] (start) and x[T-1] (end)."""
    p = kt // 2
    rows = {}
    for m in range(t_out):
        left = [k for k in range(kt) if m + k - p < 0]
        right = [k for k in range(kt) if m + k - p >= t_out]
        if left or right:
            rows[m] = (left, right)
    return rows


def upsampled_tconv(x_BxTxWxC: jax.Array, taps: list[jax.Array], *, impl: str = "fast") -> jax.Array:
    """correlate(upsample_time2(x), taps) with zero padding kt//2 in time (B x 2T x W x O), where
    taps[k] (C x O) is the correlation kernel at time offset k - kt//2, computed from x itself,
    phase by phase (polyphase): each output phase needs kt//2 + 2 taps of x instead of kt taps of
    the twice as long upsampled signal, 4/5 of the work for kt = 5. One convolution gives both
    phases ([even | odd] output channels); a few boundary rows get a small correction.
    The phase kernels are weighted sums of the taps, written elementwise so that XLA builds them
    in one pass (at batch 1 the kernels outweigh the activations).
    Equal to the straightforward form to float32 rounding (tests/test_fast_equals_reference.py)."""
    kt = len(taps)
    b, t, w, _ = x_BxTxWxC.shape
    A, lo, shift = _upsample_phase_coeffs(kt)
    n = A.shape[1]
    o = taps[0].shape[-1]

    def phase_tap(r, j):
        return sum(float(A[r, j, k]) * taps[k] for k in range(kt) if A[r, j, k])

    k_phase = jnp.stack([jnp.concatenate([phase_tap(0, j), phase_tap(1, j)], axis=-1) for j in range(n)])
    pad_lo, pad_hi = -lo, lo + shift + n - 1
    x_ext = jnp.pad(x_BxTxWxC, ((0, 0), (pad_lo, pad_hi), (0, 0), (0, 0)), mode="edge")
    z = conv2d(x_ext, k_phase[:, None], impl=impl)  # B x (T + shift) x W x 2O
    even, odd = z[:, :t, :, :o], z[:, shift:shift + t, :, o:]
    y = jnp.stack([even, odd], axis=2).reshape(b, 2 * t, w, o)
    # rows whose taps reach into the upsampled signal's zero padding: a few rows, updated in place
    first, last = x_BxTxWxC[:, 0], x_BxTxWxC[:, -1]
    for m, (left, right) in sorted(_upsample_edge_rows(kt, 2 * t).items()):
        c = 0.0
        if left:
            c = c + first @ sum(taps[i] for i in left)
        if right:
            c = c + last @ sum(taps[i] for i in right)
        y = y.at[:, m].add(-c.astype(y.dtype))
    return y


class ConvTranspose(nnx.Module):
    """PyTorch ConvTranspose2d kernel (kt, kwidth), stride (1, kwidth), no padding, then a crop of kt//2
    frames from each end of time: T is kept, the width is multiplied by kwidth (DESIGN.md §3.1).

    Because the width stride equals the width kernel, each input column owns its kwidth output
    columns; with stride 1 in time the crop turns the transposed conv into a zero-padded
    correlation with the time-flipped kernel. So it runs as one ordinary conv with kwidth·out output
    channels, reshaped into width. Tested against an explicit loop and lax.conv_transpose.
    Init: N(0, 0.02²), bias 0.

    `upsampled(d, e)` is the same layer applied to upsample_time2(concat[tile(e), d]) (G's skip
    connections), computed without building that input: see the method.
    """

    def __init__(self, in_ch: int, out_ch: int, kernel_size: tuple[int, int], *, impl: str = "fast",
                 rngs: nnx.Rngs):
        kt, kwidth = kernel_size
        self.impl = impl
        self.kernel = nnx.Param(normal_init(0.02)(rngs.params(), (kt, kwidth, in_ch, out_ch)))
        self.bias = nnx.Param(jnp.zeros((out_ch,)))

    def _conv_kernel(self) -> jax.Array:
        """kt x 1 x in x (kwidth·out): the time-flipped kernel of the equivalent correlation."""
        kernel = self.kernel[...]
        kt, kwidth, cin, cout = kernel.shape
        return jnp.transpose(kernel[::-1], (0, 2, 1, 3)).reshape(kt, 1, cin, kwidth * cout)

    def _to_width(self, y_BxTxWxO: jax.Array) -> jax.Array:
        b, t, w, _ = y_BxTxWxO.shape
        cout = self.kernel.shape[-1]
        return y_BxTxWxO.reshape(b, t, -1, cout) + self.bias[...].astype(y_BxTxWxO.dtype)

    def __call__(self, x_BxTxWxC: jax.Array) -> jax.Array:
        k = self._conv_kernel().astype(x_BxTxWxC.dtype)
        crop = k.shape[0] // 2
        y = conv2d(x_BxTxWxC, k, padding=((k.shape[0] - 1 - crop, crop), (0, 0)), impl=self.impl)
        return self._to_width(y)

    def upsampled(self, d_BxTxWxCd: jax.Array, e_BxTx1xCe: jax.Array | None = None) -> jax.Array:
        """self(upsample_time2(concat[tile(e, W), d])) without building that input (B x 2T x kwidth·W x out).

        * Skip (e): a tiled e is constant along the width and each input column owns its output
          columns, so e's share is computed once, on one column, and broadcast to all W.
        * Upsampling: linear x2 in time followed by a time correlation is one polyphase
          correlation of the original samples (`upsampled_tconv`).
        """
        kernel = self.kernel[...].astype(d_BxTxWxCd.dtype)
        kt, kwidth, cin, cout = kernel.shape
        ce = 0 if e_BxTx1xCe is None else e_BxTx1xCe.shape[-1]
        if ce + d_BxTxWxCd.shape[-1] != cin:
            raise ValueError(f"{ce} + {d_BxTxWxCd.shape[-1]} input channels, kernel has {cin}")

        def taps(lo, hi):  # correlation taps (C x kwidth·out): time-flipped, like _conv_kernel
            return [jnp.transpose(kernel[kt - 1 - i, :, lo:hi], (1, 0, 2)).reshape(hi - lo, kwidth * cout)
                    for i in range(kt)]

        def part(x, lo, hi):
            b, t, w, _ = x.shape
            if b * t * w >= POLYPHASE_MIN_ROWS:
                return upsampled_tconv(x, taps(lo, hi), impl=self.impl)
            # small inputs (batch-1 inference): the phase kernels would cost more than they save
            k = jnp.stack(taps(lo, hi))[:, None]
            crop = kt // 2
            return conv2d(upsample_time2(x), k, padding=((kt - 1 - crop, crop), (0, 0)), impl=self.impl)

        y = part(d_BxTxWxCd, ce, cin)
        if ce:
            y = y + part(e_BxTx1xCe, 0, ce)  # one column, broadcast over W
        return self._to_width(y)


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

    Init (DESIGN.md §3.2): A_s, a_s PyTorch default U(±1/sqrt(w_dim)); A_b N(0, 0.02²), a_b 0.
    """

    def __init__(self, channels: int, w_dim: int, *, rngs: nnx.Rngs):
        self.scale = torch_default_dense(w_dim, channels, rngs=rngs)
        self.shift = Dense(w_dim, channels, kernel_init=normal_init(0.02), bias_init=zeros_init, rngs=rngs)

    def style(self, w_BxD: jax.Array) -> tuple[jax.Array, jax.Array]:
        """(s_BxC, b_BxC) for a style code; the analysis tools read these."""
        return self.scale(w_BxD), self.shift(w_BxD)

    def __call__(self, h_BxTxWxC: jax.Array, w_BxD: jax.Array) -> jax.Array:
        s, b = self.style(w_BxD)
        return modulated_instance_norm(h_BxTxWxC, s, b)
