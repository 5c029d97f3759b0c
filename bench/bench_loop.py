#!/usr/bin/env python
"""Does the training step wait for data? (run by hand, never in CI). Prints medians.

Four loops over the same jitted train_step, timed per iteration (blocks of `--block` steps,
median over `--repeats` blocks; inside a block each step's metrics are read after the next step
is dispatched, as train.py does):

* fixed:   one batch, sampled once; the step alone (no data cost at all);
* train:   `train.py`'s loop: sample_batch(arrays, key, s) then train_step, both dispatched
           asynchronously;
* ahead:   the same two programs, but batch s+1 is dispatched before step s;
* fused:   batch s+1 sampled inside the jitted step s (one XLA program, so the sampler can run
           beside the step's own ops).

"train - fixed" is what data costs the step. Also the sampler alone (jitted, blocked per call).
The small config reads the embedded dataset; the paper shapes use four long synthetic 120 fps
clips (bench_data.py's set-up: 1024 frames at step 8, FPS and rotation augmentation).

  JAX_PLATFORMS=cpu python -m bench.bench_loop [--which small,paper] [--block 20] [--repeats 5]
"""

import argparse
import os
import statistics
import time
from pathlib import Path

import jax

from bench.bench_data import long_clips
from bench.timing import load, median_time
from motiongan_jax.config import load_config, override
from motiongan_jax.data import clip_cache, sampling
from motiongan_jax.model import state as model_state
from motiongan_jax.train import objectives
from motiongan_jax.train import step as step_lib
from motiongan_jax.train.loop import make_step_fn

CONFIGS = Path(__file__).resolve().parents[1] / "configs"


def setup(which: str):
    """(cfg, arrays, layout, num_styles, step_fn) with real batches for `which`."""
    if which == "small":
        cfg = load_config(CONFIGS / "small.py")
        dataset = clip_cache.load_dataset(cfg.data, log=lambda s: None)
        clips, styles, layout = dataset.train, dataset.style_names, dataset.layout
        step_fn = make_step_fn(cfg, dataset, log=lambda s: None)
    else:
        cfg = override(load_config(CONFIGS / "paper.py", check=False),
                       ["data.data_dir=None", "data.label_rule=synthetic", "data.control_point_interval=256",
                        "data.window_stride=3"])
        clips, styles = long_clips()
        layout = clips[0].layout
        step_fn = step_lib.make_train_step(cfg, layout, len(styles))
    return cfg, sampling.build_arrays(clips, tuple(styles), cfg.data), layout, len(styles), step_fn


def per_step(loop, block: int, repeats: int) -> float:
    """Median seconds per step over `repeats` blocks of `block` steps (one untimed block first)."""
    loop(block)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        loop(block)
        times.append((time.perf_counter() - t0) / block)
    return statistics.median(times)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--which", default="small,paper")
    ap.add_argument("--block", type=int, default=20)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    print(f"jax {jax.__version__}, {os.cpu_count()} cpus; {load()}")
    for which in args.which.split(","):
        cfg, arrays, layout, num_styles, step_fn = setup(which)
        block = args.block if which == "small" else max(2, args.block // 10)
        B = cfg.train.batch_size
        k_data, k_step = jax.random.key(1), jax.random.key(2)
        sample_fn = sampling.make_sample_batch(cfg.data, B, objectives.reconstructed_rows(cfg.train))
        sample = jax.jit(sample_fn)
        train_step = jax.jit(step_fn, donate_argnums=0)

        def fused_fn(state, batch, key, arrays, s):
            state, metrics = step_fn(state, batch, key)
            return state, metrics, sample_fn(arrays, k_data, s + 1)

        fused = jax.jit(fused_fn, donate_argnums=(0, 1))
        sample_s = median_time(sample, arrays, k_data, 0, repeats=20)
        holder = {"state": model_state.init_state(cfg, layout, num_styles, jax.random.key(0)), "s": 0}
        fixed_batch = sample(arrays, k_data, 0)

        def run(n, step_once):
            """n steps of step_once(s) -> metrics, each step's metrics read after the next step is
            dispatched, as train.py does."""
            pending = None
            for _ in range(n):
                m = step_once(holder["s"])
                holder["s"] += 1
                if pending is not None:
                    jax.device_get(pending)
                pending = m
            jax.block_until_ready(pending)

        def step_on(batch, s):
            holder["state"], m = train_step(holder["state"], batch, jax.random.fold_in(k_step, s))
            return m

        def ahead_once(s):
            batch = holder.pop("ahead", None) or sample(arrays, k_data, s)
            holder["ahead"] = sample(arrays, k_data, s + 1)  # dispatched before the step that precedes it
            return step_on(batch, s)

        def fused_once(s):
            batch = holder.pop("fused", None) or sample(arrays, k_data, s)
            holder["state"], m, holder["fused"] = fused(holder["state"], batch, jax.random.fold_in(k_step, s),
                                                        arrays, s)
            return m

        loops = {"fixed": lambda s: step_on(fixed_batch, s),
                 "train": lambda s: step_on(sample(arrays, k_data, s), s),
                 "ahead": ahead_once,
                 "fused": fused_once}
        results = {name: per_step(lambda n, once=once: run(n, once), block, args.repeats)
                   for name, once in loops.items()}
        print(f"{which}: B {B}, T {cfg.data.window_T}; sampler alone {sample_s * 1e3:.2f} ms/batch; per step: "
              + ", ".join(f"{k} {v * 1e3:.1f} ms" for k, v in results.items())
              + f"; train - fixed {1e3 * (results['train'] - results['fixed']):+.1f} ms "
              f"({block} steps x {args.repeats} blocks; {load()})", flush=True)


if __name__ == "__main__":
    main()
