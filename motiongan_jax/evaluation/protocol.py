"""The evaluation protocol's driver (docs/DESIGN.md §7): generation on the protocol's curves, every
metric for generated and real held-out data side by side, a trained run evaluated end to end.

Conventions. Generated clips are placed by `walk.generate_motion` (root integrated from the
curve start, feet put on the floor by a percentile shift); real held-out windows get the same
floor shift, so ground-penetration figures compare like with like. Feet are the two toe joints
(`foot_joints`). Generated motion is cut into evaluator windows of the training length T.
Every (curve × style) pair gets K noise draws per seed; statistics are averaged per seed, and the
report gives mean ± 95% CI over seeds (`metrics.mean_ci95`). Real data have no seeds: one value.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Callable, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from motiongan_jax.analysis import search as search_lib
from motiongan_jax.analysis import style_space
from motiongan_jax.config import ConfigError, config_hash
from motiongan_jax.data import clip_cache, file_labels, gait_stats, sampling
from motiongan_jax.evaluation import clip_metrics, d_probe, evaluator, metrics, own_paths, streaming, style_recovery
from motiongan_jax.evaluation.eval_curves import (
    EvalCurve,
    file_curves,
    from_origin,
    heldout_curves,
    long_line,
    median_speed,
    shape_curves,
)
from motiongan_jax.generate import styles, walk
from motiongan_jax.model import apply as model_apply
from motiongan_jax.model import checkpoint, pretrained
from motiongan_jax.motion.representation import foot_joints, from_rows


class EvaluationError(ValueError):
    pass


@dataclasses.dataclass(frozen=True)
class Settings:
    seeds: tuple[int, ...] = (0, 1, 2)
    k: int = 3  # noise draws per (curve, style)
    windows_per_curve: int = 4  # curve length L = this × T
    max_heldout_curves: int = 12
    max_cmu_curves: int = 6
    long_curve_m: float = 60.0  # the drift test's straight line
    interp_steps: int = 5
    search_clips: int = 1  # per style
    search_steps: int = search_lib.STEPS
    w_samples: int = 10
    realism_windows: int = 8  # like-for-like walks (own_paths.py): each held-out path up to this many windows
    realism_max_curves: int = 48
    stream_curves: int = 6  # like-for-like paths also walked as a live stream (streaming.py); 0: none


@dataclasses.dataclass
class Context:
    state: object
    meta: dict
    cfg: object
    layout: object
    ev: evaluator.Evaluator
    style_names: tuple[str, ...]
    val_clips: list
    sample_rate: float
    feet: tuple[int, int]
    curves_: list[EvalCurve]
    settings: Settings
    contact_height_m: float  # calibrated on the real training clips (gait_stats.contact_height)
    long_curve: EvalCurve | None = None  # tens of metres: does the walk drift?
    probe_batch: dict | None = None  # real training windows from the run's sampler, for discriminator_probe
    ev_speed_free: evaluator.Evaluator | None = None  # the speed-free evaluator, if one is given
    realism_curves: list[EvalCurve] = dataclasses.field(default_factory=list)  # own_paths.curves_of


def _real_block(ctx: Context) -> dict:
    """Every per-clip metric and evaluator score on real held-out data."""
    T, step = ctx.cfg.data.window_T, ctx.cfg.data.frame_step
    root, pose, labels, _ = evaluator.real_windows(ctx.val_clips, ctx.style_names, T, step)
    if len(root) < 2:
        raise EvaluationError("fewer than two real held-out windows: cannot evaluate")
    logits, feats = evaluator.classify(ctx.ev, root, pose)
    joints = np.asarray(from_rows(root, pose, ctx.layout), np.float64)
    shift = walk.floor_shift(joints)
    joints[..., 1] += shift[:, None, None]
    contact = ctx.contact_height_m
    per = []
    for i in range(len(joints)):
        per.append(clip_metrics.motion_metrics(joints[i], None, ctx.layout, ctx.feet, ctx.sample_rate, contact))
    # trajectory of real motion against its own (noise-free) curve, on the held-out curves
    traj = []
    for c in ctx.curves_:
        if not c.kind.startswith("heldout"):
            continue
        clip = next(cl for cl in ctx.val_clips if cl.source == c.source)
        n = len(c.curve_Lx3)
        r = from_origin(np.asarray(clip.root_Fx3, np.float64)[: (n - 1) * step + 1: step])
        traj.append({"traj_error_original_m": metrics.trajectory_error_original(r, c.curve_Lx3),
                     "traj_error_symmetric_m": metrics.trajectory_error_symmetric(r, c.curve_Lx3),
                     "endpoint_error_m": metrics.endpoint_error(r, c.curve_Lx3),
                     "path_length_ratio": metrics.path_length_ratio(r, c.curve_Lx3)})
    # gait on whole held-out clips at the generated sample rate (a window is too short for a
    # step frequency); `clips` keyed by source for the same-curve cadence comparison
    clips = {}
    for clip in ctx.val_clips:
        j = np.asarray(from_rows(clip.root_Fx3[::step], clip.pose_FxR[::step], ctx.layout), np.float64)
        if len(j) >= 4:
            clips[clip.source] = {"style": clip.label.style,
                                  **clip_metrics.gait_metrics(j, ctx.feet, ctx.sample_rate, contact)}
    return {"logits": logits, "feats": feats, "labels": labels, "per_window": per, "traj": traj,
            "contact_height_m": contact, "joints": joints, "clips": clips}


def _generate_block(ctx: Context, seed: int, contact: float) -> dict:
    """Generation for every (curve × style × K) with one seed; per-clip metrics and scores."""
    s = ctx.settings
    C = len(ctx.style_names)
    T = ctx.cfg.data.window_T
    Z = model_apply.z_dim(ctx.state)
    labels = np.repeat(np.arange(C, dtype=np.int32), s.k)
    key = jax.random.key(seed)
    rows, win_logits, win_feats, win_labels, mm_groups = [], [], [], [], []
    for ci, c in enumerate(ctx.curves_):
        z = jax.random.normal(jax.random.fold_in(key, ci), (C * s.k, Z), jnp.float32)
        w = styles.latent_codes(ctx.state, labels, z)
        # each draw starts its walk at its own gait phase, as in training
        phase = (np.asarray(jax.random.uniform(jax.random.fold_in(key, 100_000 + ci), (C * s.k,), maxval=2 * np.pi))
                 if model_apply.has_gait_phase(ctx.state) else None)
        gen = walk.generate_motion(ctx.state, ctx.layout, c.curve_Lx3, np.asarray(w), phase)
        root = gen.positions[:, :, 0]
        r, p, n = clip_metrics.cut_windows(root, gen.pose, T)
        logits, feats = evaluator.classify(ctx.ev, r, p)
        win_logits.append(logits)
        win_feats.append(feats)
        win_labels.append(np.repeat(labels, n))
        # multimodality: the K draws of one (curve, style), each clip's mean window feature
        clip_feats = feats.reshape(C * s.k, n, -1).mean(1).reshape(C, s.k, -1)
        mm_groups.append(clip_feats)
        for b in range(C * s.k):
            m = clip_metrics.motion_metrics(gen.positions[b], c.curve_Lx3, ctx.layout, ctx.feet, ctx.sample_rate,
                                            contact)
            rows.append({"curve": c.name, "kind": c.kind, "source": c.source, "style": int(labels[b]), **m})
    return {"rows": rows, "logits": np.concatenate(win_logits), "feats": np.concatenate(win_feats),
            "labels": np.concatenate(win_labels), "mm": np.concatenate(mm_groups)}


def _long_curve_block(ctx: Context, seed: int) -> dict:
    """Every style (one noise draw) along the long curve: gait metrics, averaged over styles."""
    C = len(ctx.style_names)
    z = jax.random.normal(jax.random.key(20_000 + seed), (C, model_apply.z_dim(ctx.state)), jnp.float32)
    w = styles.latent_codes(ctx.state, np.arange(C, dtype=np.int32), z)
    gen = walk.generate_motion(ctx.state, ctx.layout, ctx.long_curve.curve_Lx3, np.asarray(w))
    rows = [clip_metrics.gait_metrics(gen.positions[b], ctx.feet, ctx.sample_rate, ctx.contact_height_m)
            for b in range(C)]
    return {f"long_{k}": _mean_key(rows, k) for k in clip_metrics.GAIT_KEYS}


def _style_space_block(ctx: Context, seed: int) -> dict:
    """w-space metrics with one seed: nearest-centroid accuracy, PCA, interpolation, arithmetic."""
    s = ctx.settings
    C = len(ctx.style_names)
    T = ctx.cfg.data.window_T
    key = jax.random.key(10_000 + seed)
    k_a, k_b = jax.random.split(key)
    fit = style_space.label_codes(ctx.state, ctx.style_names, k=s.w_samples, key=k_a)
    test = style_space.label_codes(ctx.state, ctx.style_names, k=s.w_samples, key=k_b)
    X, y = test.flat_samples
    cents = np.asarray(fit.centroids_CxD)
    nc_acc = metrics.nearest_centroid_accuracy(np.asarray(X), np.asarray(y), cents)
    ev_ratio = np.asarray(style_space.pca(fit.flat_samples[0]).explained_variance_ratio_K)
    # a straight line of L samples at the held-out median spacing, for interpolation/arithmetic
    line = next((c for c in ctx.curves_ if c.name == "line"), ctx.curves_[0]).curve_Lx3
    # the first component alone shows a style code collapsed onto one line (docs/RESULTS.md §8)
    out = {"nearest_centroid_accuracy": nc_acc, "pca_explained_1": float(ev_ratio[0]),
           "pca_explained_2": float(np.sum(ev_ratio[:2])),
           "pca_explained": ev_ratio[:5].tolist()}
    if C >= 2:
        alphas = np.linspace(0.0, 1.0, s.interp_steps)
        rhos = []
        rng = np.random.default_rng(seed)
        pairs = [(a, (a + 1 + int(rng.integers(C - 1))) % C) for a in range(C)]
        for a, b in pairs:
            w = np.stack([(1 - t) * cents[a] + t * cents[b] for t in alphas])
            gen = walk.generate_motion(ctx.state, ctx.layout, line, w)
            r, p, n = clip_metrics.cut_windows(gen.positions[:, :, 0], gen.pose, T)
            logits, _ = evaluator.classify(ctx.ev, r, p)
            pb = np.asarray(jax.nn.softmax(logits, -1))[:, b].reshape(len(alphas), n).mean(1)
            rhos.append(metrics.interpolation_monotonicity(alphas, pb))
        out["interp_monotonicity"] = float(np.nanmean(rhos)) if np.isfinite(rhos).any() else float("nan")
    if C >= 3:
        triples = [(a, (a + 1) % C, (a + 2) % C) for a in range(C)]
        w = np.stack([cents[a] - cents[b] + cents[c] for a, b, c in triples])
        gen = walk.generate_motion(ctx.state, ctx.layout, line, w)
        r, p, n = clip_metrics.cut_windows(gen.positions[:, :, 0], gen.pose, T)
        logits, _ = evaluator.classify(ctx.ev, r, p)
        pred = np.argmax(logits, -1).reshape(len(triples), n)
        ok = [np.mean((pred[i] == a) | (pred[i] == c)) for i, (a, b, c) in enumerate(triples)]
        out["arithmetic_agreement"] = float(np.mean(ok))
        out["arithmetic_chance"] = 2.0 / C
    return out


def _search_block(ctx: Context) -> dict:
    """Style search on held-out real clips (`search_clips` per style) and on G's walks of their
    paths (style_recovery.py): is the recovered style nearest the true one?"""
    s = ctx.settings
    if s.search_clips < 1 or s.search_steps < 1:
        return {}
    res = style_recovery.recovery(ctx.state, ctx.meta, ctx.cfg, ctx.layout, ctx.val_clips, ctx.style_names,
                                  style_recovery.Settings(steps=s.search_steps, clips_per_style=s.search_clips),
                                  log=lambda m: None)
    if not res["real"]["clips"]:
        return {}
    return {"search_recovery": res["real"]["top1"], "search_recovery_top3": res["real"]["top3"],
            "search_recovery_own_walks": res["own"]["top1"], "search_clips": res["real"]["clips"],
            "search_final_loss": float(np.mean([r["loss"] for r in res["clips"]["real"]])),
            "search_seconds_median": res["seconds"]["median"]}


GEN_KEYS = ("traj_error_original_m", "traj_error_symmetric_m", "endpoint_error_m", "path_length_ratio",
            "foot_skate_original_m", "skate_ratio", "bone_length_error", "ground_penetration", "jerk_mps3",
            "facing_error_deg") + clip_metrics.GAIT_KEYS


def _mean_key(rows, key):
    v = [r[key] for r in rows if key in r and np.isfinite(r[key])]
    return float(np.mean(v)) if v else float("nan")


def evaluate(ctx: Context, log: Callable[[str], None] = print) -> dict:
    s = ctx.settings
    C = len(ctx.style_names)
    log(f"real held-out data: {len(ctx.val_clips)} clips")
    real = _real_block(ctx)
    real_sra = metrics.style_recognition(real["logits"], real["labels"])
    real_jerk = _mean_key(real["per_window"], "jerk_mps3")
    # FMD reference level: two halves of the real held-out windows (alternate windows)
    half_a, half_b = real["feats"][0::2], real["feats"][1::2]
    real_row = {
        "sra_top1": real_sra["top1"], "sra_top3": real_sra["top3"],
        "fmd": metrics.frechet_distance(half_a, half_b) if min(len(half_a), len(half_b)) > 1 else float("nan"),
        "diversity": metrics.diversity(real["feats"], 1000, seed=0),
        **{k: _mean_key(real["traj"] if k.startswith(("traj", "endpoint", "path")) else real["per_window"], k)
           for k in GEN_KEYS if k not in clip_metrics.GAIT_KEYS},
        **{k: _mean_key(list(real["clips"].values()), k) for k in clip_metrics.GAIT_KEYS},
    }
    real_row["jerk_ratio"] = 1.0
    # the highest root-height range of a real clip: what a long generated walk must stay within
    real_row["long_root_height_range_m"] = max(r["root_height_range_m"] for r in real["clips"].values())
    curve_sources = {c.source for c in ctx.curves_}
    real_per_style = {}
    for c in range(C):
        name = ctx.style_names[c]
        sel = real["labels"] == c
        rows = [r for r, m in zip(real["per_window"], sel) if m]
        clip_rows = [r for r in real["clips"].values() if r["style"] == name]
        real_per_style[name] = {
            "windows": int(sel.sum()),
            "sra_top1": float(np.mean(np.argmax(real["logits"][sel], -1) == c)) if sel.any() else float("nan"),
            **{k: _mean_key(rows, k) for k in ("foot_skate_original_m", "skate_ratio", "bone_length_error")},
            **{k: _mean_key(clip_rows, k) for k in clip_metrics.GAIT_KEYS},
            # the clips of this style whose paths are evaluation curves: the same-curve cadence
            "step_frequency_same_curve_hz": _mean_key(
                [r for src, r in real["clips"].items() if r["style"] == name and src in curve_sources],
                "step_frequency_hz")}

    realism_real = None
    if ctx.realism_curves:
        log(f"realism: {len(ctx.realism_curves)} held-out paths, real windows")
        realism_real = own_paths.real_block(ctx)
        ref = (realism_real["reference"] or {}).get("tests", {})
        real_row.update({f"two_sample_{g}": ref[g]["accuracy"] for g in ref})
        real_row["sra_top1_own_speed"] = realism_real["sra"]
        real_row["sra_top1_speed_free_own_speed"] = realism_real["sra_speed_free"]
        real_row["stride_speed_slope"] = realism_real["real_slope_within_styles"]
        real_style = own_paths.style_rows(realism_real["per_clip"], C)
        for c in range(C):
            name = ctx.style_names[c]
            real_per_style[name].update(real_style[c])
            real_per_style[name]["sra_top1_speed_free_own_speed"] = float(realism_real["sra_speed_free_per_style"][c])
            real_per_style[name]["stride_speed_slope"] = realism_real["real_slope_per_style"][c]["slope"]
    realism_seeds = []

    per_seed, per_seed_style, confusions, stream_seeds = [], [], [], []
    for seed in s.seeds:
        log(f"seed {seed}: generating {len(ctx.curves_)} curves x {C} styles x {s.k} draws")
        g = _generate_block(ctx, seed, ctx.contact_height_m)
        sra = metrics.style_recognition(g["logits"], g["labels"])
        confusions.append(sra["confusion_CxC"])
        row = {"sra_top1": sra["top1"], "sra_top3": sra["top3"],
               "fmd": metrics.frechet_distance(real["feats"], g["feats"]),
               "diversity": metrics.diversity(g["feats"], 1000, seed=seed),
               "multimodality": metrics.multimodality(g["mm"].reshape(-1, s.k, g["mm"].shape[-1])),
               **{k: _mean_key(g["rows"], k) for k in GEN_KEYS}}
        row["jerk_ratio"] = row["jerk_mps3"] / real_jerk
        for kind in sorted({c.kind for c in ctx.curves_}):
            rows = [r for r in g["rows"] if r["kind"] == kind]
            row[f"traj_error_original_m[{kind}]"] = _mean_key(rows, "traj_error_original_m")
            row[f"traj_error_symmetric_m[{kind}]"] = _mean_key(rows, "traj_error_symmetric_m")
        if ctx.long_curve is not None:
            log(f"seed {seed}: the {ctx.long_curve.name} curve")
            row.update(_long_curve_block(ctx, seed))
        log(f"seed {seed}: style space")
        row.update(_style_space_block(ctx, seed))
        if realism_real is not None:
            log(f"seed {seed}: realism (own paths, own styles, own speeds; default speed; stride-speed sweep)")
            rg = own_paths.generated_block(ctx, seed, realism_real)
            rd = own_paths.default_speed_block(ctx, seed)
            rs = own_paths.stride_speed_block(ctx, seed)
            row.update({f"two_sample_{g}": v["accuracy"] for g, v in rg["tests"]["tests"].items()})
            nan = float("nan")
            row.update({"sra_top1_own_speed": rg["sra_own_speed"],
                        "sra_top1_speed_free_own_speed": rg["sra_speed_free_own_speed"],
                        "sra_top1_default_speed": rd.get("sra_default_speed", nan),
                        "sra_top1_speed_free_default_speed": rd.get("sra_speed_free_default_speed", nan),
                        "stride_speed_slope": float(np.nanmean(rs["slope_C"])) if np.isfinite(rs["slope_C"]).any()
                        else float("nan")})
            realism_seeds.append({"seed": seed, "tests": rg["tests"], "style": own_paths.style_rows(rg["per_clip"], C),
                                  "own": rg, "default": rd, "sweep": rs})
        if s.stream_curves and ctx.realism_curves:
            log(f"seed {seed}: streaming ({min(s.stream_curves, len(ctx.realism_curves))} held-out paths)")
            sb = streaming.stream_block(ctx, seed)
            row.update({k: v for k, v in sb.items() if k.startswith(("stream_", "whole_seam_"))})
            stream_seeds.append({"seed": seed, **sb})
        per_seed.append(row)
        st = {}
        for c in range(C):
            name = ctx.style_names[c]
            sel = g["labels"] == c
            rows = [r for r in g["rows"] if r["style"] == c]
            rs = real["labels"] == c
            # cadence on the paths of real clips of the same style, against those clips
            same = [r for r in rows if real["clips"].get(r["source"], {}).get("style") == name]
            st[name] = {
                "sra_top1": float(np.mean(np.argmax(g["logits"][sel], -1) == c)),
                "fmd": (metrics.frechet_distance(real["feats"][rs], g["feats"][sel])
                        if rs.sum() > 1 and sel.sum() > 1 else float("nan")),
                **{k: _mean_key(rows, k) for k in ("traj_error_original_m", "foot_skate_original_m",
                                                  "skate_ratio", "bone_length_error") + clip_metrics.GAIT_KEYS},
                "step_frequency_same_curve_hz": _mean_key(same, "step_frequency_hz")}
            st[name]["step_frequency_ratio"] = (st[name]["step_frequency_same_curve_hz"]
                                                / real_per_style[name]["step_frequency_same_curve_hz"])
            if realism_seeds:
                st[name].update(_realism_style(realism_seeds[-1], c))
        per_seed_style.append(st)
    log("style search on held-out clips")
    search = _search_block(ctx)
    probe = ({} if ctx.probe_batch is None
             else d_probe.discriminator_probe(ctx.state, ctx.probe_batch, jax.random.key(30_000)))

    keys = list(per_seed[0])
    generated = {k: _ci([r.get(k, float("nan")) for r in per_seed]) for k in keys}
    per_style = {}
    for name in ctx.style_names:
        per_style[name] = {"generated": {k: _ci([st[name][k] for st in per_seed_style])
                                         for k in per_seed_style[0][name]},
                           "real": real_per_style[name]}
    return {
        "generated": generated,
        "real": real_row,
        "per_style": per_style,
        "realism": _realism_summary(ctx, realism_real, realism_seeds),
        "streaming": stream_seeds,
        "search": search,
        "discriminator_probe": probe,
        "confusion_generated": np.sum(confusions, axis=0).tolist(),
        "confusion_real": real_sra["confusion_CxC"].tolist(),
        "contact_height_m": ctx.contact_height_m,
        "evaluator_real_heldout": ctx.ev.meta.get("real_heldout"),
        "num_generated_clips_per_seed": len(ctx.curves_) * C * s.k,
        "num_real_windows": int(len(real["labels"])),
    }


def _realism_style(r: dict, c: int) -> dict:
    """One seed's like-for-like measures of style c (own_paths), flat for the per-style rows."""
    out = dict(r["style"][c])
    own, dflt, sweep = r["own"], r["default"], r["sweep"]
    out["sra_top1_own_speed"] = float(own["sra_own_speed_per_style"][c])
    out["sra_top1_speed_free_own_speed"] = float(own["sra_speed_free_own_speed_per_style"][c])
    out["sra_top1_default_speed"] = float(dflt["sra_default_speed_per_style"][c]) if dflt else float("nan")
    out["sra_top1_speed_free_default_speed"] = (float(dflt["sra_speed_free_default_speed_per_style"][c])
                                                if dflt else float("nan"))
    out["stride_speed_slope"] = float(sweep["slope_C"][c])
    for si, v in enumerate(own_paths.STRIDE_SPEEDS):
        out[f"step_frequency_hz@{v:g}"] = float(sweep["frequency_hz_CxS"][c, si])
    return out


def _realism_summary(ctx, real: dict | None, seeds: list[dict]) -> dict:
    """What the report shows of the realism part beyond the mean ± CI rows: the first seed's
    tests in detail (paths, folds, the features that separate most), the real reference's, the
    stride measurements per held-out clip, and the sweep's speeds."""
    if real is None:
        return {}
    first = seeds[0]["tests"] if seeds else None
    return {"paths": len(ctx.realism_curves), "real_windows": int(len(real["labels"])),
            "speeds_m_per_s": list(own_paths.STRIDE_SPEEDS), "fit_band_m_per_s": list(own_paths.FIT_BAND),
            "real_slope_within_styles": real["real_slope_within_styles"],
            "real_slope_across_styles": real["real_slope_across_styles"],
            "generated_tests_first_seed": first, "real_reference": real["reference"],
            "stride_clips": [{"style": ctx.style_names[r["style"]], **{k: v for k, v in r.items() if k != "style"}}
                             for r in real["stride_clips"]],
            "speed_free_evaluator": None if ctx.ev_speed_free is None else {
                "checksum": ctx.ev_speed_free.checksum, "real_heldout": ctx.ev_speed_free.meta.get("real_heldout")}}


def _ci(values) -> dict:
    vals = np.asarray(values, np.float64)
    if not np.isfinite(vals).any():
        return {"mean": float("nan"), "ci95": float("nan"), "per_seed": vals.tolist()}
    m, h = metrics.mean_ci95(vals)
    return {"mean": m, "ci95": h, "per_seed": vals.tolist()}


def _load_matching(ev_path, style_names, layout, cfg, source) -> evaluator.Evaluator:
    """An evaluator that fits the model: its styles, skeleton and window length."""
    ev = evaluator.load(ev_path)
    problems = []
    if tuple(ev.style_names) != style_names:
        problems.append(f"styles {list(ev.style_names)} vs the model's {list(style_names)}")
    if tuple(ev.meta.get("joint_names", ())) != tuple(layout.joint_names):
        problems.append("a different skeleton")
    if ev.meta.get("window_T") != cfg.data.window_T:
        problems.append(f"window T {ev.meta.get('window_T')} vs {cfg.data.window_T}")
    if problems:
        raise evaluator.EvaluatorError(f"{ev_path} does not match the run {source}: " + "; ".join(problems))
    return ev


def _load(workdir, step, params, model):
    """(state, meta, cfg, layout, checkpoint step, source) of a run's checkpoint or an export."""
    if workdir is None:
        state, meta, cfg, layout = pretrained.load_model(None, step, params, model)
        return state, meta, cfg, layout, int(state.step), str(model or pretrained.SHIPPED_MODEL.name)
    ckpt_step = checkpoint.resolve_step(workdir, step)
    state, meta, cfg, layout = checkpoint.load_run(workdir, ckpt_step, params)
    return state, meta, cfg, layout, ckpt_step, str(workdir)


def _heldout(cfg, data_dir, style_names):
    if data_dir is not None:
        cfg = dataclasses.replace(cfg, data=dataclasses.replace(cfg.data, data_dir=data_dir))
    dataset = clip_cache.load_dataset(cfg.data)
    if tuple(dataset.style_names) != tuple(style_names):
        raise file_labels.DataError(f"the data's styles {list(dataset.style_names)} differ from the model's")
    if not dataset.val:
        raise file_labels.DataError("the validation split is empty: no held-out data to evaluate on")
    return cfg, dataset


def search_run(workdir, settings: style_recovery.Settings, *, step: int | None = None, params: str = "ema",
               data_dir=None, model=None, log: Callable[[str], None] = print) -> tuple[dict, dict]:
    """The style search alone (`bin/evaluate.py --search-only`) on the run `workdir` (or the export
    `model`, default the shipped model) and its held-out clips: (style_recovery.recovery's result,
    a header naming the model, config, step and files)."""
    state, meta, cfg, layout, ckpt_step, source = _load(workdir, step, params, model)
    cfg, dataset = _heldout(cfg, data_dir, meta["style_names"])
    log(f"style search on {len(dataset.val)} held-out clips of {source}")
    result = style_recovery.recovery(state, meta, cfg, layout, dataset.val, dataset.style_names, settings, log=log)
    header = {"workdir": source, "config_name": cfg.name, "config_hash": config_hash(cfg),
              "checkpoint_step": ckpt_step, "val_files": sorted(Path(c.source).name for c in dataset.val),
              "data_dir": dataset.data_dir}
    return result, header


def evaluate_run(workdir, settings: Settings, shapes: Sequence[str], *, step: int | None = None,
                 params: str = "ema", data_dir=None, evaluator_path=None, cmu_curves=None,
                 speed_free_evaluator_path=None, model=None,
                 log: Callable[[str], None] = print) -> tuple[dict, Context]:
    """The protocol on the run `workdir` (its checkpoint `step`, G's `params`): loads the model, the
    evaluator (default WORKDIR/evaluator.npz, which must match the run) and the run's data (or
    `data_dir`), builds the unseen curves (held-out paths, the root paths of the BVH files in
    `cmu_curves`, the synthetic `shapes`) and evaluates. Returns the report {"header", "results"}
    and the context (for `write_report`). With `workdir` None, the export file `model` (default
    the shipped model) is evaluated instead: it holds G alone, so the discriminator probe is
    skipped, and `evaluator_path` must be given. The speed-free evaluator (default
    WORKDIR/evaluator_speed_free.npz when that exists) adds its style accuracy to the realism part.
    Raises ConfigError, DataError, BVHError, CheckpointError, EvaluatorError, EvaluationError or
    GenerateError naming the problem."""
    if workdir is None and not evaluator_path:
        raise ConfigError("evaluating a model file needs --evaluator (there is no run to find one in)")
    state, meta, cfg, layout, ckpt_step, source = _load(workdir, step, params, model)
    ev_path = Path(evaluator_path) if evaluator_path else Path(workdir) / "evaluator.npz"
    style_names = tuple(meta["style_names"])
    ev = _load_matching(ev_path, style_names, layout, cfg, source)
    sf_path = (Path(speed_free_evaluator_path) if speed_free_evaluator_path
               else (Path(workdir) / "evaluator_speed_free.npz" if workdir is not None else None))
    ev_sf = None
    if sf_path is not None and (speed_free_evaluator_path or sf_path.is_file()):
        ev_sf = _load_matching(sf_path, style_names, layout, cfg, source)
        if not ev_sf.meta["config"].get("speed_free"):
            raise evaluator.EvaluatorError(f"{sf_path} is not a speed-free evaluator (bin/train_evaluator.py "
                                           "--speed-free)")
    cfg, dataset = _heldout(cfg, data_dir, style_names)
    rate = walk.sample_rate(meta, cfg)
    T = cfg.data.window_T
    L = settings.windows_per_curve * T
    speed = median_speed(dataset.val, dataset.fps)
    eval_curves = heldout_curves(dataset.val, cfg, L, settings.max_heldout_curves)
    if cmu_curves:
        files = sorted(Path(cmu_curves).glob("*.bvh"))
        if not files:
            raise ConfigError(f"--cmu-curves {cmu_curves}: no .bvh files")
        eval_curves += file_curves(files[: settings.max_cmu_curves], rate, L, T,
                                   cfg.data.control_point_interval / dataset.fps, log=log)
    eval_curves += shape_curves(rate, speed, L, T, shapes)
    feet = foot_joints(layout)
    contact = gait_stats.contact_height(dataset.train, layout, feet)
    log(f"contact height {contact * 100:.1f} cm (calibrated on the training clips)")
    long_curve = long_line(rate, speed, settings.long_curve_m)
    probe = None if workdir is None else jax.jit(sampling.make_sample_batch(cfg.data, d_probe.PROBE_WINDOWS))(
        sampling.build_arrays(dataset.train, dataset.style_names, cfg.data), jax.random.key(0), 0)
    ctx = Context(state, meta, cfg, layout, ev, style_names, dataset.val, rate, feet,
                  eval_curves, settings, contact, long_curve, probe, ev_sf)
    ctx.realism_curves = own_paths.curves_of(ctx)
    results = evaluate(ctx, log=log)

    counts = {}
    for c in eval_curves:
        counts[c.kind] = counts.get(c.kind, 0) + 1
    header = {
        "workdir": source, "config_name": cfg.name, "config_hash": config_hash(cfg),
        "checkpoint_step": ckpt_step,
        "g_params": (f"moving average (train.g_ema_decay {cfg.train.g_ema_decay})"
                     if params == "ema" and cfg.train.g_ema_decay > 0 else "raw"),
        "evaluator": str(ev_path), "evaluator_checksum": ev.checksum,
        "speed_free_evaluator": None if ev_sf is None else str(sf_path),
        "speed_free_evaluator_checksum": None if ev_sf is None else ev_sf.checksum,
        "evaluator_real_heldout": ev.meta.get("real_heldout"), "style_names": list(style_names),
        "settings": dataclasses.asdict(settings), "curve_counts": counts,
        "curves": [{"name": c.name, "kind": c.kind, "samples": len(c.curve_Lx3), "source": c.source}
                   for c in eval_curves],
        "train_files": sorted(Path(c.source).name for c in dataset.train),
        "val_files": sorted(Path(c.source).name for c in dataset.val),
        "data_dir": dataset.data_dir, "walking_speed_m_per_s": speed, "sample_rate_hz": rate,
        "feet": [layout.joint_names[i] for i in feet],
    }
    return {"header": header, "results": results}, ctx
