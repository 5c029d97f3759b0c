#!/usr/bin/env python
"""Peak memory (RSS) of training (run by hand, never in CI).

Each measurement runs in a fresh child process; the figure is the child's peak resident set
size (`ru_maxrss` from os.wait4), so it includes Python, JAX, the compiled step and XLA's
buffers. Two kinds of child:

* `step`: init_state + jitted train_step (state donated) + N steps on synthetic batches of the
  config's shapes: the training computation alone, for the small and the paper config;
* `train`: `bin/train.py --config configs/small.py --steps N` in a temporary workdir: a whole
  training run (embedded dataset, data pipeline, metrics, checkpoints, a preview).

  JAX_PLATFORMS=cpu python -m bench.bench_memory [--which small,paper] [--impl fast,xla] [--steps 3] [--no-train]
"""

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# run with -c in the repository root (run_child), so that `bench` imports as under `python -m bench.X`
CHILD = r"""
import jax
from bench.bench_train_step import bench_step_fn, fake_batch, paper_or_small
from motiongan_jax.train import objectives
from motiongan_jax.model import state as model_state
cfg, layout, num_styles = paper_or_small({which!r})
state = model_state.init_state(cfg, layout, num_styles, jax.random.key(0), impl={impl!r})
step = jax.jit(bench_step_fn(cfg, layout, num_styles), donate_argnums=0)
batch = fake_batch(cfg.train.batch_size, cfg.data.window_T, layout.num_rows, num_styles, jax.random.key(1),
                   objectives.reconstructed_rows(cfg.train))
for i in range({steps}):
    state, m = step(state, batch, jax.random.key(i))
    jax.block_until_ready(m)
"""


def run_child(argv, env=None) -> tuple[float, float, int]:
    """(peak RSS in MiB, wall seconds, exit status) of a child process started in the repository root."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(argv, env=env, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    err = proc.stderr.read().decode(errors="replace")
    proc.stderr.close()
    if status != 0:
        print(err[-2000:], file=sys.stderr)
    return usage.ru_maxrss / 1024.0, time.perf_counter() - t0, status


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--which", default="small,paper")
    ap.add_argument("--impl", default="fast,xla")
    ap.add_argument("--steps", type=int, default=3)
    ap.add_argument("--no-train", action="store_true", help="skip the bin/train.py run")
    args = ap.parse_args()
    env = dict(os.environ, JAX_PLATFORMS=os.environ.get("JAX_PLATFORMS", "cpu"))
    print(f"{os.cpu_count()} cpus; load {os.getloadavg()[0]:.2f}")
    for which in args.which.split(","):
        for impl in args.impl.split(","):
            code = CHILD.format(which=which, impl=impl, steps=args.steps)
            rss, wall, status = run_child([sys.executable, "-c", code], env)
            print(f"  step loop, {which} config [{impl}], {args.steps} steps: peak RSS {rss:7.0f} MiB "
                  f"({wall:.0f} s, exit {status})", flush=True)
    if not args.no_train:
        with tempfile.TemporaryDirectory() as tmp:
            argv = [sys.executable, str(ROOT / "bin" / "train.py"), "--config", str(ROOT / "configs" / "small.py"),
                    "--workdir", tmp, "--steps", str(max(args.steps, 2)), "--no-progress"]
            rss, wall, status = run_child(argv, dict(env, MOTIONGAN_CACHE=os.path.join(tmp, "cache")))
            print(f"  bin/train.py --config configs/small.py --steps {max(args.steps, 2)} (embedded dataset, "
                  f"checkpoints, preview): peak RSS {rss:7.0f} MiB ({wall:.0f} s, exit {status})", flush=True)


if __name__ == "__main__":
    main()
