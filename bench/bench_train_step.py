#!/usr/bin/env python
"""Training-step benchmark (run by hand, never in CI). Prints medians.

Times one jitted train_step (D update then G update, state donated) on synthetic batches of the
right shapes: the paper's (B 24, T 128, CMU skeleton 27 joints -> 81 rows, 28 styles, 64 base channels) and
the small config's. Reports compile time, median wall and process-CPU seconds per step, the load
average (the machine is shared: compare runs taken close together) and XLA's flop count of the
compiled step. Reference PyTorch on this machine kind, 2 threads: median 8.57 s per iteration
at the paper's shapes (G forward 3.1 s, D update 0.24 s, G update 5.0 s).

`--impl xla` times the straightforward convolutions (tile + concat skips, upsample then tconv,
plain lax.conv), `--impl fast` (default) the rewrites of nn/conv.py and nn/generator.py.

`--dtype bfloat16` times mixed precision (bf16 activations, float32 parameters and optimizer
state). On a GPU (drop JAX_PLATFORMS=cpu) it also prints it/s and the allocator's peak memory.

  JAX_PLATFORMS=cpu python -m bench.bench_train_step [--which paper,small] [--impl fast,xla]
                                                     [--dtype float32,bfloat16] [--repeats 5]
"""

import argparse
import os
import statistics
import time
from pathlib import Path

import jax
import jax.numpy as jnp

from bench.timing import load
from motiongan_jax.config import load_config, override
from motiongan_jax.data import gait_stats, synthetic
from motiongan_jax.model import state as model_state
from motiongan_jax.motion.representation import CMU_UNIT_M, foot_joints, layout_from_skeleton
from motiongan_jax.train import objectives
from motiongan_jax.train import step as step_lib

CONFIGS = Path(__file__).resolve().parents[1] / "configs"
REFERENCE_STEP_S = 8.57



def paper_or_small(which: str):
    """(cfg, layout, num_styles) of configs/<which>.py on the CMU skeleton, no data needed."""
    cfg = load_config(CONFIGS / f"{which}.py", check=False)
    cfg = override(cfg, ["data.data_dir=None", "data.label_rule=synthetic"])
    layout = layout_from_skeleton(synthetic.cmu_skeleton(), CMU_UNIT_M)
    num_styles = 28 if which == "paper" else len(synthetic.STYLES)
    return cfg, layout, num_styles


def stand_in_gait(cfg, layout, num_styles):
    """Gait targets of the right kind for configs with gait terms (their values do not change
    the step's cost), else None."""
    if not step_lib.needs_gait_targets(cfg.train):
        return None
    return gait_stats.GaitTargets(stride_m_C=(1.2,) * num_styles, speed_mps_C=(1.2,) * num_styles,
                                  step_height_m_C=(0.06,) * num_styles, stride_speed_slope=0.6,
                                  sample_hz=15.0, contact_height_m=0.02, toe_joints=foot_joints(layout))


def bench_step_fn(cfg, layout, num_styles):
    """The pure train step of `cfg` on fake data (fake_batch)."""
    return step_lib.make_train_step(cfg, layout, num_styles, stand_in_gait(cfg, layout, num_styles))


def fake_batch(B, T, R, num_styles, key, rec_rows: int = 0):
    """Random batch of the step's shapes, with a gait phase and `rec_rows` reconstructed rows
    (read by configs with train.w_g_rec)."""
    k1, k2, k3, k4 = jax.random.split(key, 4)
    t = jnp.arange(T, dtype=jnp.float32)[None, :, None]
    root = (jnp.concatenate([0.1 * t, jnp.ones((1, T, 1)), jnp.zeros((1, T, 1))], -1)
            + 0.01 * jax.random.normal(k1, (B, T, 3)))
    return {
        "root_BxTx3": root,
        "pose_BxTxR": 0.3 * jax.random.normal(k2, (B, T, R)),
        "curve_BxTx3": root.at[..., 1].set(0.0) + 0.01 * jax.random.normal(k3, (B, T, 3)),
        "label_B": jax.random.randint(k4, (B,), 0, num_styles),
        "phase_BxT": jnp.broadcast_to(0.5 * t[..., 0], (B, T)),
        "phase_valid_BxT": jnp.ones((B, T), bool),
        "rec_B": jnp.arange(B) < rec_rows,
    }


def peak_device_memory() -> str:
    """Peak bytes the device allocator has handed out (GPUs; XLA:CPU keeps no such statistic)."""
    stats = jax.devices()[0].memory_stats() or {}
    peak = stats.get("peak_bytes_in_use")
    return f"; peak device memory {peak / 2**30:.2f} GiB" if peak else ""


def compiled_step(cfg, layout, num_styles, impl="fast", dtype="float32"):
    """(compiled step, fresh state, fake batch, compile seconds, XLA's flop count) of `cfg`'s
    training step at its batch size and window, the state donated."""
    B, T = cfg.train.batch_size, cfg.data.window_T
    state = model_state.init_state(cfg, layout, num_styles, jax.random.key(0), impl=impl, dtype=dtype)
    step_fn = jax.jit(bench_step_fn(cfg, layout, num_styles), donate_argnums=0)
    batch = fake_batch(B, T, layout.num_rows, num_styles, jax.random.key(1), objectives.reconstructed_rows(cfg.train))
    t0 = time.perf_counter()
    compiled = step_fn.lower(state, batch, jax.random.key(2)).compile()
    compile_s = time.perf_counter() - t0
    cost = compiled.cost_analysis()
    cost = cost[0] if isinstance(cost, (list, tuple)) else cost
    flops = float(cost.get("flops", float("nan"))) if cost else float("nan")
    return compiled, state, batch, compile_s, flops


def bench(name, cfg, layout, num_styles, repeats, impl, dtype="float32"):
    B, T = cfg.train.batch_size, cfg.data.window_T
    compiled, state, batch, compile_s, flops = compiled_step(cfg, layout, num_styles, impl, dtype)
    state, m = compiled(state, batch, jax.random.key(3))  # warm-up
    jax.block_until_ready(m)
    times, cpu = [], []
    for i in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        state, m = compiled(state, batch, jax.random.key(10 + i))
        jax.block_until_ready(m)
        times.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    med = statistics.median(times)
    print(f"{name} [{impl}, {dtype}]: B {B}, T {T}, rows {layout.num_rows}, {num_styles} styles, "
          f"base channels {cfg.model.base_channels}: "
          f"compile {compile_s:.1f} s; step median {med:.3f} s (min {min(times):.3f}, max {max(times):.3f}, "
          f"{repeats} runs; process CPU {statistics.median(cpu):.2f} s); XLA counts {flops / 1e9:.1f} GFLOP "
          f"-> {flops / med / 1e9:.1f} GFLOP/s; {1 / med:.2f} it/s{peak_device_memory()}; {load()}", flush=True)
    return med


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--which", default="paper,small")
    ap.add_argument("--impl", default="fast", help="comma list of fast, xla")
    ap.add_argument("--dtype", default="float32", help="comma list of float32, bfloat16 (compute dtype)")
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    print(f"jax {jax.__version__} on {jax.devices()[0].platform} ({jax.devices()[0].device_kind}), "
          f"{os.cpu_count()} cpus; {load()}")
    for which in args.which.split(","):
        cfg, layout, num_styles = paper_or_small(which)
        for impl, dtype in [(i, d) for i in args.impl.split(",") for d in args.dtype.split(",")]:
            med = bench(which, cfg, layout, num_styles, args.repeats, impl, dtype)
            if which == "paper":
                print(f"  reference PyTorch (2 threads): {REFERENCE_STEP_S} s -> "
                      f"{med / REFERENCE_STEP_S:.2f}x of the reference's time")


if __name__ == "__main__":
    main()
