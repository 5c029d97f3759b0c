#!/usr/bin/env python
"""Where a training step's time goes (run by hand, never in CI). Prints medians.

Two views of one jitted train_step at the paper's shapes (or the small config's):

* pieces: the step's parts jitted on their own (G forward; G forward + backward to G's
  parameters; the D update; D's forward + backward for G's loss) and the whole step;
* ops: one step traced with jax.profiler; the time of every executed XLA op is attributed to
  the G/D layer whose `jax.named_scope` produced it (nn/generator.py, nn/discriminator.py),
  split into forward and backward ("transpose(" in the op's name) and by op kind.

`--impl xla` profiles the straightforward convolutions, `--impl fast` (default) the rewrites.
Caveats of the op view: XLA's weight-gradient convolutions carry no op name (they land in
"other"), and convolutions XLA runs with Eigen are dispatched asynchronously, so their time is
under-counted; the pieces are exact.
The machine is shared: the load average is printed with every figure; compare runs taken close
together, and prefer the op shares to the absolute seconds.

  JAX_PLATFORMS=cpu python -m bench.bench_profile [--which paper] [--impl fast] [--repeats 3] [--no-ops]
"""

import argparse
import collections
import glob
import os
import re
import statistics
import tempfile
import time

import jax
import jax.numpy as jnp
import optax
from flax import nnx

from bench.bench_train_step import (
    bench_step_fn,
    fake_batch,
    paper_or_small,
    stand_in_gait,
)
from bench.timing import load, median_time
from motiongan_jax.model import state as model_state
from motiongan_jax.motion import trajectory
from motiongan_jax.motion.representation import LENGTH_UNIT_M
from motiongan_jax.nn import SpectralNormState
from motiongan_jax.nn.generator import Generator
from motiongan_jax.train import objectives

SCOPES = Generator.BLOCKS + ("heads", "D")


def pieces(cfg, layout, num_styles, state, batch, repeats):
    """Seconds of each part of the step, jitted on its own."""
    tcfg = cfg.train
    labels, z, phase = objectives.generator_inputs(cfg, num_styles, batch, jax.random.key(5))
    gait = stand_in_gait(cfg, layout, num_styles)
    curve_vel = trajectory.velocity(batch["curve_BxTx3"])
    real_vel = trajectory.velocity(batch["root_BxTx3"])
    bone_pairs = tuple((int(a), int(b)) for a, b in layout.bone_pairs)
    bone_lengths = jnp.asarray(layout.bone_lengths_m, jnp.float32)

    def g_forward(g_params):
        g = nnx.merge(state.g_def, g_params, copy=True)
        w = g.style(labels, z)
        return g(curve_vel, w, phase)

    def g_fwd_bwd(g_params, cot):
        out, vjp = jax.vjp(g_forward, g_params)
        return out, vjp(cot)

    fake = jax.jit(g_forward)(state.g_params)
    cot = jax.tree.map(jnp.ones_like, fake)

    def d_update(d_params, sn, opt_d, fake):
        def obj(p):
            d = nnx.merge(state.d_def, p, sn, copy=True)
            terms = objectives.d_losses(d, *fake, real_vel, batch["pose_BxTxR"], batch["label_B"], tcfg)
            return terms["d_total"], nnx.state(d, SpectralNormState)

        (_, sn), grads = jax.value_and_grad(obj, has_aux=True)(d_params)
        tx_d = model_state.optimizers(cfg)[1]
        upd, opt_d = tx_d.update(grads, opt_d, d_params)
        return optax.apply_updates(d_params, upd), sn, opt_d

    def g_loss_grad(d_params, sn, fake):
        def obj(f):
            d = nnx.merge(state.d_def, d_params, sn, copy=True)
            terms = objectives.g_losses(d, *f, labels, batch, tcfg, LENGTH_UNIT_M, bone_pairs=bone_pairs,
                                        bone_lengths_m=bone_lengths, gait=gait, log_stride_B=jnp.zeros(labels.shape))
            return terms["g_total"]

        return jax.value_and_grad(obj)(fake)

    out = {}
    out["G forward"] = median_time(jax.jit(g_forward), state.g_params, repeats=repeats)
    out["G forward + backward"] = median_time(jax.jit(g_fwd_bwd), state.g_params, cot, repeats=repeats)
    out["D update (2 D calls, fwd+bwd, Adam)"] = median_time(
        jax.jit(d_update), state.d_params, state.d_sn_state, state.opt_d_state, fake, repeats=repeats)
    out["G loss through D (1 D call, fwd+bwd)"] = median_time(
        jax.jit(g_loss_grad), state.d_params, state.d_sn_state, fake, repeats=repeats)
    return out


def _op_names(hlo_text: str) -> dict[str, str]:
    """instruction name -> metadata op_name, over every computation of a compiled module."""
    names = {}
    for m in re.finditer(r"^\s*(?:ROOT )?%?([\w.\-]+) = [^\n]*?op_name=\"([^\"]*)\"", hlo_text, re.M):
        names[m.group(1)] = m.group(2)
    return names


def _kind(hlo_op: str) -> str:
    base = re.sub(r"[.\d]+$", "", hlo_op)
    return base


def op_profile(compiled, state, batch, key):
    """Run one step under the profiler; seconds per (scope, direction) and per op kind."""
    names = _op_names(compiled.as_text())
    tmp = tempfile.mkdtemp(prefix="motiongan_profile_")
    with jax.profiler.trace(tmp):
        new_state, m = compiled(state, batch, key)
        jax.block_until_ready(m)
    files = glob.glob(os.path.join(tmp, "**", "*.xplane.pb"), recursive=True)
    pd = jax.profiler.ProfileData.from_file(files[0])
    by_scope = collections.defaultdict(float)
    by_kind = collections.defaultdict(float)
    by_op = collections.defaultdict(float)
    total = 0.0
    for plane in pd.planes:
        for line in plane.lines:
            for ev in line.events:
                stats = dict(ev.stats)
                op = stats.get("hlo_op")
                if not op or ev.name.startswith("end:") or _kind(op) in ("while", "call", "conditional"):
                    continue
                sec = ev.duration_ns * 1e-9
                op_name = names.get(op, "")
                scope = next((s for s in SCOPES if re.search(rf"(^|[/(]){s}([/)]|$)", op_name)), "other")
                direction = "bwd" if "transpose(" in op_name else "fwd"
                by_scope[(scope, direction)] += sec
                by_kind[_kind(op)] += sec
                by_op[(op, op_name)] += sec
                total += sec
    return new_state, by_scope, by_kind, by_op, total


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--which", default="paper", choices=("paper", "small"))
    ap.add_argument("--impl", default="fast", choices=("fast", "xla"))
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--no-pieces", action="store_true")
    ap.add_argument("--no-ops", action="store_true")
    ap.add_argument("--top", type=int, default=0, help="also list the N slowest ops")
    args = ap.parse_args()
    cfg, layout, num_styles = paper_or_small(args.which)
    B, T = cfg.train.batch_size, cfg.data.window_T
    print(f"jax {jax.__version__}, {os.cpu_count()} cpus; {args.which}: B {B}, T {T}, impl {args.impl}; {load()}")
    state = model_state.init_state(cfg, layout, num_styles, jax.random.key(0), impl=args.impl)
    batch = fake_batch(B, T, layout.num_rows, num_styles, jax.random.key(1), objectives.reconstructed_rows(cfg.train))

    if not args.no_pieces:
        for name, sec in pieces(cfg, layout, num_styles, state, batch, args.repeats).items():
            print(f"  {name:40s} {sec:8.3f} s   ({load()})", flush=True)

    step_fn = jax.jit(bench_step_fn(cfg, layout, num_styles), donate_argnums=0)
    compiled = step_fn.lower(state, batch, jax.random.key(2)).compile()
    state, m = compiled(state, batch, jax.random.key(3))
    jax.block_until_ready(m)
    times = []
    for i in range(args.repeats):
        t0 = time.perf_counter()
        state, m = compiled(state, batch, jax.random.key(10 + i))
        jax.block_until_ready(m)
        times.append(time.perf_counter() - t0)
    print(f"  {'whole train step':40s} {statistics.median(times):8.3f} s   ({load()})", flush=True)
    if args.no_ops:
        return

    state, by_scope, by_kind, by_op, total = op_profile(compiled, state, batch, jax.random.key(99))
    print(f"\nops of one traced step: {total:.2f} s of op time ({load()})")
    print(f"  {'scope':10s} {'fwd s':>8s} {'bwd s':>8s} {'share':>6s}")
    rows = sorted({s for s, _ in by_scope}, key=lambda s: -(by_scope[(s, 'fwd')] + by_scope[(s, 'bwd')]))
    for s in rows:
        f, b = by_scope[(s, "fwd")], by_scope[(s, "bwd")]
        print(f"  {s:10s} {f:8.3f} {b:8.3f} {100 * (f + b) / total:5.1f}%")
    print("  by op kind: " + ", ".join(f"{k} {v:.2f} s" for k, v in sorted(by_kind.items(), key=lambda kv: -kv[1])[:8]))
    if args.top:
        print(f"  the {args.top} slowest ops:")
        for (op, op_name), sec in sorted(by_op.items(), key=lambda kv: -kv[1])[:args.top]:
            print(f"    {sec:7.3f} s  {op:32s} {op_name[-110:]}")


if __name__ == "__main__":
    main()
