"""Times curves.window_curves on a paper-size batch after compilation (not a test).

B = 24 windows of 512, 1024 and 1536 frames (FPS augmentation steps 4, 8, 12) padded to 1536,
control points every 256 frames, T = 128 points, noise 0.02. Prints the median of 50 runs.

    JAX_PLATFORMS=cpu python -m bench.bench_curves [--runs 50]
"""

from __future__ import annotations

import argparse
import time

import jax
import numpy as np

from motiongan_jax.data import curves


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=50)
    ap.add_argument("--batch", type=int, default=24)
    args = ap.parse_args()
    B, N, T, interval = args.batch, 1536, 128, 256
    rng = np.random.default_rng(0)
    # Walk-like paths: ~1.3 m/s at 120 fps with a slowly drifting heading.
    heading = np.cumsum(rng.normal(0, 0.01, (B, N)), axis=1)
    step = 1.3 / 120 * (1 + 0.2 * np.sin(np.arange(N) / 40.0))
    path = np.cumsum(step[:, None] * np.stack([np.cos(heading), np.sin(heading)], -1), axis=1)
    path = path.astype(np.float32)
    length = np.array([(512, 1024, 1536)[b % 3] for b in range(B)], np.int32)
    fn = jax.jit(curves.window_curves, static_argnames=("T", "interval"))
    key = jax.random.key(0)

    t0 = time.perf_counter()
    jax.block_until_ready(fn(path, length, T=T, interval=interval, noise=0.02, key=key))
    compile_s = time.perf_counter() - t0
    times = []
    for i in range(args.runs):
        k = jax.random.fold_in(key, i)
        t0 = time.perf_counter()
        jax.block_until_ready(fn(path, length, T=T, interval=interval, noise=0.02, key=k))
        times.append(time.perf_counter() - t0)
    print(f"window_curves B={B} N={N} T={T} interval={interval} on {jax.devices()[0].platform}: "
          f"compile {compile_s:.2f} s, median {1e3 * np.median(times):.2f} ms over {args.runs} "
          f"runs (min {1e3 * min(times):.2f} ms)")


if __name__ == "__main__":
    main()
