"""The protocol's realism part (DESIGN.md §7, item 11): held-out paths walked like for like.

Every held-out clip's path (`eval_curves.heldout_curves`, up to `Settings.realism_windows`
windows) is walked by G in that clip's own style at its own speed (the curve's samples are the
clip's root path at the network's rate), K noise draws per seed; the real clip's same stretch,
sampled the same way, is cut into the same back-to-back windows. On these pairs:
- the classifier two-sample test per feature group (realism.py), with its real reference: the
  real windows split into two halves by path, tested against each other the same way;
- per style, stride frequency, step height (std of left − right toe height), skating ratio and the
  lower toe's height, generated against real;
- style accuracy at the clip's own speed, by the evaluator and by the speed-free evaluator, and
  at the default speed (every style on every held-out path resampled to DEFAULT_SPEED_M_PER_S);
- the stride–speed relation: every style walked on a straight line at each of STRIDE_SPEEDS, its
  step frequency against speed fitted over the speeds within FIT_BAND, against the real
  held-out clips' (per style, and pooled within styles: one slope, a level per style);
- how strides are measured: per style, the training's stride targets (`gait_stats.clip_stride_m`: the
  root path averaged over one gait cycle) against distance per gait cycle and per counted cycle, on held-out clips.
Functions take the protocol's Context (protocol.py); pure measures live in realism.py and metrics.py.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from motiongan_jax.data import gait_stats
from motiongan_jax.evaluation import clip_metrics, evaluator, metrics, realism
from motiongan_jax.evaluation.eval_curves import from_origin, heldout_curves
from motiongan_jax.generate import styles, user_curves, walk
from motiongan_jax.model import apply as model_apply
from motiongan_jax.motion import gait
from motiongan_jax.motion.representation import from_rows

STRIDE_SPEEDS = (0.3, 0.6, 0.95, 1.3, 1.65, 2.0, 2.5, 3.0)  # m/s: the demo's range (0.3-3), 5 within FIT_BAND
FIT_BAND = (0.6, 2.0)  # speeds real walks of these styles cover; the slope is fitted over these
STRIDE_SECONDS = 8.0  # each straight walk of the stride-speed sweep: several gait cycles at 0.3 m/s
STYLE_KEYS = ("own_step_frequency_hz", "own_step_height_m", "own_skate_ratio", "own_lower_foot_height_m")


def curves_of(ctx) -> list:
    """The held-out paths walked like for like (whole clips up to realism_windows windows)."""
    s = ctx.settings
    T = ctx.cfg.data.window_T
    if s.realism_max_curves < 1:
        return []
    return heldout_curves(ctx.val_clips, ctx.cfg, s.realism_windows * T, s.realism_max_curves)


def _clip_of(ctx, source):
    return next(c for c in ctx.val_clips if c.source == source)


def _style_index(ctx, clip) -> int:
    return ctx.style_names.index(clip.label.style)


def _clip_rows(joints_BxLxJx3, ctx) -> list[dict]:
    return [clip_metrics.motion_metrics(j, None, ctx.layout, ctx.feet, ctx.sample_rate, ctx.contact_height_m)
            for j in joints_BxLxJx3]


def _windows(joints_BxLxJx3, T):
    B, L = joints_BxLxJx3.shape[:2]
    n = L // T
    return joints_BxLxJx3[:, : n * T].reshape(B * n, T, *joints_BxLxJx3.shape[2:]), n


def _rows_of(joints_NxTxJx3):
    """(root N x T x 3, pose rows N x T x R) of world joints, for the evaluators."""
    j = np.asarray(joints_NxTxJx3, np.float32)
    root = j[:, :, 0]
    return root, (j[:, :, 1:] - root[:, :, None]).reshape(len(j), j.shape[1], -1)


def style_accuracy(ev, joints_NxTxJx3, labels_N, C) -> tuple[float, np.ndarray]:
    """(top-1, per-class top-1 C) of an evaluator on world-joint windows (nan where a class is absent)."""
    if ev is None or len(labels_N) == 0:
        return float("nan"), np.full(C, np.nan)
    root, pose = _rows_of(joints_NxTxJx3)
    logits, _ = evaluator.classify(ev, root, pose)
    hit = np.argmax(logits, -1) == labels_N
    return float(np.mean(hit)), np.array([np.mean(hit[labels_N == c]) if np.any(labels_N == c) else np.nan
                                          for c in range(C)])


def real_block(ctx) -> dict:
    """Real windows of the held-out paths (features, paths, styles), each clip's gait on the same
    stretch, the two-sample reference (two halves by path), stride measurements, and the real
    stride-speed relation. Keys used by `generated_block` and the report."""
    T, step = ctx.cfg.data.window_T, ctx.cfg.data.frame_step
    C = len(ctx.style_names)
    body = realism.body(ctx.layout)
    feats, paths, labels, ev_feats, per_clip, wins = [], [], [], [], [], []
    for c in ctx.realism_curves:
        clip = _clip_of(ctx, c.source)
        n = len(c.curve_Lx3)
        j = np.asarray(from_rows(clip.root_Fx3[: (n - 1) * step + 1: step], clip.pose_FxR[: (n - 1) * step + 1: step],
                                 ctx.layout), np.float64)
        j[..., 1] += walk.floor_shift(j[None])[0]
        w, k = _windows(j[None], T)
        X, names, kinds = realism.window_features(w, body, ctx.sample_rate, ctx.contact_height_m)
        feats.append(X)
        wins.append(w)
        paths += [c.source] * k
        labels += [_style_index(ctx, clip)] * k
        ev_feats.append(evaluator.classify(ctx.ev, *_rows_of(w))[1])
        per_clip.append({"source": c.source, "style": _style_index(ctx, clip), **_clip_rows(j[None], ctx)[0]})
    X = np.concatenate(feats)
    paths, labels = np.asarray(paths), np.asarray(labels, np.int32)
    E = np.concatenate(ev_feats)
    reference = _reference(X, E, names, kinds, paths, labels)
    windows = np.concatenate(wins)
    top1, _ = style_accuracy(ctx.ev, windows, labels, C)
    sf_top1, sf_per = style_accuracy(ctx.ev_speed_free, windows, labels, C)
    out = {"X": X, "names": names, "kinds": kinds, "paths": paths, "labels": labels, "ev_feats": E,
           "per_clip": per_clip, "reference": reference, "sra": top1, "sra_speed_free": sf_top1,
           "sra_speed_free_per_style": sf_per}
    out.update(_real_strides(ctx))
    return out


def _reference(X, E, names, kinds, paths, labels) -> dict | None:
    """The two-sample test of real against real: the windows of styles with two or more paths,
    their paths dealt to two halves (realism.split_halves). None with fewer than 4 such paths: a
    style with one path would sit in one half only, and the test would tell styles apart."""
    many = [c for c in np.unique(labels) if len(np.unique(paths[labels == c])) >= 2]
    keep = np.isin(labels, many)
    if len(np.unique(paths[keep])) < 4:
        return None
    X, E, paths, labels = X[keep], E[keep], paths[keep], labels[keep]
    half = realism.split_halves(paths, labels)
    a, b = half == 0, half == 1
    return realism.realism_tests(X[a], X[b], names, kinds, paths[a], paths[b],
                                 realism.numpy_rng(jax.random.key(40_000)), extra={"evaluator": (E[a], E[b])})


def _real_strides(ctx) -> dict:
    """Per held-out clip (whole, at the data's rate): walking speed, step frequency, the training's
    stride measure, distance per cycle, and the counted stride; the per-style and pooled slopes."""
    toes = list(ctx.feet)
    rows = []
    for clip in ctx.val_clips:
        j = np.asarray(from_rows(clip.root_Fx3, clip.pose_FxR, ctx.layout), np.float64)
        h = gait.toe_heights(j[:, toes])
        counted = gait.counted_gait_cycles(j[:, 0], h, clip.fps)
        rows.append({"style": _style_index(ctx, clip), "speed_mps": gait.walking_speed_mps(j[:, 0], clip.fps),
                     "step_frequency_hz": gait.step_frequency_hz(h, clip.fps),
                     "training_stride_m": gait_stats.clip_stride_m(clip, ctx.layout, ctx.feet),
                     "distance_per_cycle_m": gait.distance_per_cycle_m(j[:, 0], h, clip.fps),
                     "counted_stride_m": counted["stride_m"], "counted_frequency_hz": counted["frequency_hz"]})
    ok = [r for r in rows if np.isfinite(r["step_frequency_hz"])]
    slopes = {}
    for c in range(len(ctx.style_names)):
        mine = [r for r in ok if r["style"] == c and FIT_BAND[0] <= r["speed_mps"] <= FIT_BAND[1]]
        slopes[c] = (metrics.linear_fit([r["speed_mps"] for r in mine], [r["step_frequency_hz"] for r in mine])
                     if len(mine) >= 2 else {"slope": float("nan"), "intercept": float("nan"), "n": len(mine)})
    band = [r for r in ok if FIT_BAND[0] <= r["speed_mps"] <= FIT_BAND[1]]
    pooled = (metrics.linear_fit([r["speed_mps"] for r in band], [r["step_frequency_hz"] for r in band],
                                 [r["style"] for r in band]) if len(band) >= 2 else {"slope": float("nan")})
    across = (metrics.linear_fit([r["speed_mps"] for r in band], [r["step_frequency_hz"] for r in band])
              if len(band) >= 2 else {"slope": float("nan")})
    return {"stride_clips": rows, "real_slope_per_style": slopes, "real_slope_within_styles": pooled["slope"],
            "real_slope_across_styles": across["slope"]}


def _phases(ctx, key, B):
    if not model_apply.has_gait_phase(ctx.state):
        return None
    return np.asarray(jax.random.uniform(key, (B,), maxval=2 * np.pi))


def generated_block(ctx, seed: int, real: dict) -> dict:
    """One seed: K draws of every held-out path in its clip's style at its speed; the two-sample
    tests against `real`, the per-style gait, and style accuracy by both evaluators."""
    s = ctx.settings
    T = ctx.cfg.data.window_T
    C = len(ctx.style_names)
    Z = model_apply.z_dim(ctx.state)
    body = realism.body(ctx.layout)
    key = jax.random.key(50_000 + seed)
    feats, paths, labels, ev_feats, wins, per_clip = [], [], [], [], [], []
    for ci, c in enumerate(ctx.realism_curves):
        clip = _clip_of(ctx, c.source)
        style = _style_index(ctx, clip)
        k_z, k_p = jax.random.split(jax.random.fold_in(key, ci))
        z = jax.random.normal(k_z, (s.k, Z), jnp.float32)
        w = styles.latent_codes(ctx.state, np.full(s.k, style, np.int32), z)
        gen = walk.generate_motion(ctx.state, ctx.layout, c.curve_Lx3, np.asarray(w), _phases(ctx, k_p, s.k))
        win, n = _windows(gen.positions, T)
        X, _, _ = realism.window_features(win, body, ctx.sample_rate, ctx.contact_height_m)
        feats.append(X)
        wins.append(win)
        paths += [c.source] * len(win)
        labels += [style] * len(win)
        ev_feats.append(evaluator.classify(ctx.ev, *_rows_of(win))[1])
        per_clip += [{"source": c.source, "style": style, **r} for r in _clip_rows(gen.positions, ctx)]
    X = np.concatenate(feats)
    paths, labels = np.asarray(paths), np.asarray(labels, np.int32)
    E = np.concatenate(ev_feats)
    tests = realism.realism_tests(real["X"], X, real["names"], real["kinds"], real["paths"], paths,
                                  realism.numpy_rng(jax.random.key(60_000 + seed)),
                                  extra={"evaluator": (real["ev_feats"], E)})
    windows = np.concatenate(wins)
    top1, per = style_accuracy(ctx.ev, windows, labels, C)
    sf_top1, sf_per = style_accuracy(ctx.ev_speed_free, windows, labels, C)
    return {"tests": tests, "per_clip": per_clip, "sra_own_speed": top1, "sra_own_speed_per_style": per,
            "sra_speed_free_own_speed": sf_top1, "sra_speed_free_own_speed_per_style": sf_per}


def default_speed_block(ctx, seed: int) -> dict:
    """One seed: every style (one draw) on every held-out path resampled to the default speed;
    style accuracy by both evaluators, overall and per style."""
    T = ctx.cfg.data.window_T
    C = len(ctx.style_names)
    Z = model_apply.z_dim(ctx.state)
    key = jax.random.key(70_000 + seed)
    wins, labels = [], []
    resampled = [user_curves.prepare_curve(c.curve_Lx3[:, [0, 2]].astype(np.float64), ctx.sample_rate,
                                           user_curves.DEFAULT_SPEED_M_PER_S) for c in ctx.realism_curves]
    # one length for all (whole windows of the shortest long enough, at most the sweep's): G
    # compiles once per length, and the sweep's C walks of that length share the compilation
    n = min((len(c) // T * T for c in resampled if len(c) >= T), default=0)
    n = min(n, sweep_samples(ctx))
    for ci, curve in enumerate(resampled):
        if n == 0 or len(curve) < n:
            continue
        curve = from_origin(curve[:n])
        k_z, k_p = jax.random.split(jax.random.fold_in(key, ci))
        z = jax.random.normal(k_z, (C, Z), jnp.float32)
        w = styles.latent_codes(ctx.state, np.arange(C, dtype=np.int32), z)
        gen = walk.generate_motion(ctx.state, ctx.layout, curve, np.asarray(w), _phases(ctx, k_p, C))
        win, per = _windows(gen.positions, T)
        wins.append(win)
        labels.append(np.repeat(np.arange(C, dtype=np.int32), per))
    if not wins:
        return {}
    windows, labels = np.concatenate(wins), np.concatenate(labels)
    top1, per = style_accuracy(ctx.ev, windows, labels, C)
    sf_top1, sf_per = style_accuracy(ctx.ev_speed_free, windows, labels, C)
    return {"sra_default_speed": top1, "sra_default_speed_per_style": per,
            "sra_speed_free_default_speed": sf_top1, "sra_speed_free_default_speed_per_style": sf_per}


def sweep_samples(ctx) -> int:
    """Samples of each walk of the stride-speed sweep: STRIDE_SECONDS in whole windows."""
    T = ctx.cfg.data.window_T
    return max(int(np.ceil(STRIDE_SECONDS * ctx.sample_rate / T)), 1) * T


def stride_speed_block(ctx, seed: int) -> dict:
    """One seed: every style (one draw) on a straight line at each of STRIDE_SPEEDS; step
    frequency (Hz) per style and speed, and per style the slope of frequency on speed over the
    speeds within FIT_BAND."""
    C = len(ctx.style_names)
    Z = model_apply.z_dim(ctx.state)
    key = jax.random.key(80_000 + seed)
    k_z, k_p = jax.random.split(key)
    z = jax.random.normal(k_z, (C, Z), jnp.float32)
    w = np.asarray(styles.latent_codes(ctx.state, np.arange(C, dtype=np.int32), z))
    phase = _phases(ctx, k_p, C)  # one draw per style, walked at every speed
    freq = np.full((C, len(STRIDE_SPEEDS)), np.nan)
    m = sweep_samples(ctx)
    for si, v in enumerate(STRIDE_SPEEDS):
        # a little longer than needed, then cut: every speed walks the same samples (one compilation)
        line = user_curves.prepare_curve(user_curves.load_curve("line", length=v * (m + 2) / ctx.sample_rate),
                                         ctx.sample_rate, v)[:m]
        gen = walk.generate_motion(ctx.state, ctx.layout, from_origin(line), w, phase)
        for c in range(C):
            freq[c, si] = gait.step_frequency_hz(gait.toe_heights(gen.positions[c][:, list(ctx.feet)]),
                                                    ctx.sample_rate)
    speeds = np.asarray(STRIDE_SPEEDS)
    band = (speeds >= FIT_BAND[0]) & (speeds <= FIT_BAND[1])
    slopes = []
    for c in range(C):
        ok = band & np.isfinite(freq[c])
        slopes.append(metrics.linear_fit(speeds[ok], freq[c, ok])["slope"] if ok.sum() >= 2 else float("nan"))
    return {"frequency_hz_CxS": freq, "slope_C": np.asarray(slopes)}


def style_rows(per_clip: list[dict], C: int) -> dict:
    """Per style index: the mean of each STYLE_KEYS measure over its clips (from motion_metrics rows)."""
    src = {"own_step_frequency_hz": "step_frequency_hz", "own_step_height_m": "step_amplitude_m",
           "own_skate_ratio": "skate_ratio", "own_lower_foot_height_m": "lower_foot_height_m"}
    out = {}
    for c in range(C):
        rows = [r for r in per_clip if r["style"] == c]
        out[c] = {k: _mean([r[v] for r in rows]) for k, v in src.items()}
    return out


def _mean(values) -> float:
    v = np.asarray(values, np.float64)
    v = v[np.isfinite(v)]
    return float(np.mean(v)) if v.size else float("nan")
