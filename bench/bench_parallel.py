#!/usr/bin/env python
"""The data-parallel step's scaling (run by hand, never in CI). Prints medians.

Times train.py's loop (sample the global batch, give each device its rows, the sharded step,
metrics read one step late) at one global batch in three layouts, each in fresh child processes:

* 1x1: one process, one device (the plain jitted step);
* 1x2: one process, two devices (XLA_FLAGS=--xla_force_host_platform_device_count=2);
* 2x1: two processes on 127.0.0.1, one device each (jax.distributed, gloo collectives on CPU).

On a CPU the forced devices share the machine's cores, so this shows the cost of splitting the
step and of the collectives, not a speed-up; on GPUs (drop JAX_PLATFORMS=cpu; the layouts are
then real devices) it shows the scaling.

  JAX_PLATFORMS=cpu python -m bench.bench_parallel [--which small] [--layouts 1x1,1x2,2x1]
                                                   [--block 10] [--repeats 5] [--set a=b ...]
"""

import argparse
import os
import socket
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def child(args) -> None:
    import jax

    if args.num_processes > 1:
        jax.distributed.initialize(args.coordinator, args.num_processes, args.process_id)
    from bench.timing import load
    from motiongan_jax.config import load_config, override
    from motiongan_jax.data import clip_cache, sampling
    from motiongan_jax.model import state as model_state
    from motiongan_jax.train import objectives, parallel
    from motiongan_jax.train.loop import make_step_fn

    cfg = override(load_config(ROOT / "configs" / f"{args.which}.py"), args.set)
    dataset = clip_cache.load_dataset(cfg.data, log=lambda s: None)
    arrays = sampling.build_arrays(dataset.train, dataset.style_names, cfg.data)
    B = cfg.train.batch_size
    step_fn = make_step_fn(cfg, dataset, log=lambda s: None)

    def keyed_step(state, batch, key, s):
        return step_fn(state, batch, jax.random.fold_in(key, s))

    sample = jax.jit(sampling.make_sample_batch(cfg.data, B, objectives.reconstructed_rows(cfg.train)))
    state = model_state.init_state(cfg, dataset.layout, dataset.num_styles, jax.random.key(0))
    k_data, key = jax.random.key(1), jax.random.key(2)
    if jax.device_count() > 1:
        mesh = parallel.data_mesh()
        step = parallel.shard_step(keyed_step, mesh, B, num_replicated=2)
        state, key = parallel.put_state(state, mesh), parallel.put_key(key, mesh)
        place = lambda b: parallel.global_batch(b, mesh)  # noqa: E731
    else:
        step, place = jax.jit(keyed_step, donate_argnums=0), (lambda b: b)
    holder = {"state": state, "s": 0}

    def run(n):
        pending = None
        for _ in range(n):
            s = holder["s"]
            holder["state"], m = step(holder["state"], place(sample(arrays, k_data, s)), key, s)
            holder["s"] += 1
            if pending is not None:
                jax.device_get(pending)
            pending = m
        jax.device_get(pending)

    t0 = time.perf_counter()
    run(1)
    first = time.perf_counter() - t0
    run(args.block)
    times = []
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        run(args.block)
        times.append((time.perf_counter() - t0) / args.block)
    if jax.process_index() == 0:
        print(f"RESULT {args.which} B {B}: {jax.process_count()} process(es) x {jax.local_device_count()} device(s): "
              f"{statistics.median(times) * 1e3:.1f} ms/step (min {min(times) * 1e3:.1f}, max "
              f"{max(times) * 1e3:.1f}; first step with compile {first:.1f} s; {load()})", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--which", default="small")
    ap.add_argument("--layouts", default="1x1,1x2,2x1")
    ap.add_argument("--block", type=int, default=10)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--set", nargs="+", action="extend", default=[])
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--coordinator", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--num-processes", type=int, default=1, help=argparse.SUPPRESS)
    ap.add_argument("--process-id", type=int, default=0, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        return child(args)
    # children run as `python -m bench.bench_parallel` in the repository root, where `bench` imports
    common = [sys.executable, "-m", "bench.bench_parallel", "--child", "--which", args.which,
              "--block", str(args.block), "--repeats", str(args.repeats)] + (["--set", *args.set] if args.set else [])
    for layout in args.layouts.split(","):
        procs, devices = (int(x) for x in layout.split("x"))
        env = dict(os.environ)
        if devices > 1:
            env["XLA_FLAGS"] = (env.get("XLA_FLAGS", "") + f" --xla_force_host_platform_device_count={devices}").strip()
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            port = s.getsockname()[1]
        runs = [subprocess.Popen(common + ["--coordinator", f"127.0.0.1:{port}", "--num-processes", str(procs),
                                           "--process-id", str(i)], env=env, cwd=ROOT, stdout=subprocess.PIPE,
                                 text=True)
                for i in range(procs)]
        for r in runs:
            out, _ = r.communicate()
            for line in out.splitlines():
                if line.startswith("RESULT"):
                    print(line[7:], flush=True)


if __name__ == "__main__":
    main()
