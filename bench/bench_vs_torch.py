#!/usr/bin/env python
"""Ours and PyTorch side by side, in one run, on this machine's CPU (run by hand, never in CI).

Each row runs the same network, with the same parameters (ours, copied into PyTorch's modules of
bench/torch_reference.py), on the same inputs, in both frameworks, and prints a markdown table:
PyTorch's median, ours, and ours / PyTorch. The repeats alternate (PyTorch, ours, PyTorch, ...)
so that a change of load on a shared machine hits both alike. One untimed call of each first;
ours' compile time is reported apart, as is PyTorch's first call.

Rows:
* paper_step: the training step at the paper's shapes (bench_train_step.py --which paper: B 24,
  T 128, CMU skeleton 27 joints -> 81 rows, 28 styles, 64 base channels): D update then G update,
  Adam on both (torch_reference.TrainStep's docstring says what differs).
* g_forward: the paper G's forward for one walk, B 1, T 128, z = 0, the Latent Transform included
  (bench_inference.py's walk), PyTorch under inference_mode.
* small_step: the small preset's training step (B 16, T 32, 9 styles, 16 base channels, the
  walker around G, the projection D and the preset's loss terms).

`--check` times nothing: it shows that the two sides are the same networks and step, for the
presets of the rows asked. Parameter counts per module at the real shapes, asserted equal; then,
from one initialised state at a small shape (T 32; B 2, the small preset B 4): G's output and
style code, D's logits and spectral-norm vectors after a call in train mode (max abs difference
< OUTPUT_ATOL), and two training steps with PyTorch given our random draws: the first step's loss
terms and D's gradient norm within METRIC_RTOL, G's gradient norm within G_GRAD_RTOL; the
second's D terms on the real batch within METRIC_RTOL (why not more: G_GRAD_RTOL's comment).
About a minute a preset on idle cores, most of it compiling our step (minutes under load).

PyTorch is the `bench` extra (pip install -e '.[bench]'). Its threads are set to the cores this
process may use.

  JAX_PLATFORMS=cpu python -m bench.bench_vs_torch [--rows paper_step,g_forward,small_step] [--repeats 5] [--check]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import jax
import jax.numpy as jnp
import numpy as np
import torch
from flax import nnx

from bench import torch_reference as ref
from bench.bench_inference import walk
from bench.bench_train_step import compiled_step, paper_or_small, stand_in_gait
from bench.timing import load, timed
from motiongan_jax.config import override
from motiongan_jax.model import apply as model_apply
from motiongan_jax.model import build as model_build
from motiongan_jax.model import state as model_state
from motiongan_jax.motion import trajectory
from motiongan_jax.nn import SpectralNormState, count_params
from motiongan_jax.train import objectives

ROWS = ("paper_step", "g_forward", "small_step")
PRESET = {"paper_step": "paper", "g_forward": "paper", "small_step": "small"}
# float32 tolerances of the check: outputs and logits (absolute), step metrics (relative) ...
OUTPUT_ATOL = 1e-4
METRIC_RTOL = 1e-3
# ... except G's gradient norm: at init G's gradient is ill-conditioned in float32 (its encoder's
# gradient passes back through up to 14 instance norms of small activations): PyTorch's own float32
# gradient differs from its float64 one by 1-2% (paper shapes), ours by about as much. Adam's first
# update, about lr·sign(gradient), turns those differences into whole steps, so after it G's
# outputs (and losses) differ by a few % between float32 and float64 in PyTorch alone: of the
# second step only the terms of the real batch are asserted (D after its Adam update and six
# power iterations), the others printed.
G_GRAD_RTOL = 5e-2


def cores() -> int:
    return len(os.sched_getaffinity(0))


def processor() -> str:
    """The CPU's model name and widest vector instructions, from /proc/cpuinfo."""
    info = {}
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                key, _, value = line.partition(":")
                info.setdefault(key.strip(), value.strip())
    except OSError:
        return "unknown processor"
    flags = set(info.get("flags", "").split())
    isa = [name for flag, name in (("avx512f", "AVX-512"), ("amx_tile", "AMX")) if flag in flags]
    if not isa:
        isa = ["AVX2, no AVX-512 or AMX" if "avx2" in flags else "no AVX2"]
    return f"{info.get('model name', 'unknown')} ({', '.join(isa)})"


def to_torch(batch: dict) -> dict:
    """Our batch (jax arrays) as torch tensors: integer labels as int64 (torch indexes with those)."""
    out = {}
    for k, v in batch.items():
        a = np.asarray(v)
        out[k] = torch.from_numpy(a.astype(np.int64) if a.dtype.kind in "iu" else a.copy())
    return out


def torch_draws(labels_B, z_BxZ, phase_B):
    """Our step's random draws (objectives.generator_inputs) as PyTorch's step takes them."""
    return (torch.from_numpy(np.array(labels_B, np.int64)), torch.from_numpy(np.array(z_BxZ)),
            None if phase_B is None else torch.from_numpy(np.array(phase_B)))


def torch_twins(cfg, layout, num_styles, state):
    """PyTorch's G and D of `cfg` with `state`'s parameters (read before the state is donated)."""
    g, d = ref.build(cfg, layout, num_styles)
    ref.load_ours(g, state.g_params)
    ref.load_ours(d, state.d_params, state.d_sn_state)
    return g, d


# ---------------------------------------------------------------------------------------------
# Rows: (description, PyTorch's call, ours, ours' compile seconds)


def step_row(which: str):
    cfg, layout, num_styles = paper_or_small(which)
    compiled, state, batch, compile_s, _ = compiled_step(cfg, layout, num_styles)
    g, d = torch_twins(cfg, layout, num_styles, state)
    torch_step = ref.TrainStep(cfg, layout, num_styles, g, d, stand_in_gait(cfg, layout, num_styles))
    torch_batch = to_torch(batch)
    carry = {"state": state, "step": 0}

    def ours():
        carry["state"], metrics = compiled(carry["state"], batch, jax.random.key(10 + carry["step"]))
        carry["step"] += 1
        return metrics

    m = cfg.model
    what = (f"{which} training step (B {cfg.train.batch_size}, T {cfg.data.window_T}, {layout.num_rows} rows, "
            f"{num_styles} styles, {m.base_channels} base channels)")
    return what, lambda: torch_step(torch_batch), ours, compile_s


def g_forward_row(T: int = 128):
    cfg, layout, num_styles = paper_or_small("paper")
    state = model_apply.generator_state(model_state.init_state(cfg, layout, num_styles, jax.random.key(0)))
    vel = trajectory.velocity(walk(T))
    labels = jnp.array([3], jnp.int32)
    t0 = time.perf_counter()
    compiled = jax.jit(lambda model, labels_B, vel_BxTx3: model_apply.g_apply(
        model, vel_BxTx3, model_apply.style_codes(model, labels_B))).lower(state, labels, vel).compile()
    compile_s = time.perf_counter() - t0
    g, _ = ref.build(cfg, layout, num_styles)
    ref.load_ours(g, state.g_params)
    g.eval()
    vel_t, labels_t, z_t = torch.from_numpy(np.array(vel)), torch.tensor([3]), torch.zeros(1, cfg.model.z_dim)

    def torch_forward():
        with torch.inference_mode():
            return g(vel_t, g.style(labels_t, z_t))

    what = f"paper G forward, one walk (B 1, T {T}, z 0, Latent Transform included)"
    return what, torch_forward, lambda: compiled(state, labels, vel), compile_s


def measure(rows, repeats: int) -> list[str]:
    lines = ["| row | PyTorch median | ours median | ours / PyTorch | ours compile | PyTorch first call |",
             "|---|---|---|---|---|---|"]
    for row in rows:
        what, torch_fn, ours_fn, compile_s = g_forward_row() if row == "g_forward" else step_row(PRESET[row])
        torch_first = timed(torch_fn)
        timed(ours_fn)
        torch_s, ours_s = [], []
        for _ in range(repeats):
            torch_s.append(timed(torch_fn))
            ours_s.append(timed(ours_fn))
        t, o = statistics.median(torch_s), statistics.median(ours_s)
        lines.append(f"| {row}: {what} | {fmt(t)} | {fmt(o)} | **{o / t:.2f}x** | {compile_s:.1f} s "
                     f"| {fmt(torch_first)} |")
        print(f"  {row}: PyTorch {fmt(t)} (min {fmt(min(torch_s))}), ours {fmt(o)} (min {fmt(min(ours_s))}), "
              f"{repeats} repeats; {load()}", flush=True)
    return lines


def fmt(seconds: float) -> str:
    return f"{seconds * 1e3:.1f} ms" if seconds < 1 else f"{seconds:.2f} s"


# ---------------------------------------------------------------------------------------------
# The check


def module_counts(which: str) -> list[tuple[str, int, int]]:
    """(module, ours, PyTorch's) parameter counts of G's and D's top-level parts at `which`'s shapes."""
    cfg, layout, num_styles = paper_or_small(which)
    ours = nnx.eval_shape(lambda: model_build.build_models(cfg, layout.num_rows // 3, num_styles,
                                                           jax.random.key(0), layout))
    torch_g, torch_d = ref.build(cfg, layout, num_styles)
    rows = []
    for net, tnet, tag in zip(ours, (torch_g, torch_d), "GD"):
        per = {}
        for path, var in nnx.to_flat_state(nnx.state(net, nnx.Param)):
            per[path[0]] = per.get(path[0], 0) + int(np.prod(var.shape))
        assert sum(per.values()) == count_params(net)
        for name, n in per.items():
            rows.append((f"{tag}.{name}", n, ref.count_params(tnet.get_submodule(name))))
        rows.append((f"{tag} total", count_params(net), ref.count_params(tnet)))
    return rows


def max_diff(a, b) -> float:
    return float(np.max(np.abs(np.asarray(a, np.float64) - b.detach().numpy().astype(np.float64))))


def check(which: str) -> None:
    t0 = time.perf_counter()
    counts = module_counts(which)
    bad = [c for c in counts if c[1] != c[2]]
    print(f"{which}: parameter counts per module, ours = PyTorch's: "
          + ", ".join(f"{name} {n:,}" for name, n, _ in counts if name.endswith("total") or name.startswith("D.")))
    assert not bad, f"parameter counts differ (module, ours, PyTorch): {bad}"

    cfg, layout, num_styles = paper_or_small(which)
    b = 2 if which == "paper" else 4
    cfg = override(cfg, [f"train.batch_size={b}", f"data.frame_nums={32 * cfg.data.frame_step}"])
    compiled, state, batch, compile_s, _ = compiled_step(cfg, layout, num_styles)
    print(f"  ours: state and step compiled at the small shape ({compile_s:.1f} s compiling the step)")
    g, d = torch_twins(cfg, layout, num_styles, state)
    tb = to_torch(batch)
    key = jax.random.key(10)
    labels, z, phase = objectives.generator_inputs(cfg, num_styles, batch, key)
    draws = torch_draws(labels, z, phase)
    diffs = {}

    # G: style code and outputs (a walker starts at the drawn gait phase)
    curve_vel = trajectory.velocity(batch["curve_BxTx3"])
    w = model_apply.style_codes(state, labels, z)
    root, pose = model_apply.g_apply(state, curve_vel, w, phase)
    with torch.no_grad():
        tw = g.style(draws[0], draws[1])
        cv = ref.velocity(tb["curve_BxTx3"])
        troot, tpose = g(cv, tw, draws[2]) if isinstance(g, ref.WalkerGenerator) else g(cv, tw)
    diffs["G style code w"] = max_diff(w, tw)
    diffs["G root velocity"] = max_diff(root, troot)
    diffs["G pose rows"] = max_diff(pose, tpose)

    # D in train mode: logits, and the spectral-norm vectors its power iteration leaves
    dm = model_apply.discriminator(state)
    real_vel = trajectory.velocity(batch["root_BxTx3"])
    adv, cls = dm(real_vel, batch["pose_BxTxR"], update_stats=True, labels_B=batch["label_B"])
    with torch.no_grad():
        tadv, tcls = d(ref.velocity(tb["root_BxTx3"]), tb["pose_BxTxR"], tb["label_B"])
    diffs["D real/fake logit"] = max_diff(adv, tadv)
    diffs["D style logits"] = max_diff(cls, tcls)
    buffers = dict(d.named_buffers())
    diffs["D spectral-norm u, v"] = max(
        max_diff(var[...], buffers[f"{path[0]}.weight_{path[-1]}"])
        for path, var in nnx.to_flat_state(nnx.state(dm, SpectralNormState)))
    print(f"{which} at B {b}, T {cfg.data.window_T}: max |ours - PyTorch|: "
          + ", ".join(f"{k} {v:.1e}" for k, v in diffs.items()))
    assert max(diffs.values()) < OUTPUT_ATOL, diffs

    # two training steps from the same parameters, PyTorch given our draws
    g, d = torch_twins(cfg, layout, num_styles, state)
    torch_step = ref.TrainStep(cfg, layout, num_styles, g, d, stand_in_gait(cfg, layout, num_styles))
    for i in range(2):
        key = jax.random.key(10 + i)
        labels, z, phase = objectives.generator_inputs(cfg, num_styles, batch, key)
        draws = torch_draws(labels, z, phase)
        state, ours = compiled(state, batch, key)
        theirs = torch_step(tb, draws, measure=True)
        rel = {k: abs(float(ours[k]) - v) / max(abs(v), 1e-6) for k, v in theirs.items()}
        print(f"  step {i + 1}, ours vs PyTorch: "
              + ", ".join(f"{k} {float(ours[k]):.5g} vs {v:.5g}" for k, v in theirs.items()))
        asserted = list(rel) if i == 0 else ["d_adv_real", "d_cls"]
        tol = {k: G_GRAD_RTOL if k == "g_grad_norm" else METRIC_RTOL for k in asserted}
        print(f"  step {i + 1}: largest relative difference "
              + (f"{max(rel[k] for k in asserted if k != 'g_grad_norm'):.1e} (losses, D's gradient norm), "
                 f"{rel['g_grad_norm']:.1e} (G's gradient norm)" if i == 0 else
                 f"{max(rel[k] for k in asserted):.1e} (D's terms of the real batch)"))
        bad = {k: rel[k] for k in asserted if rel[k] >= tol[k]}
        assert not bad, bad
    print(f"{which}: checked in {time.perf_counter() - t0:.0f} s; {load()}")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--rows", default=",".join(ROWS), help=f"comma list of {', '.join(ROWS)}")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--check", action="store_true", help="compare the two sides' networks instead of timing them")
    args = ap.parse_args()
    rows = args.rows.split(",")
    unknown = sorted(set(rows) - set(ROWS))
    if unknown:
        ap.error(f"unknown rows {unknown}; choose from {', '.join(ROWS)}")
    torch.set_num_threads(cores())
    print(f"processor: {processor()}; {cores()} cores; PyTorch {torch.__version__} "
          f"({torch.get_num_threads()} threads, {torch.backends.cpu.get_cpu_capability()} kernels); "
          f"jax {jax.__version__} on {jax.devices()[0].platform}; {load()}", flush=True)
    if args.check:
        for which in dict.fromkeys(PRESET[r] for r in rows):
            check(which)
        print("check passed: the same networks and step")
        return
    print("\n".join(measure(rows, args.repeats)))
    print(f"({load()})")


if __name__ == "__main__":
    main()
