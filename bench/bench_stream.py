#!/usr/bin/env python
"""Streaming generation's cost (generate/stream.py; run by hand, never in CI). Prints medians.

One walker with the shipped model (or --workdir/--model) steered along a wandering heading:
 * server time per streamed step: one `Walker.advance` of --step samples (G on one window, the
   phase clock, blending, integration, the floor), warm (the window's compile is timed apart);
 * walkers one process holds at --hz: how many advances of one sample per 1/hz s fit in a
   second, i.e. 1 / (hz x the median advance time) walkers stepped one after another
   (conservative: walkers are not batched into one G call);
 * latency from lookahead: a sample is emitted lookahead / rate seconds after its path arrives.
The machine is shared: every figure is printed with the load average (bench.timing.load).

  JAX_PLATFORMS=cpu python -m bench.bench_stream [--steps 60] [--step 1] [--hz 30]
"""

import argparse
import os
import statistics
import time

import numpy as np

from bench.timing import load


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--steps", type=int, default=60, help="timed advances")
    ap.add_argument("--step", type=int, default=1, help="samples per advance")
    ap.add_argument("--hz", type=float, default=30.0, help="advances per second each walker needs")
    ap.add_argument("--lookahead", type=int, default=None)
    ap.add_argument("--workdir", default=None)
    ap.add_argument("--model", default=None)
    args = ap.parse_args()

    from motiongan_jax.generate import stream, walk
    from motiongan_jax.model import apply as model_apply
    from motiongan_jax.train import pretrained

    print(f"{load()}, {os.cpu_count()} CPUs visible", flush=True)
    state, meta, cfg, layout = pretrained.load_model(args.workdir, None, "ema", args.model)
    rate = walk.sample_rate(meta, cfg)
    w = np.asarray(model_apply.style_codes(state, [0]))[0]
    kw = {} if args.lookahead is None else {"lookahead": args.lookahead}
    wk = stream.Walker(state, layout, w, rate, **kw)
    rng = np.random.default_rng(0)
    heading = 0.0

    def feed(n):
        nonlocal heading
        heading += rng.normal(0, 0.05)
        wk.feed_steps(np.tile([np.cos(heading), np.sin(heading)], (n, 1)), np.full(n, 1.2))

    feed(wk.lookahead + args.step)
    t0 = time.perf_counter()
    wk.advance(args.step)
    first = time.perf_counter() - t0
    times = []
    for _ in range(args.steps):
        feed(args.step)
        t0 = time.perf_counter()
        wk.advance(args.step)
        times.append(time.perf_counter() - t0)
    med = statistics.median(times)
    print(f"rate {rate:g} samples/s, window {wk.window} samples (history {wk.history}, lookahead {wk.lookahead}), "
          f"lookahead latency {wk.lookahead / rate:.2f} s")
    print(f"first advance (compile included): {first:.2f} s")
    print(f"advance of {args.step} sample(s): median {1e3 * med:.1f} ms, p90 {1e3 * np.percentile(times, 90):.1f} ms "
          f"over {args.steps}")
    print(f"walkers at {args.hz:g} Hz in one process (sequential): {int(1 / (args.hz * med))}")
    print(f"state after {wk.emitted} samples: {wk.state_size()} numbers; {load()}")


if __name__ == "__main__":
    main()
