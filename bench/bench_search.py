#!/usr/bin/env python
"""Style search timing (run by hand, never in CI): what `bin/generate.py --style-from` and the
demo's upload wait for. Prints the first search in a fresh process (G's search program compiled,
or loaded from the persistent compilation cache when --cache names a folder that holds it) and
the median of the next ones, wall clock and this process's CPU time (on a shared machine the CPU
time is the steadier figure), with the load average.

The model is the shipped one (or --workdir RUN / --model FILE.npz); the clip a held-out clip of
the embedded dataset (or --clip FILE.bvh, on the model's skeleton or one it retargets from). The
goal: <= 10 s on 2 cores.

  JAX_PLATFORMS=cpu python -m bench.bench_search [--clip FILE.bvh] [--repeats 3] [--cache DIR]
"""

import argparse
import os
import statistics
import time

import jax

from bench.timing import load


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--workdir", default=None)
    ap.add_argument("--model", default=None)
    ap.add_argument("--clip", default=None, help="default: the embedded dataset's OldMan_05.bvh (held out)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--cache", default=None, help="a persistent compilation cache folder (default: none)")
    args = ap.parse_args()
    if args.cache:
        jax.config.update("jax_compilation_cache_dir", args.cache)
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)

    from motiongan_jax.analysis import clips, search, style_space
    from motiongan_jax.data import synthetic
    from motiongan_jax.model import pretrained

    t0 = time.perf_counter()
    state, meta, cfg, layout = pretrained.load_model(args.workdir, model=args.model)
    clip = args.clip or synthetic.default_dataset_dir() / "OldMan_05.bvh"
    codes = style_space.label_codes(state, meta["style_names"], k=1).zero_CxD
    root, pose, fps = clips.load_motion(clip, meta, cfg, layout)
    target = clips.model_rate_windows(root, pose, fps, meta, cfg, layout, spread=search.WINDOWS, phase=True)
    print(f"jax {jax.__version__}, {os.cpu_count()} cpus; {cfg.name}, {len(meta['style_names'])} styles; "
          f"loaded in {time.perf_counter() - t0:.1f} s; {load()}")
    times, cpu = [], []
    for i in range(1 + args.repeats):
        c0 = time.process_time()
        found = search.search_style(state, codes, meta["style_names"], target)
        times.append(found.seconds)
        cpu.append(time.process_time() - c0)
        print(f"search {i}: {found.seconds:.2f} s wall, {cpu[-1]:.2f} s CPU -> {found.mix_text()} ({load()})",
              flush=True)
    print(f"first (compile{' or cache' if args.cache else ''}) {times[0]:.2f} s wall, {cpu[0]:.2f} s CPU; then "
          f"median {statistics.median(times[1:]):.2f} s wall, {statistics.median(cpu[1:]):.2f} s CPU over "
          f"{args.repeats}; {load()}")


if __name__ == "__main__":
    main()
