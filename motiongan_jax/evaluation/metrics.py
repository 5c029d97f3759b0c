"""Evaluation metrics: the reference protocol's definitions, plus gait measures on toe tracks.

Pure functions of arrays: numpy/scipy, no state, no I/O. The evaluation driver produces the
inputs (evaluator logits and features, generated and real joints, curves) and forms ratios
and tables; everything here maps arrays to numbers.

Conventions (docs/CONTRACTS.md): metres, Y up, floor = X-Z plane (y = 0), frames at the data
rate `fps` (one "sample" = one frame of that rate). "Floor distance" and "horizontal" mean the
(x, z) components only. Feature vectors have no units.

Inputs are validated: a wrong rank or shape, an empty array, or a NaN/inf raises ValueError
naming the argument and the problem. Results are Python floats (or numpy arrays where stated);
`nan` is returned only where documented (no contacts in `skate_ratio`, constant inputs in
`interpolation_monotonicity`, a single value in `mean_ci95`).
"""

from __future__ import annotations

import math

import numpy as np
import scipy.linalg
import scipy.stats

from motiongan_jax.motion import arrays, representation

# Reference foot-skate threshold (docs/DESIGN.md §5.4): 0.5 CMU units per 15 Hz sample, in metres.
FOOT_SKATE_THRESHOLD_M = 0.5 * representation.CMU_UNIT_M

_FLOOR = (0, 2)  # x and z: the floor-plane components of a Y-up position


def _floor_path(p_Tx3: np.ndarray) -> np.ndarray:
    return p_Tx3[:, _FLOOR]


def _path_length(p_Tx3: np.ndarray) -> float:
    return float(np.sum(np.linalg.norm(np.diff(_floor_path(p_Tx3), axis=0), axis=-1)))


# ---------------------------------------------------------------------------------------------
# 1. Style recognition


def style_recognition(logits_NxC, labels_N) -> dict:
    """Style recognition accuracy of the evaluator's logits against the true labels.

    Returns {"top1": float, "top3": float, "confusion_CxC": int64 (C, C)} with confusion rows =
    true label and columns = top-1 prediction (row sums = per-style counts). Top-3 is top-C when
    there are fewer than 3 classes. Ties between logits go to the lower class index, in top-1
    and top-3 alike (a stable sort), so a tie never counts as two hits.
    """
    logits = arrays.float_array(logits_NxC, "logits_NxC", 2)
    labels = arrays.int_array(labels_N, "labels_N", 1)
    n, c = logits.shape
    arrays.same_len(logits, "logits_NxC", labels, "labels_N")
    if labels.min() < 0 or labels.max() >= c:
        raise ValueError(f"labels_N: values must lie in [0, {c}), got range [{labels.min()}, {labels.max()}]")
    order_NxC = np.argsort(-logits, axis=1, kind="stable")
    top1_N = order_NxC[:, 0]
    hits3_N = np.any(order_NxC[:, : min(3, c)] == labels[:, None], axis=1)
    confusion = np.bincount(labels * c + top1_N, minlength=c * c).reshape(c, c).astype(np.int64)
    return {
        "top1": float(np.mean(top1_N == labels)),
        "top3": float(np.mean(hits3_N)),
        "confusion_CxC": confusion,
    }


# ---------------------------------------------------------------------------------------------
# 2-3. Feature statistics: FMD, diversity, multimodality


def frechet_distance(feats_a_NxF, feats_b_MxF) -> float:
    """Fréchet distance between Gaussians fitted to two feature sets (units: feature units²).

    FD = ‖μa − μb‖² + tr(Σa + Σb − 2 (Σa Σb)^½), with sample covariances (ddof = 1), so each set
    needs at least 2 rows. The matrix square root is scipy.linalg.sqrtm's; its imaginary part
    (round-off on a product that is similar to a PSD matrix) is dropped, and ε·I is added to both
    covariances only if sqrtm returns non-finite values (singular covariances). A slightly
    negative result from cancellation is clipped to 0.
    """
    a = arrays.float_array(feats_a_NxF, "feats_a_NxF", 2, min_len=2)
    b = arrays.float_array(feats_b_MxF, "feats_b_MxF", 2, shape=(None, a.shape[1]), min_len=2)
    mu_a, mu_b = a.mean(axis=0), b.mean(axis=0)
    cov_a = np.atleast_2d(np.cov(a, rowvar=False))
    cov_b = np.atleast_2d(np.cov(b, rowvar=False))
    covmean = scipy.linalg.sqrtm(cov_a @ cov_b)
    if not np.all(np.isfinite(covmean)):
        eps_I = 1e-6 * np.eye(cov_a.shape[0])
        covmean = scipy.linalg.sqrtm((cov_a + eps_I) @ (cov_b + eps_I))
    covmean = np.real(covmean)
    fd = float(np.sum((mu_a - mu_b) ** 2) + np.trace(cov_a) + np.trace(cov_b) - 2.0 * np.trace(covmean))
    return max(fd, 0.0)


def diversity(feats_NxF, num_pairs: int, seed: int = 0) -> float:
    """Mean L2 distance between `num_pairs` random pairs of distinct rows (feature units).

    Pairs are drawn with replacement from np.random.default_rng(seed): i uniform over rows, j
    uniform over the other N − 1 rows, so the expectation is the mean over all ordered pairs
    i ≠ j. Needs N ≥ 2.
    """
    feats = arrays.float_array(feats_NxF, "feats_NxF", 2, min_len=2)
    num_pairs = arrays.count(num_pairs, "num_pairs", 1)
    n = feats.shape[0]
    rng = np.random.default_rng(seed)
    i = rng.integers(0, n, size=num_pairs)
    # An offset in [1, n) makes j ≠ i without rejection and keeps j uniform over the others.
    j = (i + rng.integers(1, n, size=num_pairs)) % n
    return float(np.mean(np.linalg.norm(feats[i] - feats[j], axis=-1)))


def multimodality(feats_GxKxF) -> float:
    """Mean L2 distance between all unordered pairs of the K draws within each group, averaged
    over the G groups (one group = one fixed curve and style, K noise draws z). Needs K ≥ 2.
    ≈ 0 means the generator ignores z."""
    feats = arrays.float_array(feats_GxKxF, "feats_GxKxF", 3)
    k = feats.shape[1]
    if k < 2:
        raise ValueError(f"feats_GxKxF: needs K >= 2 draws per group, got shape {feats.shape}")
    iu, ju = np.triu_indices(k, 1)
    dist_GxP = np.linalg.norm(feats[:, iu] - feats[:, ju], axis=-1)
    return float(np.mean(dist_GxP))


# ---------------------------------------------------------------------------------------------
# 4. Trajectory


def _two_paths(root_Tx3, curve_Tx3, min_len: int) -> tuple[np.ndarray, np.ndarray]:
    root = arrays.float_array(root_Tx3, "root_Tx3", 2, shape=(None, 3), min_len=min_len)
    curve = arrays.float_array(curve_Tx3, "curve_Tx3", 2, shape=(None, 3), min_len=min_len)
    arrays.same_len(root, "root_Tx3", curve, "curve_Tx3")
    return root, curve


def trajectory_error_original(root_Tx3, curve_Tx3, every: int = 8, window: int = 16) -> float:
    """The reference's trajectory error (DESIGN.md §5.4), in metres.

    For t = 0, every, 2·every, … < T: e_t = min over j in [max(0, t − window), min(T, t + window))
    of the floor distance ‖(root[t] − curve[j])_xz‖; the result is Σ e_t / ⌊T / every⌋.
    Both paths share the sample index and are already aligned (the caller shifts both to start
    at the origin). Kept exactly as the reference, quirks included: the window is asymmetric
    (t + window is excluded), and when `every` does not divide T there are ⌈T/every⌉ terms but
    the divisor is ⌊T/every⌋. Needs T ≥ every.
    """
    root, curve = _two_paths(root_Tx3, curve_Tx3, 1)
    every = arrays.count(every, "every", 1)
    window = arrays.count(window, "window", 1)
    t_len = root.shape[0]
    if t_len < every:
        raise ValueError(f"root_Tx3: T = {t_len} is shorter than every = {every} "
                         "(the divisor ⌊T/every⌋ would be 0)")
    root_xz, curve_xz = _floor_path(root), _floor_path(curve)
    errors = []
    for t in range(0, t_len, every):
        lo, hi = max(0, t - window), min(t_len, t + window)
        errors.append(np.min(np.linalg.norm(curve_xz[lo:hi] - root_xz[t], axis=-1)))
    return float(np.sum(errors) / (t_len // every))


def _resample_floor_path(path_Tx3: np.ndarray, num_points: int) -> np.ndarray:
    """`num_points` floor points (num_points, 2) = (x, z) at equal arc length along the floor
    path, first to last point, by linear interpolation along cumulative length. Unlike
    curves.resample_polyline (made for input curves, where a zero-length curve is an error), a
    path that never moves is a valid generated root here and gives its start point repeated."""
    xz = _floor_path(path_Tx3)
    seg = np.linalg.norm(np.diff(xz, axis=0), axis=-1)
    if not np.any(seg > 0):
        return np.repeat(xz[:1], num_points, axis=0)
    keep = np.concatenate([[True], seg > 0])  # np.interp wants strictly increasing lengths
    cum = np.concatenate([[0.0], np.cumsum(seg)])[keep]
    xz = xz[keep]
    targets = np.linspace(0.0, cum[-1], num_points)
    return np.stack([np.interp(targets, cum, xz[:, 0]), np.interp(targets, cum, xz[:, 1])], axis=-1)


def trajectory_error_symmetric(root_Tx3, curve_Tx3, num_points: int = 256) -> float:
    """Mean floor distance (metres) between the root path and the curve after resampling both
    at `num_points` equal arc-length points. Unlike the original error, it is symmetric in its
    arguments, independent of timing along the path, and sees the whole of both paths (the
    original misses a root that stops short or overshoots). The paths may differ in length."""
    root = arrays.float_array(root_Tx3, "root_Tx3", 2, shape=(None, 3), min_len=2)
    curve = arrays.float_array(curve_Tx3, "curve_Tx3", 2, shape=(None, 3), min_len=2)
    num_points = arrays.count(num_points, "num_points", 2)
    diff = _resample_floor_path(root, num_points) - _resample_floor_path(curve, num_points)
    return float(np.mean(np.linalg.norm(diff, axis=-1)))


def endpoint_error(root_Tx3, curve_Tx3) -> float:
    """Floor distance (metres) between the last root position and the last curve point."""
    root = arrays.float_array(root_Tx3, "root_Tx3", 2, shape=(None, 3))
    curve = arrays.float_array(curve_Tx3, "curve_Tx3", 2, shape=(None, 3))
    return float(np.linalg.norm(_floor_path(root)[-1] - _floor_path(curve)[-1]))


def path_length_ratio(root_Tx3, curve_Tx3) -> float:
    """Floor path length of the root divided by that of the curve (1 = same length).
    A curve of zero length is a ValueError (the ratio is undefined)."""
    root = arrays.float_array(root_Tx3, "root_Tx3", 2, shape=(None, 3), min_len=2)
    curve = arrays.float_array(curve_Tx3, "curve_Tx3", 2, shape=(None, 3), min_len=2)
    curve_len = _path_length(curve)
    if curve_len <= 0.0:
        raise ValueError("curve_Tx3: zero floor path length, the ratio is undefined")
    return _path_length(root) / curve_len


# ---------------------------------------------------------------------------------------------
# 5. Foot skating


def foot_skate_original(toes_world_Tx2x3, threshold_m: float = FOOT_SKATE_THRESHOLD_M) -> float:
    """The reference's foot-skate distance (DESIGN.md §5.4), in metres per sample.

    For each step t = 0..T−2, m_t = the smaller horizontal step length of the two toes (the
    slower toe is taken as the planted one); FS = Σ_t m_t·[m_t > threshold] / T (the reference
    divides by T, not T − 1). The default threshold is the reference's 0.5 CMU units ≈ 2.8 cm
    per sample; it was tuned for 15 Hz samples, so it means different speeds at other rates.
    """
    toes = arrays.float_array(toes_world_Tx2x3, "toes_world_Tx2x3", 3, shape=(None, 2, 3), min_len=2)
    threshold_m = arrays.positive(threshold_m, "threshold_m", allow_zero=True)
    steps_Tm1x2 = np.linalg.norm(np.diff(toes[..., _FLOOR], axis=0), axis=-1)
    m = steps_Tm1x2.min(axis=1)
    return float(np.sum(m * (m > threshold_m)) / toes.shape[0])


def skate_ratio(toes_world_Tx2x3, fps: float, height_threshold_m: float,
                speed_threshold_mps: float = 0.5) -> float:
    """Fraction of foot contacts that slide.

    A contact event is a (frame step t → t+1, foot k) with the foot's height y below
    `height_threshold_m` at both ends of the step; it slides if its horizontal speed
    ‖Δ(x, z)‖·fps exceeds `speed_threshold_mps`. Returns (#sliding contacts) / (#contacts),
    or nan when there are no contacts at all (0 would claim a perfect score for a motion that
    never touches the floor). Any number of feet K ≥ 1 is accepted (normally the two toes).
    """
    toes = arrays.float_array(toes_world_Tx2x3, "toes_world_Tx2x3", 3, shape=(None, None, 3), min_len=2)
    fps = arrays.positive(fps, "fps")
    height_threshold_m = float(height_threshold_m)
    if not math.isfinite(height_threshold_m):
        raise ValueError(f"height_threshold_m: must be finite, got {height_threshold_m}")
    speed_threshold_mps = arrays.positive(speed_threshold_mps, "speed_threshold_mps", allow_zero=True)
    low_TxK = toes[..., 1] < height_threshold_m
    contact_Tm1xK = low_TxK[:-1] & low_TxK[1:]
    speed_Tm1xK = np.linalg.norm(np.diff(toes[..., _FLOOR], axis=0), axis=-1) * fps
    num_contacts = int(np.sum(contact_Tm1xK))
    if num_contacts == 0:
        return float("nan")
    return float(np.sum(contact_Tm1xK & (speed_Tm1xK > speed_threshold_mps)) / num_contacts)


# ---------------------------------------------------------------------------------------------
# 6-7. Skeleton validity and smoothness


def bone_length_error(joints_TxJx3, bone_pairs_Bx2, target_lengths_B) -> float:
    """Mean over frames and bones of |length − target| / target (dimensionless; 0.1 = 10 %).
    `bone_pairs_Bx2` holds (parent, child) joint indices; targets must be positive."""
    joints = arrays.float_array(joints_TxJx3, "joints_TxJx3", 3, shape=(None, None, 3))
    pairs = arrays.int_array(bone_pairs_Bx2, "bone_pairs_Bx2", 2)
    if pairs.shape[1] != 2:
        raise ValueError(f"bone_pairs_Bx2: axis 1 must have size 2, got shape {pairs.shape}")
    num_joints = joints.shape[1]
    if pairs.min() < 0 or pairs.max() >= num_joints:
        raise ValueError(f"bone_pairs_Bx2: joint indices must lie in [0, {num_joints})")
    targets = arrays.float_array(target_lengths_B, "target_lengths_B", 1, shape=(pairs.shape[0],))
    if np.any(targets <= 0):
        raise ValueError("target_lengths_B: lengths must be > 0")
    lengths_TxB = representation.joint_bone_lengths(joints, pairs)
    return float(np.mean(np.abs(lengths_TxB - targets) / targets))


def facing_error_deg(joints_TxJx3, left: int, right: int, forward_offset_rad: float = 0.0, span: int = 4,
                     min_travel_m: float = 0.05) -> float:
    """Mean |angle| in degrees between where the body faces and where its root travels.

    Facing at frame t: the vector from joint `right` to joint `left` (e.g. the hips), turned a
    quarter turn about +y so that left = +x faces +z, plus `forward_offset_rad`. Travel: the
    root's (joint 0) floor displacement from t − span to t + span. Frames travelling less than
    `min_travel_m` are skipped; nan if none is left. Real walking scores a few degrees (the
    pelvis sways); a body walking sideways scores ~90."""
    joints = arrays.float_array(joints_TxJx3, "joints_TxJx3", 3, shape=(None, None, 3), min_len=2 * span + 1)
    across = joints[span:-span, left] - joints[span:-span, right]
    facing = np.arctan2(-across[:, 2], across[:, 0]) + forward_offset_rad
    travel = joints[2 * span:, 0] - joints[: -2 * span, 0]
    moving = np.hypot(travel[:, 0], travel[:, 2]) >= min_travel_m
    if not moving.any():
        return float("nan")
    diff = np.angle(np.exp(1j * (facing - np.arctan2(travel[:, 0], travel[:, 2]))))[moving]
    return float(np.degrees(np.mean(np.abs(diff))))


def ground_penetration(foot_heights_TxK, tolerance_m: float = 0.0) -> float:
    """Fraction of frames in which any of the K feet is below the floor by more than
    `tolerance_m` (height y < −tolerance)."""
    heights = arrays.float_array(foot_heights_TxK, "foot_heights_TxK", 2)
    tolerance_m = arrays.positive(tolerance_m, "tolerance_m", allow_zero=True)
    return float(np.mean(np.any(heights < -tolerance_m, axis=1)))


def mean_jerk(joints_TxJx3, fps: float) -> float:
    """Mean joint jerk magnitude in m/s³: ‖Δ³x‖·fps³ (the third finite difference along time
    scaled to a derivative) averaged over the T − 3 difference steps and all joints. Needs T ≥ 4.
    Normalising by real data (generated / real) is the caller's job."""
    joints = arrays.float_array(joints_TxJx3, "joints_TxJx3", 3, shape=(None, None, 3), min_len=4)
    fps = arrays.positive(fps, "fps")
    jerk_Tm3xJx3 = np.diff(joints, n=3, axis=0) * fps**3
    return float(np.mean(np.linalg.norm(jerk_Tm3xJx3, axis=-1)))


# ---------------------------------------------------------------------------------------------
# 8. Gait against speed (the measures themselves: motion.gait)


def linear_fit(x_N, y_N, groups_N=None) -> dict:
    """Least-squares line y = a + b·x: {"slope": b, "intercept": a (nan with groups), "n"}. With
    `groups_N`, one intercept per group and a common slope (the slope within groups, e.g. within
    styles: a style's own level does not tilt it). nan slope when x does not vary (within groups)."""
    x = arrays.float_array(x_N, "x_N", 1)
    y = arrays.float_array(y_N, "y_N", 1)
    arrays.same_len(x, "x_N", y, "y_N")
    if groups_N is None:
        xc, yc = x - x.mean(), y - y.mean()
    else:
        g = np.asarray(groups_N)
        if g.shape != x.shape:
            raise ValueError(f"groups_N: shape {g.shape} does not match x_N {x.shape}")
        xc, yc = x.copy(), y.copy()
        for k in np.unique(g):
            m = g == k
            xc[m] -= x[m].mean()
            yc[m] -= y[m].mean()
    sxx = float(np.sum(xc * xc))
    if sxx <= 1e-12 * max(float(np.sum(x * x)), 1e-300):
        return {"slope": float("nan"), "intercept": float("nan"), "n": int(len(x))}
    b = float(np.sum(xc * yc) / sxx)
    a = float(y.mean() - b * x.mean()) if groups_N is None else float("nan")
    return {"slope": b, "intercept": a, "n": int(len(x))}


# ---------------------------------------------------------------------------------------------
# 9-10. Style space


def interpolation_monotonicity(alphas_N, p_b_N) -> float:
    """Spearman rank correlation of the blend weight α with the evaluator's p(style B)
    (1 = p(B) rises monotonically along the interpolation). nan if either input is constant
    (the correlation is undefined)."""
    alphas = arrays.float_array(alphas_N, "alphas_N", 1, min_len=2)
    p_b = arrays.float_array(p_b_N, "p_b_N", 1, min_len=2)
    arrays.same_len(alphas, "alphas_N", p_b, "p_b_N")
    # Checked here so scipy's ConstantInputWarning never fires.
    if np.all(p_b == p_b[0]) or np.all(alphas == alphas[0]):
        return float("nan")
    return float(scipy.stats.spearmanr(alphas, p_b).statistic)


def nearest_centroid(w_NxD, centroids_CxD) -> np.ndarray:
    """Index (int64, (N,)) of the nearest centroid (Euclidean) for each code; ties go to the
    lower index."""
    w = arrays.float_array(w_NxD, "w_NxD", 2)
    centroids = arrays.float_array(centroids_CxD, "centroids_CxD", 2, shape=(None, w.shape[1]))
    dist_NxC = np.linalg.norm(w[:, None, :] - centroids[None, :, :], axis=-1)
    return np.argmin(dist_NxC, axis=1).astype(np.int64)


def nearest_centroid_accuracy(w_NxD, labels_N, centroids_CxD) -> float:
    """Fraction of codes whose nearest centroid is their label (style-space separability, and
    style-search recovery when w are recovered codes)."""
    pred = nearest_centroid(w_NxD, centroids_CxD)
    labels = arrays.int_array(labels_N, "labels_N", 1)
    if labels.shape[0] != pred.shape[0]:
        raise ValueError(f"labels_N: length {labels.shape[0]} does not match w_NxD ({pred.shape[0]})")
    return float(np.mean(pred == labels))


# ---------------------------------------------------------------------------------------------
# Reporting


def mean_ci95(values) -> tuple[float, float]:
    """(mean, half-width of the 95 % confidence interval) with Student's t:
    t.ppf(0.975, n − 1)·std(ddof=1)/√n over the finite values (NaN/inf are dropped, e.g. a
    skate ratio without contacts). One finite value gives (value, nan); none gives (nan, nan).
    An empty input is a ValueError."""
    v = np.asarray(values, dtype=np.float64).ravel()
    if v.size == 0:
        raise ValueError("values: empty")
    v = v[np.isfinite(v)]
    n = v.size
    if n == 0:
        return float("nan"), float("nan")
    mean = float(np.mean(v))
    if n == 1:
        return mean, float("nan")
    half = float(scipy.stats.t.ppf(0.975, n - 1) * np.std(v, ddof=1) / math.sqrt(n))
    return mean, half
