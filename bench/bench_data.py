#!/usr/bin/env python
"""Data-pipeline benchmark (run by hand, never in CI). Prints medians.

1. Parse + FK + cache every BVH of a directory (default: bandai/dataset-2 under
   $MOTIONGAN_SHARED_DATA, README), cold (empty cache) and warm (cache hits).
2. Batches of 24 paper-size windows (1024 frames at step 8 -> T 128, FPS x0.5/1/1.5 and rotation
   augmentation, noisy spline curves) from cached arrays. Reference PyTorch loader on this machine
   kind: 0.58-0.86 s per batch (docs/PERFORMANCE.md).

  JAX_PLATFORMS=cpu python -m bench.bench_data [--data DIR] [--repeats 3]
"""

import argparse
import os
import statistics
import tempfile
import time
from pathlib import Path

import jax
import numpy as np

from motiongan_jax.config import DataConfig
from motiongan_jax.data import clip_cache, file_labels, sampling, synthetic
from motiongan_jax.motion import kinematics
from motiongan_jax.motion.representation import (
    CMU_UNIT_M,
    layout_from_skeleton,
    to_rows,
)

SHARED = Path(os.environ.get("MOTIONGAN_SHARED_DATA", Path(__file__).resolve().parents[2] / "shared" / "data"))


def bench_preprocess(data_dir: Path, repeats: int) -> None:
    entries = file_labels.discover(data_dir, "bandai")
    cold, warm = [], []
    for _ in range(repeats):
        with tempfile.TemporaryDirectory() as tmp:
            os.environ["MOTIONGAN_CACHE"] = tmp
            t0 = time.perf_counter()
            for p, lab in entries:
                clip_cache.preprocess_clip(p, lab, 0.01, 0)
            cold.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            for p, lab in entries:
                clip_cache.preprocess_clip(p, lab, 0.01, 0)
            warm.append(time.perf_counter() - t0)
    print(f"preprocess {len(entries)} files of {data_dir.name}: cold (parse+FK+cache write) median "
          f"{statistics.median(cold):.2f} s, warm (cache hits) median {statistics.median(warm):.2f} s "
          f"over {repeats} runs")


def long_clips() -> tuple[list, list[str]]:
    """Four long 120 fps synthetic clips on the CMU skeleton, like the reference's own timing
    set-up (2400-3300 frames each), and their style names."""
    clips = []
    styles = list(synthetic.STYLES)[:4]
    for i, name in enumerate(styles):
        motion = synthetic.generate_clip(synthetic.STYLES[name], key_or_seed=i, num_frames=2400 + 300 * i, fps=120.0)
        layout = layout_from_skeleton(motion.skeleton, CMU_UNIT_M)
        root, pose = to_rows(kinematics.world_positions(motion)[1:] * CMU_UNIT_M, layout)
        clips.append(clip_cache.Clip(name, file_labels.FileLabel(name, 1), 120.0, root.astype(np.float32),
                               pose.astype(np.float32), layout))
    return clips, styles


def bench_batches(repeats: int) -> None:
    clips, styles = long_clips()
    cfg = DataConfig(frame_nums=1024, frame_step=8, control_point_interval=256, window_stride=3)
    arrays = sampling.build_arrays(clips, tuple(styles), cfg)
    sample = jax.jit(sampling.make_sample_batch(cfg, 24))
    key = jax.random.key(0)
    t0 = time.perf_counter()
    jax.block_until_ready(sample(arrays, key, 0))
    compile_s = time.perf_counter() - t0
    times = []
    for step in range(1, 1 + 50 * repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(sample(arrays, key, step))
        times.append(time.perf_counter() - t0)
    med = statistics.median(times)
    print(f"batch of 24 paper-size windows (T 128, fps+rotation aug, noisy curves): median {med * 1e3:.2f} ms "
          f"over {len(times)} batches (compile {compile_s:.1f} s); reference 580-860 ms -> "
          f"{0.58 / med:.0f}-{0.86 / med:.0f}x")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", type=Path, default=SHARED / "bandai" / "dataset-2")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    print(f"jax {jax.__version__} on {jax.devices()[0].platform}, {os.cpu_count()} cpus")
    if args.data.is_dir():
        bench_preprocess(args.data, args.repeats)
    else:
        print(f"skipping preprocessing benchmark: {args.data} not found")
    bench_batches(args.repeats)


if __name__ == "__main__":
    main()
