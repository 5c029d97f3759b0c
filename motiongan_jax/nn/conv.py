"""2-D convolution (NHWC input, HWIO kernel) in the form XLA:CPU runs fastest.

At this model's shapes XLA:CPU runs a convolution whose `padding` is all zero much slower than
one with any padding (its library kernel takes a slow path for VALID), runs input gradients at
full speed, and runs weight gradients far below the matrix products they amount to, the
transposed convolutions' worst (figures: docs/PERFORMANCE.md, "Faster work"; bench/bench_conv.py).

So `conv2d(..., impl="fast")` computes exactly the same sums as `lax.conv_general_dilated`,
differently scheduled:

* forward: the XLA convolution; a VALID one gets one extra zero row of time padding and the
  extra output row is dropped (bit-identical result). Heads with a few output channels
  (c_traj, dc0_0) multiply x by all taps at once and add the shifted slices instead;
* input gradient: XLA's, unchanged;
* width groups: a kernel whose width equals its width stride (D's convs) or spans the whole
  width (c_traj) sees disjoint column groups; forward and input gradient fold them into the
  channels, a kt x 1 convolution (XLA's input gradient of c_traj's 5 x 81 kernel is slow);
* weight gradient on CPU, stride 1: one matrix product per chunk of samples, summed by a `lax.scan`, of
  the shifted windows of x (im2col) against dy, where each kernel tap (time or width) is taken
  either as a window of x or as dy shifted into place, whichever makes the smaller matrices;
  the window matrix never exists for the whole batch (strided convolutions, D's, and other
  backends: XLA's own).

`impl="xla"` is the straightforward `lax.conv_general_dilated`, the reference the tests compare
against. Both agree to float32 rounding (the weight gradient sums in another order).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp

from motiongan_jax.config import ConvImpl, choices

_DIMS = ("NHWC", "HWIO", "NHWC")
# Window-matrix bytes per scan chunk of the weight gradient: big enough for efficient matrix
# products, small enough not to pay page faults on gigabytes of fresh memory every step.
_CHUNK_BYTES = 64 << 20
# Convolutions with at most this many kt·kw·O output columns run "output side" (_output_side).
_NARROW_OUTPUT = 64

Padding = tuple[tuple[int, int], tuple[int, int]]


def _xla_conv(x, kernel, stride, padding):
    return jax.lax.conv_general_dilated(x, kernel, window_strides=stride, padding=padding,
                                        dimension_numbers=_DIMS)


def _out_size(n: int, k: int, s: int) -> int:
    return (n - k) // s + 1


def _output_side(x, kernel):
    """Stride-1 VALID correlation as x·[all taps] (one matrix product, kt·kw·O wide) followed by
    the sum of the shifted slices: for heads with a few output channels (c_traj, dc0_0), where a
    convolution kernel runs at a few GFLOP/s."""
    kt, kw, c, o = kernel.shape
    b, t, w, _ = x.shape
    to, wo = t - kt + 1, w - kw + 1
    z = jax.lax.dot_general(x, jnp.transpose(kernel, (2, 0, 1, 3)).reshape(c, kt * kw * o),
                            (((3,), (0,)), ((), ()))).reshape(b, t, w, kt * kw, o)
    return sum(z[:, i:i + to, j:j + wo, i * kw + j] for i in range(kt) for j in range(kw))


def _forward(x, kernel, stride, padding):
    kt, kw, _, o = kernel.shape
    if stride == (1, 1) and padding == ((0, 0), (0, 0)) and kt * kw * o <= _NARROW_OUTPUT:
        return _output_side(x, kernel)
    if any(p for pair in padding for p in pair):
        return _xla_conv(x, kernel, stride, padding)
    to, wo = _out_size(x.shape[1], kt, stride[0]), _out_size(x.shape[2], kw, stride[1])
    # one zero row more at the end of time; its output row (if any) is dropped
    y = _xla_conv(x, kernel, stride, ((0, 1), (0, 0)))
    return y[:, :to, :wo]


def _chunk(batch: int, bytes_per_sample: int) -> int:
    """Largest divisor of the batch whose matrices fit _CHUNK_BYTES (at least 1)."""
    best = 1
    for c in range(1, batch + 1):
        if batch % c == 0 and c * bytes_per_sample <= _CHUNK_BYTES:
            best = c
    return best


def _gather(x, axis: int, k: int, n_out: int, stride: int = 1):
    """The k shifted (strided) windows of length n_out along `axis` (1 time, 2 width), side by
    side on the channel axis, shift-major."""
    parts = [jax.lax.slice_in_dim(x, i, i + stride * (n_out - 1) + 1, stride=stride, axis=axis) for i in range(k)]
    return parts[0] if k == 1 else jnp.concatenate(parts, axis=-1)


def _spread(dy, axis: int, k: int, n_full: int):
    """dy placed at the k shifts i (zero elsewhere) of a length-n_full axis, side by side."""
    n = dy.shape[axis]
    pads = [[(0, 0)] * dy.ndim for _ in range(k)]
    for i in range(k):
        pads[i][axis] = (i, n_full - n - i)
    parts = [jnp.pad(dy, pads[i]) for i in range(k)]
    return parts[0] if k == 1 else jnp.concatenate(parts, axis=-1)


def _weight_grad_plan(x_shape, dy_shape, kt: int, kw: int, stride: tuple[int, int]):
    """For dW[i, j] = Σ x[t·st + i, w·sw + j]ᵀ dy[t, w]: which taps are gathered from x (the
    windows) and which spread from dy (dy shifted into place). Either gives the same sums; each
    tap multiplies its side's width, so pick the combination with the smallest matrices.
    Strided axes gather from x. Returns (time_from_x, width_from_x)."""
    _, t, w, c = x_shape
    _, to, wo, o = dy_shape
    best = None
    for tx in ((True,) if stride[0] > 1 else (True, False)):
        for wx in ((True,) if stride[1] > 1 else (True, False)):
            rows = (to if tx else t) * (wo if wx else w)
            size = rows * ((kt if tx else 1) * (kw if wx else 1) * c + (1 if tx else kt) * (1 if wx else kw) * o)
            if best is None or size < best[0]:
                best = (size, tx, wx)
    return best[1], best[2]


def _weight_grad_matrices(xp, dy, kt: int, kw: int, stride: tuple[int, int], plan):
    """(a, b): dL/dkernel = Σ_rows aᵀ b, rearranged by `_weight_grad_finish`. Width taps are
    placed first, so each side's channels end up (time tap, width tap, channel)."""
    tx, wx = plan
    st, sw = stride
    _, to, wo, _ = dy.shape
    a, b = xp, dy
    if wx:
        a = _gather(a, 2, kw, wo, sw)
    else:
        b = _spread(b, 2, kw, xp.shape[2])
    if tx:
        a = _gather(a, 1, kt, to, st)
    else:
        b = _spread(b, 1, kt, xp.shape[1])
    return a, b


def _weight_grad_finish(g, kt: int, kw: int, c: int, o: int, plan):
    tx, wx = plan
    g = g.reshape(kt if tx else 1, kw if wx else 1, c, 1 if tx else kt, 1 if wx else kw, o)
    return jnp.transpose(g, (0, 3, 1, 4, 2, 5)).reshape(kt, kw, c, o)


def weight_grad(xp_BxTxWxC: jax.Array, dy_BxToxWoxO: jax.Array, kt: int, kw: int,
                stride: tuple[int, int]) -> jax.Array:
    """dL/dkernel (kt, kw, C, O) of a VALID convolution of xp, as matrix products over chunks of
    the batch (summed by lax.scan when the whole batch's matrices would exceed _CHUNK_BYTES)."""
    b, c, o = xp_BxTxWxC.shape[0], xp_BxTxWxC.shape[-1], dy_BxToxWoxO.shape[-1]
    plan = _weight_grad_plan(xp_BxTxWxC.shape, dy_BxToxWoxO.shape, kt, kw, stride)
    a_shape, b_shape = jax.eval_shape(lambda x, d: _weight_grad_matrices(x, d, kt, kw, stride, plan),
                                      xp_BxTxWxC[:1], dy_BxToxWoxO[:1])
    n = _chunk(b, (a_shape.size + b_shape.size) * xp_BxTxWxC.dtype.itemsize)
    axes = (0, 1, 2)

    # the narrow matrix first when it is much narrower (c_traj's weight gradient: bench/bench_conv.py)
    narrow_first = b_shape.shape[-1] * 4 < a_shape.shape[-1]

    def chunk_grad(xc, dyc):
        a, m = _weight_grad_matrices(xc, dyc, kt, kw, stride, plan)
        # XLA:CPU has no bf16 x bf16 -> f32 matrix product: accumulate bf16 inputs in float32
        a, m = a.astype(jnp.promote_types(a.dtype, jnp.float32)), m.astype(jnp.promote_types(m.dtype, jnp.float32))
        if narrow_first:
            return jax.lax.dot_general(m, a, ((axes, axes), ((), ())), preferred_element_type=jnp.float32).T
        return jax.lax.dot_general(a, m, ((axes, axes), ((), ())), preferred_element_type=jnp.float32)

    if n == b:
        g = chunk_grad(xp_BxTxWxC, dy_BxToxWoxO)
    else:
        xs = xp_BxTxWxC.reshape(b // n, n, *xp_BxTxWxC.shape[1:])
        dys = dy_BxToxWoxO.reshape(b // n, n, *dy_BxToxWoxO.shape[1:])

        def body(acc, pair):
            return acc + chunk_grad(*pair), None

        g, _ = jax.lax.scan(body, jnp.zeros((a_shape.shape[-1], b_shape.shape[-1]), jnp.float32), (xs, dys))
    return _weight_grad_finish(g, kt, kw, c, o, plan)


def _fold_width(x, kernel, stride, padding):
    """Disjoint width groups (kernel width = width stride, or one output column, no width
    padding) folded into the channels: (x, kernel, stride) of an equal kt x 1 convolution, or
    None. D's convs, ec1_0 and c_traj's full-width kernel, whose input gradient XLA runs far below
    its few FLOPs otherwise (docs/PERFORMANCE.md, "Faster work")."""
    kt, kw, cin, cout = kernel.shape
    b, t, w, c = x.shape
    wo = _out_size(w + sum(padding[1]), kw, stride[1])
    if kw == 1 or padding[1] != (0, 0) or not (stride[1] == kw or wo == 1):
        return None
    return (x[:, :, : wo * kw].reshape(b, t, wo, kw * c), kernel.reshape(kt, 1, kw * cin, cout),
            (stride[0], 1))


@functools.partial(jax.custom_vjp, nondiff_argnums=(2, 3))
def _fast_conv(x, kernel, stride, padding):
    folded = _fold_width(x, kernel, stride, padding)
    return _forward(x, kernel, stride, padding) if folded is None else _forward(*folded, padding)


def _fast_conv_fwd(x, kernel, stride, padding):
    return _fast_conv(x, kernel, stride, padding), (x, kernel)


def _fast_conv_bwd(stride, padding, res, dy):
    x, kernel = res
    folded = _fold_width(x, kernel, stride, padding)
    xf, kf, sf = (x, kernel, stride) if folded is None else folded
    _, x_vjp = jax.vjp(lambda x_: _xla_conv(x_, kf, sf, padding), xf)
    (dx,) = x_vjp(dy)
    if folded is not None:  # back to x's columns (an unused trailing column gets 0)
        dx = dx.reshape(*dx.shape[:2], -1, x.shape[-1])
        dx = jnp.pad(dx, ((0, 0), (0, 0), (0, x.shape[2] - dx.shape[2]), (0, 0)))
    if jax.default_backend() == "cpu" and sf == (1, 1):
        (pt0, pt1), (pw0, pw1) = padding
        xp = jnp.pad(xf, ((0, 0), (pt0, pt1), (pw0, pw1), (0, 0))) if (pt0 or pt1 or pw0 or pw1) else xf
        d_kernel = weight_grad(xp, dy, kf.shape[0], kf.shape[1], sf).reshape(kernel.shape).astype(kernel.dtype)
    else:  # strided (D's convs: XLA's is as fast, on the unfolded form) and other backends
        _, k_vjp = jax.vjp(lambda k_: _xla_conv(x, k_, stride, padding), kernel)
        (d_kernel,) = k_vjp(dy)
    return dx, d_kernel


_fast_conv.defvjp(_fast_conv_fwd, _fast_conv_bwd)


def conv2d(x_BxTxWxC: jax.Array, kernel: jax.Array, stride: tuple[int, int] = (1, 1),
           padding: Padding = ((0, 0), (0, 0)), *, impl: ConvImpl = "fast") -> jax.Array:
    """Cross-correlation of an NHWC input with an HWIO kernel, zero `padding` ((t0, t1), (w0, w1)),
    no bias: `lax.conv_general_dilated` semantics. impl "fast" (see the module doc) or "xla"."""
    stride = (int(stride[0]), int(stride[1]))
    padding = tuple((int(a), int(b)) for a, b in padding)
    if impl == "xla":
        return _xla_conv(x_BxTxWxC, kernel, stride, padding)
    if impl != "fast":
        raise ValueError(f"conv impl must be one of {choices(ConvImpl)}, got {impl!r}")
    return _fast_conv(x_BxTxWxC, kernel, stride, padding)
