#!/usr/bin/env python
"""G's and D's convolutions one by one at the paper's shapes (run by hand, never in CI).

For every layer: forward, input gradient (dx) and weight gradient (dW), each jitted alone, with
`conv.conv2d(impl="xla")` (plain lax.conv_general_dilated, VALID on the padded input, as the
straightforward layers call it) and `impl="fast"` (nn/conv.py). Prints medians, GFLOP/s (2 flops
per multiply-add) and the load average; the machine is shared, so compare rows taken together.

The tconv rows are the layers as `ConvTranspose.__call__` runs them (a zero-padded correlation
with kwidth·out channels); "dc1_1 poly" etc. are the polyphase form of `ConvTranspose.upsampled`
(x at half the time resolution, (kt//2 + 2) taps, [even | odd] channels) on the skip-free part.

  JAX_PLATFORMS=cpu python -m bench.bench_conv [--layers dc1_0,dc1_1] [--impl xla,fast] [--batch 24]
"""

import argparse
import os

import jax

from bench.timing import load, median_time
from motiongan_jax.nn.conv import conv2d

# name: (T, W, C_in, C_out, kernel (kt, kwidth), stride, padding inside the conv) of the padded input
# the layer hands to the convolution (reflect padding already applied for convs).
LAYERS = {
    "dc1_0": (132, 83, 128, 64, (5, 3), (1, 1), ((0, 0), (0, 0))),
    "dc1_1": (128, 27, 256, 384, (5, 1), (1, 1), ((2, 2), (0, 0))),
    "dc1_1 poly": (69, 27, 128, 768, (4, 1), (1, 1), ((0, 0), (0, 0))),
    "dc2_0": (68, 29, 256, 128, (5, 3), (1, 1), ((0, 0), (0, 0))),
    "dc2_1": (64, 9, 512, 768, (5, 1), (1, 1), ((2, 2), (0, 0))),
    "dc2_1 poly": (37, 9, 256, 1536, (4, 1), (1, 1), ((0, 0), (0, 0))),
    "dc3_0": (36, 11, 512, 256, (5, 3), (1, 1), ((0, 0), (0, 0))),
    "dc3_1": (32, 3, 512, 1536, (5, 1), (1, 1), ((2, 2), (0, 0))),
    "dc3_1 poly": (21, 3, 512, 3072, (4, 1), (1, 1), ((0, 0), (0, 0))),
    "heads c_traj": (132, 81, 64, 3, (5, 81), (1, 1), ((0, 0), (0, 0))),
    "D c0_0": (132, 81, 2, 64, (5, 3), (2, 3), ((0, 0), (0, 0))),
    "D c1_0": (68, 27, 64, 128, (5, 3), (2, 3), ((0, 0), (0, 0))),
    "D c2_0": (36, 9, 128, 256, (5, 3), (2, 3), ((0, 0), (0, 0))),
}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--layers", default=",".join(LAYERS))
    ap.add_argument("--impl", default="xla,fast")
    ap.add_argument("--batch", type=int, default=24)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    print(f"jax {jax.__version__}, {os.cpu_count()} cpus, batch {args.batch}; {load()}")
    print(f"  {'layer':13s} {'impl':5s} {'fwd s':>7s} {'GF/s':>5s} {'dx s':>7s} {'GF/s':>5s} {'dW s':>7s} {'GF/s':>5s}")
    for name in args.layers.split(","):
        t, w, cin, cout, (kt, kwidth), stride, padding = LAYERS[name]
        x = jax.random.normal(jax.random.key(0), (args.batch, t, w, cin))
        k = 0.02 * jax.random.normal(jax.random.key(1), (kt, kwidth, cin, cout))
        y = jax.eval_shape(lambda a, b: conv2d(a, b, stride, padding, impl="xla"), x, k)
        dy = jax.random.normal(jax.random.key(2), y.shape)
        flop = 2 * y.size * kt * kwidth * cin
        for impl in args.impl.split(","):
            def f(a, b, impl=impl):
                return conv2d(a, b, stride, padding, impl=impl)

            fwd = jax.jit(f)
            dx = jax.jit(lambda a, b, d, f=f: jax.vjp(lambda a_: f(a_, b), a)[1](d)[0])
            dw = jax.jit(lambda a, b, d, f=f: jax.vjp(lambda b_: f(a, b_), b)[1](d)[0])
            secs = [median_time(fn, *fargs, repeats=args.repeats)
                    for fn, fargs in ((fwd, (x, k)), (dx, (x, k, dy)), (dw, (x, k, dy)))]
            cells = " ".join(f"{s:7.3f} {flop / s / 1e9:5.0f}" for s in secs)
            print(f"  {name:13s} {impl:5s} {cells}   ({load()})", flush=True)


if __name__ == "__main__":
    main()
