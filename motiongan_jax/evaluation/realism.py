"""Realism, like for like: window features of a walk and a classifier two-sample test (DESIGN.md §7).

A held-out path is walked by G in the held-out clip's own style at its own speed (its samples are
the clip's root path at the network's rate), and both walks are cut into the same windows. If a
simple classifier (L2-regularised logistic regression) cannot tell real windows from generated
ones when it is tested on paths it was not fitted on (group k-fold by path), G's walks are
realistic *in those features*: balanced accuracy 0.5 means indistinguishable, 1.0 means every
window gives itself away.

Features per window (`window_features`), in feature groups:
- posture: the time-mean of every joint relative to the root, in the walker's frame (x to the
  left, z forward; each frame turned to the root's direction of travel), in leg lengths;
- gait: cadence, stride, step length and width, toe lift, step height, support, planted-toe slip,
  arm swing, lean and its variation, head and hip bob, hip height, pelvis sway and yaw, knee flexion,
  alternation (lengths in leg lengths, angles in radians);
- speed: travel speed and its variation, and raw joint speeds (toes, hands).
Pure numpy/scipy functions of arrays; the protocol (protocol.py) generates and cuts the windows.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import scipy.optimize

from motiongan_jax.motion.representation import foot_joints, joint_side, rest_positions

GROUPS = ("posture", "gait", "speed")
L2 = 0.05  # ridge on standardised coefficients: ~100 features on a few hundred windows must not interpolate
FOLDS = 4
CADENCE_BAND_HZ = (0.4, 4.0)  # gait cycles per second searched by `cycle_frequency_hz`
HEADING_SPAN_S = 0.5  # each frame's direction of travel: the root's floor displacement over this span

GAIT_FEATURES = (
    "cadence_steps_per_s", "stride_leg", "step_length_leg", "step_width_leg", "toe_lift_leg", "step_height_leg",
    "lower_toe_leg", "double_support", "planted_toe_slip", "arm_swing_leg", "hand_height_leg", "hand_width_leg",
    "forward_lean_rad", "forward_lean_std_rad", "side_lean_std_rad", "head_bob_leg", "hip_height_leg",
    "hip_bob_leg", "pelvis_sway_leg", "pelvis_yaw_range_rad", "knee_flexion_range_rad", "alternation")
SPEED_FEATURES = ("speed_mps", "speed_variation", "toe_peak_speed_mps", "hand_mean_speed_mps")


class RealismError(ValueError):
    """A skeleton without the joints the gait features need, or windows too few to test."""


@dataclasses.dataclass(frozen=True)
class Body:
    """Kept-joint indices the gait features read, (left, right) pairs, and the leg length."""
    toes: tuple[int, int]
    ankles: tuple[int, int]
    knees: tuple[int, int]
    hips: tuple[int, int]
    hands: tuple[int, int]
    head: int
    leg_m: float  # thigh + shank, metres
    joint_names: tuple[str, ...]


def body(layout) -> Body:
    """The toes (representation.foot_joints) and, up their parent chain, the ankles, knees and
    hip joints; the hands and head by name; the leg length (hip to knee to ankle, mean of the two
    legs). RealismError if any is missing."""
    names = layout.joint_names
    parents = layout.parents
    toes = foot_joints(layout)
    ankles = tuple(parents[t] for t in toes)
    knees = tuple(parents[a] for a in ankles)
    hips = tuple(parents[k] for k in knees)
    if min(ankles + knees + hips) < 0 or len(set(hips)) != 2:
        raise RealismError(f"no two legs of four joints above the toes in {list(names)}")

    def named(word, side=None):
        hits = [i for i, n in enumerate(names) if word in n.lower() and "end" not in n.lower()
                and (side is None or joint_side(n) == side)]
        # the shortest such name is the joint itself (LeftHand, not LeftHandIndex1)
        return min(hits, key=lambda i: len(names[i])) if hits else None

    hands = (named("hand", "left"), named("hand", "right"))
    head = named("head")
    if None in hands or head is None:
        raise RealismError(f"cannot find both hands and the head among {list(names)}")
    # thigh + shank: distances in the rest pose, whichever way its offsets point (Bandai's lie along x)
    rest = rest_positions(layout)
    leg = float(np.mean([np.linalg.norm(rest[h] - rest[k]) + np.linalg.norm(rest[k] - rest[a])
                         for h, k, a in zip(hips, knees, ankles)]))
    if not leg > 0:
        raise RealismError("the rest pose's legs have no length")
    return Body(toes, ankles, knees, hips, hands, head, leg, tuple(names))


# ---------------------------------------------------------------------------------------------
# Gait signals


def cycle_frequency_hz(signal_NxT, fps: float, band_hz: tuple[float, float] = CADENCE_BAND_HZ,
                       grid: int = 400) -> np.ndarray:
    """Dominant frequency (Hz, N) of each row: the sinusoid (with an offset and a linear trend)
    that explains most of its variance, searched on `grid` frequencies in `band_hz` and refined by
    a parabola. A least-squares fit, not an FFT peak: a 2-second window holds two gait cycles,
    too few for a spectrum's resolution. nan for a constant row."""
    x = np.asarray(signal_NxT, np.float64)
    n, t_len = x.shape
    t = np.arange(t_len) / fps
    freqs = np.linspace(band_hz[0], band_hz[1], grid)
    base = np.stack([np.ones(t_len), t - t.mean()], -1)  # T x 2
    resid = x - x @ (base @ np.linalg.pinv(base)).T  # offset and trend removed: N x T
    power = np.empty((n, grid))
    for i, f in enumerate(freqs):
        design = np.concatenate([base, np.stack([np.sin(2 * np.pi * f * t), np.cos(2 * np.pi * f * t)], -1)], -1)
        fitted = resid @ (design @ np.linalg.pinv(design)).T
        power[:, i] = np.sum(fitted * fitted, axis=1)
    k = np.clip(np.argmax(power, axis=1), 1, grid - 2)
    a, b, c = (power[np.arange(n), k + d] for d in (-1, 0, 1))
    denom = a - 2 * b + c
    shift = np.where(denom < 0, 0.5 * (a - c) / np.where(denom < 0, denom, 1.0), 0.0)
    out = freqs[k] + np.clip(shift, -1, 1) * (freqs[1] - freqs[0])
    return np.where(np.ptp(resid, axis=1) > 1e-9, out, np.nan)


def walker_frame(joints_NxTxJx3, fps: float, span_s: float = HEADING_SPAN_S) -> tuple[np.ndarray, np.ndarray]:
    """(joints relative to the root turned so that each frame's direction of travel is +z (left
    at +x), N x T x J x 3; the heading per frame, N x T radians). The direction is the root's floor
    displacement from t − s to t + s (clamped at the window's ends), s = span_s / 2 in frames."""
    j = np.asarray(joints_NxTxJx3, np.float64)
    N, T = j.shape[:2]
    s = max(int(round(span_s * fps / 2)), 1)
    idx = np.arange(T)
    lo, hi = np.clip(idx - s, 0, T - 1), np.clip(idx + s, 0, T - 1)
    d = j[:, hi, 0] - j[:, lo, 0]
    theta = np.arctan2(d[..., 0], d[..., 2])  # N x T, 0 = +z
    rel = j - j[:, :, :1]
    c, sn = np.cos(-theta)[..., None], np.sin(-theta)[..., None]
    x, z = rel[..., 0], rel[..., 2]
    out = np.stack([c * x + sn * z, rel[..., 1], -sn * x + c * z], -1)
    return out, theta


def _floor_speed(p_NxTx3, fps):
    return np.linalg.norm(np.diff(p_NxTx3[..., [0, 2]], axis=1), axis=-1) * fps  # N x (T-1)


def _angle_range(a_NxT):
    a = np.unwrap(a_NxT, axis=1)
    return np.percentile(a, 95, axis=1) - np.percentile(a, 5, axis=1)


def window_features(joints_NxTxJx3, b: Body, fps: float, contact_height_m: float) -> tuple[np.ndarray, list[str],
                                                                                           list[str]]:
    """(features N x F, names F, group of each F) of N windows of world joints (metres, y up,
    T samples at `fps`). Heights are above each window's floor (the 5th percentile of its lower
    toe, as gait.toe_heights per clip). nan where a feature is undefined (no contact: slip)."""
    j = np.asarray(joints_NxTxJx3, np.float64)
    if j.ndim != 4 or j.shape[-1] != 3 or j.shape[1] < 8:
        raise RealismError(f"windows must be N x T x J x 3 with T >= 8, got {j.shape}")
    N, T, J, _ = j.shape
    leg = b.leg_m
    rel, theta = walker_frame(j, fps)
    L, R = 0, 1
    toes_y = j[:, :, list(b.toes), 1]
    floor = np.percentile(toes_y.min(-1), 5, axis=1)[:, None, None]
    toe_h = toes_y - floor  # N x T x 2
    root = j[:, :, 0]
    dur = (T - 1) / fps
    path = np.sum(np.linalg.norm(np.diff(root[..., [0, 2]], axis=1), axis=-1), axis=1)
    speed = path / dur
    root_speed = _floor_speed(root, fps)

    diff_h = toe_h[..., L] - toe_h[..., R]
    f_cycle = cycle_frequency_hz(diff_h, fps)
    ank = rel[:, :, list(b.ankles)]
    hand = rel[:, :, list(b.hands)]
    fwd_sep = ank[..., L, 2] - ank[..., R, 2]
    contact = toe_h < contact_height_m
    toe_speed = np.stack([_floor_speed(j[:, :, t], fps) for t in b.toes], -1)  # N x T-1 x 2
    planted = contact[:, 1:] & contact[:, :-1]
    slip = np.where(planted.any((1, 2)), np.sum(toe_speed * planted, (1, 2)) / np.maximum(planted.sum((1, 2)), 1),
                    np.nan) / np.maximum(speed, 1e-6)
    head = rel[:, :, b.head]
    lean_fwd = np.arctan2(head[..., 2], head[..., 1])
    lean_side = np.arctan2(head[..., 0], head[..., 1])
    hip_l, hip_r = j[:, :, b.hips[L]], j[:, :, b.hips[R]]
    across = hip_l - hip_r
    pelvis_yaw = np.arctan2(-across[..., 2], across[..., 0]) - theta  # facing minus travel
    pelvis_yaw = np.angle(np.exp(1j * pelvis_yaw))

    def knee_flexion(side):
        u = j[:, :, b.hips[side]] - j[:, :, b.knees[side]]
        v = j[:, :, b.ankles[side]] - j[:, :, b.knees[side]]
        cos = np.sum(u * v, -1) / np.maximum(np.linalg.norm(u, axis=-1) * np.linalg.norm(v, axis=-1), 1e-9)
        return np.pi - np.arccos(np.clip(cos, -1, 1))

    # chord of the root on the floor: the pelvis's lateral sway is its offset from it
    chord = root[:, -1, [0, 2]] - root[:, 0, [0, 2]]
    chord = chord / np.maximum(np.linalg.norm(chord, axis=-1, keepdims=True), 1e-9)
    off = root[..., [0, 2]] - root[:, :1, [0, 2]]
    lateral = off[..., 0] * chord[:, None, 1] - off[..., 1] * chord[:, None, 0]
    hl, hr = toe_h[..., L], toe_h[..., R]
    alt = -np.sum((hl - hl.mean(1, keepdims=True)) * (hr - hr.mean(1, keepdims=True)), 1) / np.maximum(
        np.sqrt(np.sum((hl - hl.mean(1, keepdims=True)) ** 2, 1) * np.sum((hr - hr.mean(1, keepdims=True)) ** 2, 1)),
        1e-12)
    gait = {
        "cadence_steps_per_s": 2 * f_cycle,
        "stride_leg": speed / f_cycle / leg,
        "step_length_leg": (np.percentile(fwd_sep, 95, 1) - np.percentile(fwd_sep, 5, 1)) / 2 / leg,
        "step_width_leg": np.mean(np.abs(ank[..., L, 0] - ank[..., R, 0]), 1) / leg,
        "toe_lift_leg": np.mean(np.percentile(toe_h, 95, axis=1), -1) / leg,
        "step_height_leg": np.std(diff_h, 1) / leg,
        "lower_toe_leg": np.mean(toe_h.min(-1), 1) / leg,
        "double_support": np.mean(contact.all(-1), 1),
        "planted_toe_slip": slip,
        "arm_swing_leg": np.ptp(hand[..., L, 2] - hand[..., R, 2], 1) / 2 / leg,
        "hand_height_leg": np.mean(hand[..., 1], (1, 2)) / leg,
        "hand_width_leg": np.mean(hand[..., L, 0] - hand[..., R, 0], 1) / leg,
        "forward_lean_rad": np.mean(lean_fwd, 1),
        "forward_lean_std_rad": np.std(lean_fwd, 1),
        "side_lean_std_rad": np.std(lean_side, 1),
        "head_bob_leg": np.std(j[:, :, b.head, 1], 1) / leg,
        "hip_height_leg": np.mean(root[..., 1] - floor[:, :, 0], 1) / leg,
        "hip_bob_leg": np.std(root[..., 1], 1) / leg,
        "pelvis_sway_leg": np.std(lateral, 1) / leg,
        "pelvis_yaw_range_rad": _angle_range(pelvis_yaw),
        "knee_flexion_range_rad": np.mean([np.ptp(knee_flexion(s), 1) for s in (L, R)], 0),
        "alternation": alt,
    }
    hand_speed = np.stack([_floor_speed(j[:, :, h], fps) for h in b.hands], -1)
    spd = {
        "speed_mps": speed,
        "speed_variation": np.std(root_speed, 1) / np.maximum(np.mean(root_speed, 1), 1e-6),
        "toe_peak_speed_mps": np.mean(np.percentile(toe_speed, 95, axis=1), -1),
        "hand_mean_speed_mps": np.mean(hand_speed, (1, 2)),
    }
    assert tuple(gait) == GAIT_FEATURES and tuple(spd) == SPEED_FEATURES
    posture = rel[:, :, 1:].mean(1).reshape(N, -1) / leg
    pnames = [f"{n}.{a}" for n in b.joint_names[1:] for a in "xyz"]
    X = np.concatenate([posture, np.stack(list(gait.values()), -1), np.stack(list(spd.values()), -1)], -1)
    names = pnames + list(GAIT_FEATURES) + list(SPEED_FEATURES)
    groups = ["posture"] * len(pnames) + ["gait"] * len(GAIT_FEATURES) + ["speed"] * len(SPEED_FEATURES)
    return X, names, groups


# ---------------------------------------------------------------------------------------------
# The classifier two-sample test


def group_folds(groups_N, k: int, rng: np.random.Generator) -> np.ndarray:
    """Fold index (N,) of every sample: whole groups dealt to min(k, #groups) folds in a random
    order (`rng`), so no group is ever in two folds."""
    g = np.asarray(groups_N)
    uniq = np.unique(g)
    k = min(int(k), len(uniq))
    if k < 2:
        raise RealismError(f"need at least two groups (paths) for a cross-validated test, got {len(uniq)}")
    fold_of = dict(zip(uniq[rng.permutation(len(uniq))].tolist(), (np.arange(len(uniq)) % k).tolist()))
    return np.array([fold_of[x] for x in g.tolist()], np.int64)


def fit_logistic(X_NxF, y_N, weight_N, l2: float = L2) -> tuple[np.ndarray, float]:
    """(β F, bias) minimising the weighted mean log-loss + l2/2 ‖β‖² (bias not penalised), by
    L-BFGS from zero: a convex problem, so one deterministic answer."""
    X = np.asarray(X_NxF, np.float64)
    y = np.asarray(y_N, np.float64)
    w = np.asarray(weight_N, np.float64) / np.sum(weight_N)

    def f(theta):
        beta, bias = theta[:-1], theta[-1]
        z = X @ beta + bias
        loss = np.sum(w * (np.logaddexp(0.0, z) - y * z)) + 0.5 * l2 * beta @ beta
        r = w * (1.0 / (1.0 + np.exp(-z)) - y)
        return loss, np.concatenate([X.T @ r + l2 * beta, [np.sum(r)]])

    res = scipy.optimize.minimize(f, np.zeros(X.shape[1] + 1), jac=True, method="L-BFGS-B",
                                  options={"maxiter": 500, "gtol": 1e-8})
    return res.x[:-1], float(res.x[-1])


def _impute(X):
    """nan columns entries -> the column's median over all rows (label-blind), 0 if all nan."""
    X = np.array(X, np.float64)
    bad = ~np.isfinite(X)
    if bad.any():
        med = np.nanmedian(np.where(bad, np.nan, X), axis=0) if (~bad).any() else np.zeros(X.shape[1])
        X[bad] = np.take(np.nan_to_num(med), np.nonzero(bad)[1])
    return X


def two_sample_test(X_real_NxF, X_gen_MxF, groups_real_N, groups_gen_M, rng: np.random.Generator,
                    k: int = FOLDS, l2: float = L2) -> dict:
    """Classifier two-sample test, real (label 0) against generated (label 1), cross-validated
    by group (path): each fold's model is fitted on the other folds' paths, with features
    standardised on them and each class weighted to half the total. Returns {"accuracy":
    balanced out-of-fold accuracy (mean of the real and generated hit rates; 0.5 =
    indistinguishable), "folds", "coef_std": the folds' mean coefficient per standardised
    feature (F; + = more generated), "n_real", "n_gen", "paths"}. Non-finite entries take their
    column's median."""
    Xr = np.asarray(X_real_NxF, np.float64)
    Xg = np.asarray(X_gen_MxF, np.float64)
    if Xr.ndim != 2 or Xg.ndim != 2 or Xr.shape[1] != Xg.shape[1]:
        raise RealismError(f"feature matrices must be N x F and M x F, got {Xr.shape} and {Xg.shape}")
    if len(Xr) < 2 or len(Xg) < 2:
        raise RealismError(f"need at least two windows of each kind, got {len(Xr)} real and {len(Xg)} generated")
    X = _impute(np.concatenate([Xr, Xg]))
    y = np.concatenate([np.zeros(len(Xr)), np.ones(len(Xg))])
    groups = np.concatenate([np.asarray(groups_real_N), np.asarray(groups_gen_M)])
    fold = group_folds(groups, k, rng)
    pred = np.full(len(y), np.nan)
    coefs = []
    for f in range(fold.max() + 1):
        tr, te = fold != f, fold == f
        if len(np.unique(y[tr])) < 2:
            continue  # a fold whose training paths hold one kind only cannot be fitted
        mu, sd = X[tr].mean(0), X[tr].std(0)
        sd = np.where(sd > 1e-12, sd, 1.0)
        Z = (X - mu) / sd
        n1 = y[tr].sum()
        w = np.where(y[tr] == 1, 0.5 / n1, 0.5 / (tr.sum() - n1))
        beta, bias = fit_logistic(Z[tr], y[tr], w, l2)
        pred[te] = (Z[te] @ beta + bias > 0).astype(np.float64)
        coefs.append(beta)
    ok = np.isfinite(pred)
    hits_real = pred[ok & (y == 0)] == 0
    hits_gen = pred[ok & (y == 1)] == 1
    acc = 0.5 * (np.mean(hits_real) + np.mean(hits_gen)) if hits_real.size and hits_gen.size else float("nan")
    return {"accuracy": float(acc), "folds": int(fold.max() + 1),
            "coef_std": np.mean(coefs, 0) if coefs else np.full(X.shape[1], np.nan),
            "n_real": int(len(Xr)), "n_gen": int(len(Xg)), "paths": int(len(np.unique(groups)))}


def feature_shifts(X_real_NxF, X_gen_MxF, names) -> list[dict]:
    """Per feature: real and generated means and the difference in units of the real data's
    standard deviation ("d"), sorted by |d|, largest first (finite values only)."""
    out = []
    for i, name in enumerate(names):
        r = np.asarray(X_real_NxF, np.float64)[:, i]
        g = np.asarray(X_gen_MxF, np.float64)[:, i]
        r, g = r[np.isfinite(r)], g[np.isfinite(g)]
        if len(r) < 2 or len(g) < 1:
            continue
        sd = np.std(r, ddof=1)
        d = (np.mean(g) - np.mean(r)) / sd if sd > 0 else (0.0 if np.mean(g) == np.mean(r) else np.inf)
        out.append({"feature": name, "real": float(np.mean(r)), "generated": float(np.mean(g)), "d": float(d)})
    return sorted(out, key=lambda e: -abs(e["d"]))


def realism_tests(X_real, X_gen, names, groups_of_feature, paths_real, paths_gen, rng: np.random.Generator,
                  extra: dict | None = None, top: int = 6) -> dict:
    """The two-sample test on each feature group, on all of them, and on each `extra` group
    ({name: (X_real, X_gen)}, e.g. the evaluator's features); the `top` features that separate
    most (largest |d|, with each one's own single-feature test accuracy) and the largest
    standardised coefficients of the all-features model. Fold assignment is drawn once from `rng`
    and shared by every test (one path, one fold)."""
    seed = int(rng.integers(2**31))
    kinds = np.asarray(groups_of_feature)
    sets = {g: kinds == g for g in GROUPS}
    sets["all"] = np.ones(len(names), bool)

    def test(xr, xg):
        return two_sample_test(xr, xg, paths_real, paths_gen, np.random.default_rng(seed))

    out = {}
    for g, m in sets.items():
        res = test(X_real[:, m], X_gen[:, m])
        res["features"] = int(m.sum())
        if g == "all":
            order = np.argsort(-np.abs(res["coef_std"]))[:top]
            res["top_coefficients"] = [{"feature": names[i], "coef": float(res["coef_std"][i])}
                                       for i in order if np.isfinite(res["coef_std"][i])]
        res.pop("coef_std")
        out[g] = res
    for g, (xr, xg) in (extra or {}).items():
        res = test(xr, xg)
        res["features"] = int(np.asarray(xr).shape[1])
        res.pop("coef_std")
        out[g] = res
    shifts = feature_shifts(X_real, X_gen, names)
    for e in shifts[:top]:
        i = names.index(e["feature"])
        e["accuracy"] = test(X_real[:, [i]], X_gen[:, [i]])["accuracy"]
    return {"tests": out, "top_features": shifts[:top],
            "gait_features": {e["feature"]: e for e in shifts if e["feature"] in GAIT_FEATURES + SPEED_FEATURES}}


def numpy_rng(key) -> np.random.Generator:
    """A numpy Generator seeded from a jax key's bits (one key, one generator)."""
    import jax

    return np.random.default_rng(np.asarray(jax.random.key_data(key)).ravel().tolist())


def split_halves(paths_N, styles_N) -> np.ndarray:
    """Which half (0/1) each real window goes to for the real-against-real reference: whole paths,
    sorted by (style, path) and dealt in turn, so a style with several paths is in both halves."""
    paths = np.asarray(paths_N)
    styles = np.asarray(styles_N)
    order = sorted({(s, p) for s, p in zip(styles.tolist(), paths.tolist())})
    half = {p: i % 2 for i, (_, p) in enumerate(order)}
    return np.array([half[p] for p in paths.tolist()], np.int64)
