"""The evaluation protocol (docs/DESIGN.md §7) as one driver: curves, generation,
every metric for generated and real held-out data side by side, and the reports.

Conventions. Generated clips are placed by `generate.generate_motion` (root integrated from the
curve start, feet put on the floor by a percentile shift); real held-out windows get the same
floor shift, so ground-penetration figures compare like with like. Feet are the two toe joints
(`foot_joints`). Generated motion is cut into evaluator windows of the training length T.
Every (curve × style) pair gets K noise draws per seed; statistics are averaged per seed, and the
report gives mean ± 95% CI over seeds (`metrics.mean_ci95`). Real data have no seeds: one value.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
from pathlib import Path
from typing import Callable, Sequence

import jax
import jax.numpy as jnp
import numpy as np
import scipy.special
from scipy.ndimage import gaussian_filter1d

from motiongan_jax import analysis, atomic, checkpoint, curves, data, evaluator, generate, metrics
from motiongan_jax import step as step_lib
from motiongan_jax.config import ConfigError, config_hash
from motiongan_jax.representation import facing_joints, foot_joints, from_rows, rest_positions

TURNING_DEG = 45.0  # a held-out path whose heading changes more than this is "turning"
PENETRATION_TOLERANCE_M = 0.02


class EvaluationError(ValueError):
    pass


@dataclasses.dataclass(frozen=True)
class EvalCurve:
    name: str
    kind: str  # heldout_straight, heldout_turning, cmu, synthetic
    curve_Lx3: np.ndarray  # metres, y = 0, starts at the origin
    source: str


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
    search_steps: int = 200
    w_samples: int = 10


def _heading_change_deg(curve_Lx3) -> float:
    d = np.diff(curve_Lx3[:, [0, 2]], axis=0)
    d = d[np.linalg.norm(d, axis=1) > 1e-9]
    if len(d) < 2:
        return 0.0
    ang = np.unwrap(np.arctan2(d[:, 0], d[:, 1]))
    return float(np.degrees(ang.max() - ang.min()))


# ---------------------------------------------------------------------------------------------
# Curves
# ---------------------------------------------------------------------------------------------


def heldout_curves(val_clips, cfg, L: int, max_curves: int) -> list[EvalCurve]:
    """The noise-free training curve of each held-out clip's first L-sample stretch (fewer
    samples, a multiple of T, if the clip is shorter), round-robin over styles."""
    T, step = cfg.data.window_T, cfg.data.frame_step
    by_style: dict[str, list] = {}
    for clip in val_clips:
        by_style.setdefault(clip.label.style, []).append(clip)
    order = []
    while any(by_style.values()):
        for s in sorted(by_style):
            if by_style[s]:
                order.append(by_style[s].pop(0))
    out = []
    for clip in order:
        F = len(clip.root_Fx3)
        n = min(L, ((F - 1) // step + 1) // T * T)
        if n < T:
            continue
        mw = analysis.windows_from_rows(clip.root_Fx3, clip.pose_FxR, T=n, frame_step=step,
                                        interval=cfg.data.control_point_interval, max_windows=1)
        c = np.asarray(mw.curve_NxTx3[0], np.float64)
        c = c - c[0] * np.array([1.0, 0.0, 1.0])
        kind = "heldout_turning" if _heading_change_deg(c) > TURNING_DEG else "heldout_straight"
        out.append(EvalCurve(Path(clip.source).stem, kind, c.astype(np.float32), clip.source))
        if len(out) >= max_curves:
            break
    return out


def file_curves(paths: Sequence[Path], sample_rate: float, L: int, T: int, control_seconds: float,
                log=None) -> list[EvalCurve]:
    """Root paths of BVH files from another session or lab (their own speed), trimmed to L."""
    out = []
    for p in paths:
        try:
            c = generate.load_curve(str(p), control_seconds=control_seconds)
            arr = generate.prepare_curve(c, sample_rate)
        except (ValueError, OSError) as err:
            if log:
                log(f"skipping curve {p}: {err}")
            continue
        n = min(L, len(arr) // T * T)
        if n < T:
            continue
        arr = arr[:n] - arr[0] * np.array([1.0, 0.0, 1.0], np.float32)
        out.append(EvalCurve(Path(p).stem, "cmu", arr.astype(np.float32), str(p)))
    return out


def shape_curves(sample_rate: float, speed: float, L: int, T: int,
                 shapes: Sequence[str] = curves.SHAPES) -> list[EvalCurve]:
    """The synthetic shapes (line, circle, S-curve, figure-8, 90° corner) walked at `speed`."""
    out = []
    length = L * speed / sample_rate
    for name in shapes:
        kw = {"length": length} if name in ("line", "corner") else {"scale": max(length / (2 * math.pi), 1.0)}
        if name == "figure8":
            kw = {"scale": max(length / (4 * math.pi), 1.0)}
        arr = generate.prepare_curve(generate.load_curve(name, **kw), sample_rate, speed)
        n = min(L, len(arr) // T * T)
        if n < T:
            continue
        arr = arr[:n] - arr[0] * np.array([1.0, 0.0, 1.0], np.float32)
        out.append(EvalCurve(name, "synthetic", arr.astype(np.float32), f"shape:{name}"))
    return out


def long_line(sample_rate: float, speed: float, length_m: float) -> EvalCurve:
    """A straight line of `length_m` metres walked at `speed`: the drift test's curve."""
    arr = generate.prepare_curve(generate.load_curve("line", length=length_m), sample_rate, speed)
    arr = arr - arr[0] * np.array([1.0, 0.0, 1.0], np.float32)
    return EvalCurve(f"line_{length_m:g}m", "long", arr.astype(np.float32), f"shape:line:{length_m:g}m")


def median_speed(clips, fps: float) -> float:
    """Median walking speed (m/s) of clips: floor path length over duration."""
    s = []
    for c in clips:
        xz = np.asarray(c.root_Fx3)[:, [0, 2]]
        if len(xz) > 1:
            s.append(np.sum(np.linalg.norm(np.diff(xz, axis=0), axis=1)) / ((len(xz) - 1) / fps))
    return float(np.median(s)) if s else generate.DEFAULT_SPEED_M_PER_S


# ---------------------------------------------------------------------------------------------
# Per-clip motion metrics (generated and real alike)
# ---------------------------------------------------------------------------------------------


GAIT_KEYS = ("support", "lower_foot_height_m", "alternation", "step_frequency_hz", "step_amplitude_m",
             "root_height_range_m")


def gait_metrics(joints_LxJx3, feet, fps: float, contact_height: float) -> dict:
    """Does it walk: support, lower-toe height, alternation, step frequency and amplitude (toe
    heights above the clip's own floor, metrics.toe_heights) and the root's height range."""
    h = metrics.toe_heights(joints_LxJx3[:, list(feet)])
    return {"support": metrics.support(h, contact_height), "lower_foot_height_m": metrics.lower_foot_height(h),
            "alternation": metrics.alternation(h), "step_frequency_hz": metrics.step_frequency_hz(h, fps),
            "step_amplitude_m": metrics.step_amplitude_m(h),
            "root_height_range_m": metrics.height_range_m(joints_LxJx3[:, 0])}


@dataclasses.dataclass(frozen=True)
class GaitTrace:
    style: str
    source: str  # the held-out clip whose path G walked
    real_heights_Tx2: np.ndarray  # that clip's toe heights above its floor (left, right), metres
    gen_heights_Tx2: np.ndarray  # G's, walking the clip's path in the clip's style


def gait_traces(state, cfg, layout, val_clips, style_names, feet, sample_rate: float, seconds: float = 6.0,
                seed: int = 0) -> list[GaitTrace]:
    """Per style, the first held-out clip of that style and G's walk of its path in its style (one
    noise draw z from `seed`, phase offset 0), as toe heights at the network's sample rate, over at
    most `seconds` (a multiple of 8 samples, at least 16)."""
    step = cfg.data.frame_step
    out = []
    for c, name in enumerate(style_names):
        clip = next((v for v in val_clips if v.label.style == name), None)
        if clip is None:
            continue
        n = min(int(seconds * sample_rate), (len(clip.root_Fx3) - 1) // step + 1) // 8 * 8
        if n < generate.MIN_T:
            continue
        mw = analysis.windows_from_rows(clip.root_Fx3, clip.pose_FxR, T=n, frame_step=step,
                                        interval=cfg.data.control_point_interval, max_windows=1)
        curve = np.asarray(mw.curve_NxTx3[0], np.float32)
        z = jax.random.normal(jax.random.fold_in(jax.random.key(seed), c), (1, step_lib.generator_z_dim(state)))
        gen = generate.generate_motion(state, layout, curve, np.asarray(generate.latent_codes(state, np.array([c]), z)))
        real = np.asarray(from_rows(clip.root_Fx3[: (n - 1) * step + 1: step], clip.pose_FxR[: (n - 1) * step + 1: step],
                                    layout), np.float64)
        out.append(GaitTrace(name, clip.source, metrics.toe_heights(real[:, list(feet)]),
                             metrics.toe_heights(gen.positions[0][:, list(feet)])))
    return out


def motion_metrics(joints_LxJx3, curve_Lx3, layout, feet, fps: float, contact_height: float) -> dict:
    """Trajectory (when a curve is given), skating, skeleton, facing, smoothness and gait of one
    clip. Contacts (skating ratio, support) are toes within `contact_height` of the clip's floor."""
    toes = joints_LxJx3[:, list(feet)]
    toes_on_floor = toes.copy()
    toes_on_floor[..., 1] = metrics.toe_heights(toes)
    hips = facing_joints(layout)
    out = {
        "facing_error_deg": float("nan") if hips is None else metrics.facing_error_deg(joints_LxJx3, *hips),
        "foot_skate_original_m": metrics.foot_skate_original(toes),
        "skate_ratio": metrics.skate_ratio(toes_on_floor, fps, contact_height),
        "bone_length_error": metrics.bone_length_error(joints_LxJx3, np.asarray(layout.bone_pairs),
                                                       np.asarray(layout.bone_lengths_m)),
        "ground_penetration": metrics.ground_penetration(toes[..., 1], PENETRATION_TOLERANCE_M),
        "jerk_mps3": metrics.mean_jerk(joints_LxJx3, fps),
        **gait_metrics(joints_LxJx3, feet, fps, contact_height),
    }
    if curve_Lx3 is not None:
        root = joints_LxJx3[:, 0]
        out.update({
            "traj_error_original_m": metrics.trajectory_error_original(root, curve_Lx3),
            "traj_error_symmetric_m": metrics.trajectory_error_symmetric(root, curve_Lx3),
            "endpoint_error_m": metrics.endpoint_error(root, curve_Lx3),
            "path_length_ratio": metrics.path_length_ratio(root, curve_Lx3),
        })
    return out


def cut_windows(root_BxLx3, pose_BxLxR, T: int):
    """Back-to-back windows of T samples of every motion: (root (B·n) x T x 3, pose, n)."""
    B, L, _ = root_BxLx3.shape
    frames = curves.window_indices(L, T)
    n = len(frames)
    return root_BxLx3[:, frames].reshape(B * n, T, 3), pose_BxLxR[:, frames].reshape(B * n, T, -1), n


# ---------------------------------------------------------------------------------------------
# The driver
# ---------------------------------------------------------------------------------------------


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
    contact_height_m: float  # calibrated on the real training clips (data.contact_height)
    long_curve: EvalCurve | None = None  # tens of metres: does the walk drift?
    probe_batch: dict | None = None  # real training windows from the run's sampler, for discriminator_probe


def _real_block(ctx: Context) -> dict:
    """Every per-clip metric and evaluator score on real held-out data."""
    T, step = ctx.cfg.data.window_T, ctx.cfg.data.frame_step
    root, pose, labels, _ = evaluator.real_windows(ctx.val_clips, ctx.style_names, T, step)
    if len(root) < 2:
        raise EvaluationError("fewer than two real held-out windows: cannot evaluate")
    logits, feats = evaluator.classify(ctx.ev, root, pose)
    joints = np.asarray(from_rows(root, pose, ctx.layout), np.float64)
    shift = generate.floor_shift(joints)
    joints[..., 1] += shift[:, None, None]
    contact = ctx.contact_height_m
    per = []
    for i in range(len(joints)):
        per.append(motion_metrics(joints[i], None, ctx.layout, ctx.feet, ctx.sample_rate, contact))
    # trajectory of real motion against its own (noise-free) curve, on the held-out curves
    traj = []
    for c in ctx.curves_:
        if not c.kind.startswith("heldout"):
            continue
        clip = next(cl for cl in ctx.val_clips if cl.source == c.source)
        n = len(c.curve_Lx3)
        r = np.asarray(clip.root_Fx3, np.float64)[: (n - 1) * step + 1: step]
        r = r - r[0] * np.array([1.0, 0.0, 1.0])
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
            clips[clip.source] = {"style": clip.label.style, **gait_metrics(j, ctx.feet, ctx.sample_rate, contact)}
    return {"logits": logits, "feats": feats, "labels": labels, "per_window": per, "traj": traj,
            "contact_height_m": contact, "joints": joints, "clips": clips}


def _generate_block(ctx: Context, seed: int, contact: float) -> dict:
    """Generation for every (curve × style × K) with one seed; per-clip metrics and scores."""
    s = ctx.settings
    C = len(ctx.style_names)
    T = ctx.cfg.data.window_T
    Z = step_lib.generator_z_dim(ctx.state)
    labels = np.repeat(np.arange(C, dtype=np.int32), s.k)
    key = jax.random.key(seed)
    rows, win_logits, win_feats, win_labels, mm_groups = [], [], [], [], []
    for ci, c in enumerate(ctx.curves_):
        z = jax.random.normal(jax.random.fold_in(key, ci), (C * s.k, Z), jnp.float32)
        w = generate.latent_codes(ctx.state, labels, z)
        # each draw starts its walk at its own gait phase, as in training
        phase = (np.asarray(jax.random.uniform(jax.random.fold_in(key, 100_000 + ci), (C * s.k,), maxval=2 * np.pi))
                 if step_lib.has_gait_phase(ctx.state) else None)
        gen = generate.generate_motion(ctx.state, ctx.layout, c.curve_Lx3, np.asarray(w), phase)
        root = gen.positions[:, :, 0]
        r, p, n = cut_windows(root, gen.pose, T)
        logits, feats = evaluator.classify(ctx.ev, r, p)
        win_logits.append(logits)
        win_feats.append(feats)
        win_labels.append(np.repeat(labels, n))
        # multimodality: the K draws of one (curve, style), each clip's mean window feature
        clip_feats = feats.reshape(C * s.k, n, -1).mean(1).reshape(C, s.k, -1)
        mm_groups.append(clip_feats)
        for b in range(C * s.k):
            m = motion_metrics(gen.positions[b], c.curve_Lx3, ctx.layout, ctx.feet, ctx.sample_rate, contact)
            rows.append({"curve": c.name, "kind": c.kind, "source": c.source, "style": int(labels[b]), **m})
    return {"rows": rows, "logits": np.concatenate(win_logits), "feats": np.concatenate(win_feats),
            "labels": np.concatenate(win_labels), "mm": np.concatenate(mm_groups)}


def _long_curve_block(ctx: Context, seed: int) -> dict:
    """Every style (one noise draw) along the long curve: gait metrics, averaged over styles."""
    C = len(ctx.style_names)
    z = jax.random.normal(jax.random.key(20_000 + seed), (C, step_lib.generator_z_dim(ctx.state)), jnp.float32)
    w = generate.latent_codes(ctx.state, np.arange(C, dtype=np.int32), z)
    gen = generate.generate_motion(ctx.state, ctx.layout, ctx.long_curve.curve_Lx3, np.asarray(w))
    rows = [gait_metrics(gen.positions[b], ctx.feet, ctx.sample_rate, ctx.contact_height_m) for b in range(C)]
    return {f"long_{k}": _mean_key(rows, k) for k in GAIT_KEYS}


PROBE_WINDOWS = 128  # real training windows the probe judges
PROBE_SMOOTHING_SAMPLES = 2.0  # Gaussian sigma of the "no steps" window
PROBE_FLOAT_M = 0.3  # how far the "floating" window's root rises over the window


def discriminator_probe(state, batch: dict, key) -> dict:
    """Can the trained D teach a gait? Its verdict on real training windows and on the same windows
    turned into a statue gliding along the root (every frame the window's mean pose), smoothed along
    time (no steps: Gaussian over PROBE_SMOOTHING_SAMPLES samples), floating (the root rising
    PROBE_FLOAT_M over the window), and on G's output for their curves and labels (z and the gait
    phase drawn as in training; G's parameters are the state's). Per input: the mean sigmoid of the real/fake logit, and the share
    judged real (logit > 0). A D that judges a glide or a float as real as a walk gives G no
    gradient toward planted feet or the floor."""
    root, pose, labels = (np.asarray(batch[k]) for k in ("root_BxTx3", "pose_BxTxR", "label_B"))
    B, T, _ = root.shape
    vel = np.asarray(curves.velocity(jnp.asarray(root)))
    floating = vel.copy()
    floating[:, 1:, 1] += PROBE_FLOAT_M / (T - 1)
    floating[:, 0, 1] = floating[:, 1, 1]
    z = jax.random.normal(key, (B, step_lib.generator_z_dim(state)), jnp.float32)
    g = step_lib.generator(state)
    offset = (jax.random.uniform(jax.random.fold_in(key, 1), (B,), jnp.float32, 0.0, 2 * np.pi)
              if step_lib.has_gait_phase(state) else None)
    fake_vel, fake_pose = g(curves.velocity(jnp.asarray(batch["curve_BxTx3"])), g.style(jnp.asarray(labels), z), offset)
    inputs = {
        "real windows": (vel, pose),
        "statue gliding along the root": (vel, np.broadcast_to(pose.mean(1, keepdims=True), pose.shape)),
        f"pose smoothed along time (sigma {PROBE_SMOOTHING_SAMPLES:g} samples)":
            (vel, gaussian_filter1d(pose, PROBE_SMOOTHING_SAMPLES, axis=1, mode="nearest")),
        f"root rising {PROBE_FLOAT_M:g} m over the window": (floating, pose),
        "G's output for the same curves and labels": (np.asarray(fake_vel), np.asarray(fake_pose)),
    }
    d = step_lib.discriminator(state)
    out = {}
    for name, (v, p) in inputs.items():
        logit, _ = d(jnp.asarray(v, jnp.float32), jnp.asarray(p, jnp.float32), update_stats=False,
                     labels_B=jnp.asarray(labels))
        logit = np.asarray(logit, np.float64)
        out[name] = {"p_real": float(np.mean(scipy.special.expit(logit))), "judged_real": float(np.mean(logit > 0))}
    return out


def _style_space_block(ctx: Context, seed: int) -> dict:
    """w-space metrics with one seed: nearest-centroid accuracy, PCA, interpolation, arithmetic."""
    s = ctx.settings
    C = len(ctx.style_names)
    T = ctx.cfg.data.window_T
    key = jax.random.key(10_000 + seed)
    k_a, k_b = jax.random.split(key)
    fit = analysis.label_codes(ctx.state, ctx.style_names, k=s.w_samples, key=k_a)
    test = analysis.label_codes(ctx.state, ctx.style_names, k=s.w_samples, key=k_b)
    X, y = test.flat_samples
    cents = np.asarray(fit.centroids_CxD)
    nc_acc = metrics.nearest_centroid_accuracy(np.asarray(X), np.asarray(y), cents)
    ev_ratio = np.asarray(analysis.pca(fit.flat_samples[0]).explained_variance_ratio_K)
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
            gen = generate.generate_motion(ctx.state, ctx.layout, line, w)
            r, p, n = cut_windows(gen.positions[:, :, 0], gen.pose, T)
            logits, _ = evaluator.classify(ctx.ev, r, p)
            pb = np.asarray(jax.nn.softmax(logits, -1))[:, b].reshape(len(alphas), n).mean(1)
            rhos.append(metrics.interpolation_monotonicity(alphas, pb))
        out["interp_monotonicity"] = float(np.nanmean(rhos)) if np.isfinite(rhos).any() else float("nan")
    if C >= 3:
        triples = [(a, (a + 1) % C, (a + 2) % C) for a in range(C)]
        w = np.stack([cents[a] - cents[b] + cents[c] for a, b, c in triples])
        gen = generate.generate_motion(ctx.state, ctx.layout, line, w)
        r, p, n = cut_windows(gen.positions[:, :, 0], gen.pose, T)
        logits, _ = evaluator.classify(ctx.ev, r, p)
        pred = np.argmax(logits, -1).reshape(len(triples), n)
        ok = [np.mean((pred[i] == a) | (pred[i] == c)) for i, (a, b, c) in enumerate(triples)]
        out["arithmetic_agreement"] = float(np.mean(ok))
        out["arithmetic_chance"] = 2.0 / C
    return out


def _search_block(ctx: Context) -> dict:
    """Style search on held-out real clips: is the recovered w nearest its true style's centroid?"""
    s = ctx.settings
    if s.search_clips < 1:
        return {}
    T, step = ctx.cfg.data.window_T, ctx.cfg.data.frame_step
    codes = analysis.label_codes(ctx.state, ctx.style_names, k=s.w_samples)
    taken: dict[str, int] = {}
    hits, losses = [], []
    for clip in ctx.val_clips:
        if taken.get(clip.label.style, 0) >= s.search_clips:
            continue
        try:
            target = analysis.windows_from_rows(clip.root_Fx3, clip.pose_FxR, T=T, frame_step=step,
                                                interval=ctx.cfg.data.control_point_interval, max_windows=2)
        except analysis.AnalysisError:
            continue
        taken[clip.label.style] = taken.get(clip.label.style, 0) + 1
        res = analysis.search_motion(ctx.state, codes, target, steps=s.search_steps)
        hits.append(res["nearest"][0][0] == clip.label.style)
        losses.append(res["result"].loss)
    if not hits:
        return {}
    return {"search_recovery": float(np.mean(hits)), "search_clips": len(hits),
            "search_final_loss": float(np.mean(losses))}


GEN_KEYS = ("traj_error_original_m", "traj_error_symmetric_m", "endpoint_error_m", "path_length_ratio",
            "foot_skate_original_m", "skate_ratio", "bone_length_error", "ground_penetration", "jerk_mps3",
            "facing_error_deg") + GAIT_KEYS


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
           for k in GEN_KEYS if k not in GAIT_KEYS},
        **{k: _mean_key(list(real["clips"].values()), k) for k in GAIT_KEYS},
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
            **{k: _mean_key(clip_rows, k) for k in GAIT_KEYS},
            # the clips of this style whose paths are evaluation curves: the same-curve cadence
            "step_frequency_same_curve_hz": _mean_key(
                [r for src, r in real["clips"].items() if r["style"] == name and src in curve_sources],
                "step_frequency_hz")}

    per_seed, per_seed_style, confusions = [], [], []
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
                                                  "skate_ratio", "bone_length_error") + GAIT_KEYS},
                "step_frequency_same_curve_hz": _mean_key(same, "step_frequency_hz")}
            st[name]["step_frequency_ratio"] = (st[name]["step_frequency_same_curve_hz"]
                                                / real_per_style[name]["step_frequency_same_curve_hz"])
        per_seed_style.append(st)
    log("style search on held-out clips")
    search = _search_block(ctx)
    probe = {} if ctx.probe_batch is None else discriminator_probe(ctx.state, ctx.probe_batch, jax.random.key(30_000))

    keys = list(per_seed[0])
    generated = {k: _ci([r.get(k, float("nan")) for r in per_seed]) for k in keys}
    per_style = {}
    for name in ctx.style_names:
        per_style[name] = {"generated": {k: _ci([st[name][k] for st in per_seed_style]) for k in per_seed_style[0][name]},
                           "real": real_per_style[name]}
    return {
        "generated": generated,
        "real": real_row,
        "per_style": per_style,
        "search": search,
        "discriminator_probe": probe,
        "confusion_generated": np.sum(confusions, axis=0).tolist(),
        "confusion_real": real_sra["confusion_CxC"].tolist(),
        "contact_height_m": ctx.contact_height_m,
        "evaluator_real_heldout": ctx.ev.meta.get("real_heldout"),
        "num_generated_clips_per_seed": len(ctx.curves_) * C * s.k,
        "num_real_windows": int(len(real["labels"])),
    }


def _ci(values) -> dict:
    vals = np.asarray(values, np.float64)
    if not np.isfinite(vals).any():
        return {"mean": float("nan"), "ci95": float("nan"), "per_seed": vals.tolist()}
    m, h = metrics.mean_ci95(vals)
    return {"mean": m, "ci95": h, "per_seed": vals.tolist()}


# ---------------------------------------------------------------------------------------------
# Reports
# ---------------------------------------------------------------------------------------------

ROWS = [
    ("sra_top1", "style accuracy top-1 (evaluator)"),
    ("sra_top3", "style accuracy top-3"),
    ("fmd", "Fréchet motion distance (real: two halves of the held-out windows)"),
    ("diversity", "diversity (feature distance)"),
    ("multimodality", "multimodality (across z)"),
    ("traj_error_original_m", "trajectory error, original (m)"),
    ("traj_error_symmetric_m", "trajectory error, symmetric arc length (m)"),
    ("endpoint_error_m", "end-point error (m)"),
    ("path_length_ratio", "path length ratio"),
    ("foot_skate_original_m", "foot skate, original (m per sample)"),
    ("skate_ratio", "skating ratio (contacts faster than 0.5 m/s)"),
    ("bone_length_error", "bone-length error (relative)"),
    ("facing_error_deg", "facing vs travel direction (degrees)"),
    ("ground_penetration", f"frames with a toe > {PENETRATION_TOLERANCE_M * 100:.0f} cm below the floor"),
    ("jerk_ratio", "jerk ratio (generated / real)"),
    ("support", "support: frames with a toe within the contact height of the floor"),
    ("lower_foot_height_m", "lower toe's mean height above the floor (m)"),
    ("alternation", "alternation: −corr(left, right toe height)"),
    ("step_frequency_hz", "step frequency (gait cycles/s; L−R toe height)"),
    ("step_amplitude_m", "step amplitude (std of L−R toe height, m)"),
    ("root_height_range_m", "root height range per clip (m)"),
    ("long_support", "long curve: support"),
    ("long_lower_foot_height_m", "long curve: lower toe's mean height (m)"),
    ("long_alternation", "long curve: alternation"),
    ("long_root_height_range_m", "long curve: root height range (m; real: the largest of a clip)"),
    ("nearest_centroid_accuracy", "w nearest-centroid accuracy"),
    ("pca_explained_1", "w PCA: variance explained by 1 component"),
    ("pca_explained_2", "w PCA: variance explained by 2 components"),
    ("interp_monotonicity", "interpolation monotonicity (Spearman)"),
    ("arithmetic_agreement", "arithmetic A-B+C classified as A or C"),
]


def _fmt(x, digits=3) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "—"
    return f"{x:.{digits}g}" if abs(x) >= 1e-3 or x == 0 else f"{x:.2e}"


def markdown(report: dict) -> str:
    h = report["header"]
    r = report["results"]
    lines = [f"# Evaluation: {h['config_name']} (step {h['checkpoint_step']})", "",
             f"- workdir: `{h['workdir']}`", f"- config hash: `{h['config_hash']}`",
             f"- checkpoint step: {h['checkpoint_step']}, G's parameters: {h.get('g_params', 'raw')}",
             f"- evaluator: `{h['evaluator']}`, checksum `{h['evaluator_checksum']}`",
             f"- evaluator accuracy on real held-out windows: {_fmt((h.get('evaluator_real_heldout') or {}).get('top1'))} "
             f"(chance {_fmt(1.0 / len(h['style_names']))})",
             f"- seeds {h['settings']['seeds']}, K = {h['settings']['k']} noise draws per (curve, style), "
             f"{r['num_generated_clips_per_seed']} generated clips per seed, {r['num_real_windows']} real held-out windows",
             "- curves: " + ", ".join(f"{k} {v}" for k, v in h["curve_counts"].items()),
             f"- files: training {len(h['train_files'])}, held-out {len(h['val_files'])} (lists in report.json)", "",
             "## Metrics (generated: mean ± 95% CI over seeds; real held-out data)", "",
             "| metric | generated | real |", "|---|---|---|"]
    for key, label in ROWS:
        g = r["generated"].get(key)
        real = r["real"].get(key)
        gs = "—" if g is None else f"{_fmt(g['mean'])} ± {_fmt(g['ci95'])}"
        lines.append(f"| {label} | {gs} | {_fmt(real)} |")
    kinds = sorted(k[len("traj_error_original_m["):-1] for k in r["generated"] if k.startswith("traj_error_original_m["))
    if kinds:
        lines += ["", "Trajectory error by curve kind (m, generated):", "",
                  "| curve kind | original | symmetric |", "|---|---|---|"]
        for kind in kinds:
            a, b = r["generated"][f"traj_error_original_m[{kind}]"], r["generated"][f"traj_error_symmetric_m[{kind}]"]
            lines.append(f"| {kind} | {_fmt(a['mean'])} ± {_fmt(a['ci95'])} | {_fmt(b['mean'])} ± {_fmt(b['ci95'])} |")
    if r.get("search"):
        s = r["search"]
        lines += ["", f"Style search: the recovered w's nearest centroid is the clip's true style for "
                      f"{_fmt(s['search_recovery'])} of {s['search_clips']} held-out clips (final loss {_fmt(s['search_final_loss'])})."]
    lines += ["", "## Per style", "", "| style | SRA gen | SRA real | FMD gen | traj. orig. (m) | skate gen | skate real | bone err gen |",
              "|---|---|---|---|---|---|---|---|"]
    for name, v in r["per_style"].items():
        g, re_ = v["generated"], v["real"]
        lines.append(f"| {name} | {_fmt(g['sra_top1']['mean'])} | {_fmt(re_['sra_top1'])} | {_fmt(g['fmd']['mean'])} | "
                     f"{_fmt(g['traj_error_original_m']['mean'])} | {_fmt(g['foot_skate_original_m']['mean'])} | "
                     f"{_fmt(re_['foot_skate_original_m'])} | {_fmt(g['bone_length_error']['mean'])} |")
    lines += ["", f"Gait per style (contact height {_fmt(r['contact_height_m'])} m, calibrated on the real training "
                  "clips; step frequency in gait cycles/s, on the paths of held-out clips of the same style against "
                  "those clips):", "",
              "| style | support gen | support real | lower toe gen (m) | lower toe real (m) | alternation gen | "
              "alternation real | step freq. gen | step freq. real | ratio |",
              "|---|---|---|---|---|---|---|---|---|---|"]
    for name, v in r["per_style"].items():
        g, re_ = v["generated"], v["real"]
        lines.append(f"| {name} | {_fmt(g['support']['mean'])} | {_fmt(re_['support'])} | "
                     f"{_fmt(g['lower_foot_height_m']['mean'])} | {_fmt(re_['lower_foot_height_m'])} | "
                     f"{_fmt(g['alternation']['mean'])} | {_fmt(re_['alternation'])} | "
                     f"{_fmt(g['step_frequency_same_curve_hz']['mean'])} | {_fmt(re_['step_frequency_same_curve_hz'])} | "
                     f"{_fmt(g['step_frequency_ratio']['mean'])} |")
    if r.get("discriminator_probe"):
        lines += ["", "The trained D's verdict (mean P(real), share judged real) on real training windows and "
                      "on the same windows altered:", "", "| D's input | P(real) | judged real |", "|---|---|---|"]
        for name, v in r["discriminator_probe"].items():
            lines.append(f"| {name} | {_fmt(v['p_real'])} | {_fmt(v['judged_real'])} |")
    lines += ["", "Plots: `confusion.png` (generated and real), `pca_w.png`.", ""]
    return "\n".join(lines)


def plot_confusion(conf_gen, conf_real, style_names, path) -> Path:
    from motiongan_jax import viz

    plt = viz._pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(12, 5.5))
    for ax, conf, title in ((axes[0], conf_gen, "generated"), (axes[1], conf_real, "real held-out")):
        m = np.asarray(conf, np.float64)
        m = m / np.maximum(m.sum(1, keepdims=True), 1)
        im = ax.imshow(m, vmin=0, vmax=1, cmap="Blues")
        ax.set_xticks(range(len(style_names)), style_names, rotation=90, fontsize=7)
        ax.set_yticks(range(len(style_names)), style_names, fontsize=7)
        ax.set_xlabel("predicted")
        ax.set_ylabel("requested" if title == "generated" else "true")
        ax.set_title(f"evaluator confusion, {title}")
    fig.colorbar(im, ax=axes, shrink=0.8)
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def to_jsonable(x):
    """Numpy values -> Python, non-finite floats -> None (strict JSON)."""
    if isinstance(x, dict):
        return {str(k): to_jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [to_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return to_jsonable(x.tolist())
    if isinstance(x, (np.floating, float)):
        return float(x) if math.isfinite(float(x)) else None
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    return x


def dumps(report: dict) -> str:
    return json.dumps(to_jsonable(report), indent=1) + "\n"


# ---------------------------------------------------------------------------------------------
# A trained run evaluated end to end, and the report's files (bin/evaluate.py)


def evaluate_run(workdir, settings: Settings, shapes: Sequence[str], *, step: int | None = None,
                 params: str = "ema", data_dir=None, evaluator_path=None, cmu_curves=None,
                 log: Callable[[str], None] = print) -> tuple[dict, Context]:
    """The protocol on the run `workdir` (its checkpoint `step`, G's `params`): loads the model, the
    evaluator (default WORKDIR/evaluator.npz, which must match the run) and the run's data (or
    `data_dir`), builds the unseen curves (held-out paths, the root paths of the BVH files in
    `cmu_curves`, the synthetic `shapes`) and evaluates. Returns the report {"header", "results"}
    and the context (for `write_report`). Raises ConfigError, DataError, BVHError,
    CheckpointError, EvaluatorError, EvaluationError or GenerateError naming the problem."""
    state, meta, cfg, layout = checkpoint.load_run(workdir, step, params)
    ckpt_step, _ = checkpoint.read_meta(checkpoint.manager(Path(workdir) / "checkpoints"), step)
    if data_dir is not None:
        cfg = dataclasses.replace(cfg, data=dataclasses.replace(cfg.data, data_dir=data_dir))
    ev_path = Path(evaluator_path) if evaluator_path else Path(workdir) / "evaluator.npz"
    ev = evaluator.load(ev_path)
    style_names = tuple(meta["style_names"])
    problems = []
    if tuple(ev.style_names) != style_names:
        problems.append(f"styles {list(ev.style_names)} vs the model's {list(style_names)}")
    if tuple(ev.meta.get("joint_names", ())) != tuple(layout.joint_names):
        problems.append("a different skeleton")
    if ev.meta.get("window_T") != cfg.data.window_T:
        problems.append(f"window T {ev.meta.get('window_T')} vs {cfg.data.window_T}")
    if problems:
        raise evaluator.EvaluatorError(f"{ev_path} does not match the run {workdir}: " + "; ".join(problems))
    dataset = data.load_dataset(cfg.data)
    if tuple(dataset.style_names) != style_names:
        raise data.DataError(f"the data's styles {list(dataset.style_names)} differ from the model's")
    if not dataset.val:
        raise data.DataError("the validation split is empty: no held-out data to evaluate on")
    rate = generate.sample_rate(meta, cfg)
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
    contact = data.contact_height(dataset.train, layout, feet)
    log(f"contact height {contact * 100:.1f} cm (calibrated on the training clips)")
    long_curve = long_line(rate, speed, settings.long_curve_m)
    probe = jax.jit(data.make_sample_batch(cfg.data, PROBE_WINDOWS))(
        data.build_arrays(dataset.train, dataset.style_names, cfg.data), jax.random.key(0), 0)
    ctx = Context(state, meta, cfg, layout, ev, style_names, dataset.val, rate, feet,
                  eval_curves, settings, contact, long_curve, probe)
    results = evaluate(ctx, log=log)

    counts = {}
    for c in eval_curves:
        counts[c.kind] = counts.get(c.kind, 0) + 1
    header = {
        "workdir": str(workdir), "config_name": cfg.name, "config_hash": config_hash(cfg),
        "checkpoint_step": ckpt_step,
        "g_params": (f"moving average (train.g_ema_decay {cfg.train.g_ema_decay})"
                     if params == "ema" and cfg.train.g_ema_decay > 0 else "raw"),
        "evaluator": str(ev_path), "evaluator_checksum": ev.checksum,
        "evaluator_real_heldout": ev.meta.get("real_heldout"), "style_names": list(style_names),
        "settings": dataclasses.asdict(settings), "curve_counts": counts,
        "curves": [{"name": c.name, "kind": c.kind, "samples": len(c.curve_Lx3), "source": c.source} for c in eval_curves],
        "train_files": sorted(Path(c.source).name for c in dataset.train),
        "val_files": sorted(Path(c.source).name for c in dataset.val),
        "data_dir": dataset.data_dir, "walking_speed_m_per_s": speed, "sample_rate_hz": rate,
        "feet": [layout.joint_names[i] for i in feet],
    }
    return {"header": header, "results": results}, ctx


def write_report(out, report: dict, ctx: Context) -> str:
    """Writes OUT/report.json, report.md, confusion.png and pca_w.png (OUT created); returns the
    SHA-256 of report.json as written."""
    from motiongan_jax import viz

    out = Path(out)
    results = report["results"]
    out.mkdir(parents=True, exist_ok=True)
    atomic.write_text(out / "report.json", dumps(report))
    atomic.write_text(out / "report.md", markdown(to_jsonable(report)))
    plot_confusion(results["confusion_generated"], results["confusion_real"], ctx.style_names,
                   out / "confusion.png")
    codes = analysis.label_codes(ctx.state, ctx.style_names, k=10)
    X, y = codes.flat_samples
    p = analysis.pca(X, 2)
    viz.plot_style_pca(np.asarray(analysis.pca_transform(p, X)), np.asarray(y), ctx.style_names, out / "pca_w.png",
                       centroids_Cx2=np.asarray(analysis.pca_transform(p, codes.centroids_CxD)),
                       explained=np.asarray(p.explained_variance_ratio_K)[:2])
    return hashlib.sha256((out / "report.json").read_bytes()).hexdigest()
