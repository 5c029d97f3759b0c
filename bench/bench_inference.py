#!/usr/bin/env python
"""Inference benchmark: G's forward for one walk (run by hand, never in CI). Prints medians.

The paper's G (64 base channels, CMU skeleton: 27 joints -> 81 rows, 28 styles), batch 1, z = 0, the
Latent Transform included, jitted as generate.py runs it (`model.apply.g_apply`). Lengths:
T 128 (one training window), T 1024, and a 2-minute walk in one call (15 samples/s, the paper's
120 fps / frame step 8: T 1800). Compile time is reported separately from the run time. The
2-minute path is also timed through `walk_lib.generate_motion` (G + root integration + joint
positions + floor contact), the library call behind bin/generate.py.

Reference PyTorch on this machine kind (2 threads, eval, no_grad, latent transform included):
84 ms at T 128, 0.62 s at T 1024; the goals are <= 30 ms and <= 0.2 s (docs/PERFORMANCE.md).

  JAX_PLATFORMS=cpu python -m bench.bench_inference [--impl fast,xla] [--lengths 128,1024,1800] [--repeats 7]
"""

import argparse
import os
import statistics
import time

import jax
import jax.numpy as jnp

from bench.bench_train_step import paper_or_small
from bench.timing import load
from motiongan_jax.generate import walk as walk_lib
from motiongan_jax.model import apply as model_apply
from motiongan_jax.model import state as model_state
from motiongan_jax.motion import trajectory

REFERENCE_S = {128: 0.084, 1024: 0.62}
GOAL_S = {128: 0.030, 1024: 0.2}
SAMPLES_PER_S = 15  # 120 fps, frame step 8


def walk(T: int) -> jax.Array:
    """A gently curving path at ~1.3 m/s, B x T x 3 (metres, y = 0)."""
    s = jnp.arange(T, dtype=jnp.float32) / SAMPLES_PER_S
    return jnp.stack([1.3 * s, jnp.zeros_like(s), 2.0 * jnp.sin(0.2 * s)], -1)[None]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--impl", default="fast,xla")
    ap.add_argument("--lengths", default=f"128,1024,{120 * SAMPLES_PER_S}")
    ap.add_argument("--repeats", type=int, default=7)
    args = ap.parse_args()
    cfg, layout, num_styles = paper_or_small("paper")
    print(f"jax {jax.__version__}, {os.cpu_count()} cpus; paper G, batch 1; {load()}")
    labels = jnp.array([3], jnp.int32)
    for impl in args.impl.split(","):
        state = model_state.init_state(cfg, layout, num_styles, jax.random.key(0), impl=impl)
        for T in (int(t) for t in args.lengths.split(",")):
            curve = walk(T)
            vel = trajectory.velocity(curve)
            fn = model_apply.g_apply
            t0 = time.perf_counter()
            w = model_apply.style_codes(state, labels)
            compiled = fn.lower(state, vel, w).compile()
            compile_s = time.perf_counter() - t0
            cost = compiled.cost_analysis()
            cost = cost[0] if isinstance(cost, (list, tuple)) else cost
            gflop = float(cost.get("flops", float("nan"))) / 1e9 if cost else float("nan")
            jax.block_until_ready(compiled(state, vel, w))
            times = []
            for _ in range(args.repeats):
                t0 = time.perf_counter()
                jax.block_until_ready(compiled(state, vel, w))
                times.append(time.perf_counter() - t0)
            med = statistics.median(times)
            ref = (f"; reference {REFERENCE_S[T] * 1e3:.0f} ms, goal <= {GOAL_S[T] * 1e3:.0f} ms"
                   if T in REFERENCE_S else "")
            print(f"  [{impl}] G forward T {T:5d} ({T / SAMPLES_PER_S:5.1f} s of walking): median "
                  f"{med * 1e3:7.1f} ms (min {min(times) * 1e3:.1f}, {args.repeats} runs); compile "
                  f"{compile_s:.1f} s; XLA counts {gflop:.1f} GFLOP{ref}   ({load()})", flush=True)
            if T == 120 * SAMPLES_PER_S:
                w = model_apply.style_codes(state, labels)
                walk_lib.generate_motion(state, layout, curve[0], w)  # compiles generate's own jit
                times = []
                for _ in range(max(3, args.repeats // 2)):
                    t0 = time.perf_counter()
                    walk_lib.generate_motion(state, layout, curve[0], w)
                    times.append(time.perf_counter() - t0)
                print(f"  [{impl}] walk_lib.generate_motion, 2-minute walk (T {T}), one call: median "
                      f"{statistics.median(times) * 1e3:.1f} ms   ({load()})", flush=True)


if __name__ == "__main__":
    main()
