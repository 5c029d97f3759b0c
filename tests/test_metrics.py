"""Evaluation metrics (motiongan_jax/evaluation/metrics.py): hand-computed values, invariants, second methods."""

import math

import chex
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.stats

from motiongan_jax.analysis.style_space import pca
from motiongan_jax.evaluation import metrics as M
from motiongan_jax.motion import gait


def _line(T, step_m, direction=(1.0, 0.0)):
    """(T, 3) floor path from the origin along a floor direction (x, z), step_m per sample."""
    d = np.asarray(direction, np.float64) / np.linalg.norm(direction)
    s = np.arange(T) * step_m
    return np.stack([s * d[0], np.zeros(T), s * d[1]], axis=-1)


def _rotate_y(p_Tx3, theta):
    c, s = math.cos(theta), math.sin(theta)
    R = np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]])
    return p_Tx3 @ R.T


def _with_moments(rng, n, mean_F, cov_FxF):
    """n samples whose sample mean and sample covariance (ddof = 1) are exactly the given ones."""
    x = rng.normal(size=(n, len(mean_F)))
    x -= x.mean(0)
    x = x @ np.linalg.inv(np.linalg.cholesky(np.atleast_2d(np.cov(x, rowvar=False)))).T  # cov = I
    return x @ np.linalg.cholesky(cov_FxF).T + mean_F


# ---------------------------------------------------------------------------------------------
# Style recognition


def test_style_recognition_hand_example():
    # 4 classes, 5 samples. Rankings (best first) and labels:
    #   [3,1,0,2] label 3 -> top1 hit
    #   [0,2,1,3] label 2 -> top1 miss (pred 0), top3 hit
    #   [1,0,2,3] label 3 -> miss, miss (rank 4)
    #   [2,3,1,0] label 2 -> hit
    #   [1,2,3,0] label 0 -> miss (pred 1), miss
    logits = np.array([
        [0.2, 0.5, 0.1, 0.9],
        [3.0, 1.0, 2.0, 0.0],
        [0.5, 0.7, 0.3, 0.1],
        [-1.0, 0.0, 2.0, 1.0],
        [0.0, 5.0, 4.0, 3.0],
    ])
    labels = np.array([3, 2, 3, 2, 0])
    out = M.style_recognition(logits, labels)
    assert out["top1"] == pytest.approx(2 / 5)
    assert out["top3"] == pytest.approx(3 / 5)
    conf = out["confusion_CxC"]
    chex.assert_shape(conf, (4, 4))
    assert np.issubdtype(conf.dtype, np.integer)
    expected = np.zeros((4, 4), int)
    for true, pred in [(3, 3), (2, 0), (3, 1), (2, 2), (0, 1)]:
        expected[true, pred] += 1
    np.testing.assert_array_equal(conf, expected)
    np.testing.assert_array_equal(conf.sum(1), np.bincount(labels, minlength=4))
    assert np.trace(conf) / conf.sum() == pytest.approx(out["top1"])


def test_style_recognition_few_classes_and_ties():
    # C = 2 < 3: top-3 is top-2, always a hit.
    out = M.style_recognition(np.array([[1.0, 0.0], [1.0, 2.0], [0.0, 3.0]]), np.array([1, 0, 1]))
    assert out["top1"] == pytest.approx(1 / 3)
    assert out["top3"] == 1.0
    # A tie goes to the lower index, so an all-equal row predicts class 0, and with C = 4 the
    # top-3 set is {0, 1, 2}: label 3 misses.
    out = M.style_recognition(np.zeros((2, 4)), np.array([0, 3]))
    assert out["top1"] == 0.5 and out["top3"] == 0.5
    np.testing.assert_array_equal(out["confusion_CxC"][:, 0], [1, 0, 0, 1])


# ---------------------------------------------------------------------------------------------
# Fréchet distance, diversity, multimodality


def test_frechet_identical_sets_is_zero():
    rng = np.random.default_rng(0)
    a = rng.normal(size=(200, 8)) @ rng.normal(size=(8, 8)) + 5.0
    fd = M.frechet_distance(a, a)
    assert 0.0 <= fd <= 1e-6 * np.trace(np.cov(a, rowvar=False))


def test_frechet_diagonal_gaussians_closed_form():
    rng = np.random.default_rng(1)
    mu1, mu2 = np.array([0.0, 1.0, -2.0]), np.array([1.0, -1.0, 0.5])
    var1, var2 = np.array([1.0, 4.0, 0.25]), np.array([9.0, 1.0, 0.25])
    a = _with_moments(rng, 50, mu1, np.diag(var1))
    b = _with_moments(rng, 70, mu2, np.diag(var2))
    closed = np.sum((mu1 - mu2) ** 2) + np.sum(var1 + var2 - 2 * np.sqrt(var1 * var2))
    # = 1 + 4 + 6.25 + (1 + 9 - 6) + (4 + 1 - 4) + 0 = 16.25
    assert closed == pytest.approx(16.25)
    assert M.frechet_distance(a, b) == pytest.approx(closed, rel=1e-9)
    assert M.frechet_distance(b, a) == pytest.approx(closed, rel=1e-9)


def test_frechet_full_covariance_matches_symmetric_form():
    # Second method: tr((Σa Σb)^½) = tr((Σa^½ Σb Σa^½)^½), the latter from symmetric eigh only.
    rng = np.random.default_rng(2)
    a = rng.normal(size=(300, 5)) @ rng.normal(size=(5, 5))
    b = rng.normal(size=(250, 5)) @ rng.normal(size=(5, 5)) + 0.5
    ca, cb = np.cov(a, rowvar=False), np.cov(b, rowvar=False)

    def psd_sqrt(c):
        w, v = np.linalg.eigh(c)
        return (v * np.sqrt(np.clip(w, 0, None))) @ v.T

    ra = psd_sqrt(ca)
    expected = (np.sum((a.mean(0) - b.mean(0)) ** 2) + np.trace(ca) + np.trace(cb)
                - 2 * np.trace(psd_sqrt(ra @ cb @ ra)))
    assert M.frechet_distance(a, b) == pytest.approx(expected, rel=1e-8)
    # A pure shift leaves the covariances equal: FD = ‖δ‖².
    delta = np.array([0.3, -0.4, 1.2, 0.0, 2.0])
    assert M.frechet_distance(a, a + delta) == pytest.approx(np.sum(delta**2), rel=1e-6)
    # One feature: (μa − μb)² + (σa − σb)².
    x = _with_moments(rng, 20, np.array([1.0]), np.array([[4.0]]))
    y = _with_moments(rng, 30, np.array([-2.0]), np.array([[0.25]]))
    assert M.frechet_distance(x, y) == pytest.approx(9.0 + (2.0 - 0.5) ** 2, rel=1e-9)


def test_frechet_singular_covariance_is_finite():
    # Fewer samples than features: rank-deficient covariances still give a finite distance.
    rng = np.random.default_rng(3)
    a, b = rng.normal(size=(4, 10)), rng.normal(size=(5, 10)) + 1.0
    fd = M.frechet_distance(a, b)
    assert np.isfinite(fd) and fd >= 0.0
    assert M.frechet_distance(a, a) == pytest.approx(0.0, abs=1e-5)


def test_diversity():
    # Two points: every pair is the pair (0, 1).
    assert M.diversity(np.array([[0.0, 0.0], [3.0, 4.0]]), num_pairs=7) == pytest.approx(5.0)
    # Rows of an identity (a regular simplex): all distinct pairs are √2 apart.
    assert M.diversity(np.eye(6), num_pairs=50, seed=3) == pytest.approx(math.sqrt(2))
    # Many pairs approach the mean over all distinct pairs (scipy's pdist, a second method).
    rng = np.random.default_rng(4)
    feats = rng.normal(size=(12, 3))
    full = np.mean(scipy.spatial.distance.pdist(feats))
    assert M.diversity(feats, num_pairs=100_000, seed=1) == pytest.approx(full, rel=0.01)
    # Deterministic in the seed.
    assert M.diversity(feats, 20, seed=5) == M.diversity(feats, 20, seed=5)
    assert M.diversity(feats, 20, seed=5) != M.diversity(feats, 20, seed=6)


def test_multimodality():
    # Group 0: a 3-4-5 triangle, pair distances 3, 4, 5 (mean 4); group 1: identical draws (0).
    g0 = np.array([[0.0, 0.0], [3.0, 0.0], [0.0, 4.0]])
    g1 = np.ones((3, 2))
    assert M.multimodality(np.stack([g0, g1])) == pytest.approx(2.0)
    assert M.multimodality(np.repeat(g1[None], 4, axis=0)) == 0.0


# ---------------------------------------------------------------------------------------------
# Trajectory


def test_straight_walk_on_straight_curve_is_zero_error():
    curve = _line(64, 0.1, direction=(1.0, 2.0))
    root = curve.copy()
    root[:, 1] = 0.9 + 0.02 * np.sin(np.arange(64))  # hip height and bob are not floor error
    assert M.trajectory_error_original(root, curve) == pytest.approx(0.0, abs=1e-12)
    assert M.trajectory_error_symmetric(root, curve) == pytest.approx(0.0, abs=1e-12)
    assert M.endpoint_error(root, curve) == pytest.approx(0.0, abs=1e-12)
    assert M.path_length_ratio(root, curve) == pytest.approx(1.0)
    # Same path and end, different timing (lingering, then fast; up to 3 m behind, beyond the
    # ±16-sample window): the symmetric error ignores timing, the original does not.
    s = (np.arange(64) / 63) ** 4 * 6.3
    late = np.stack([s, np.zeros(64), np.zeros(64)], -1)
    straight = _line(64, 0.1)
    assert M.trajectory_error_symmetric(late, straight) == pytest.approx(0.0, abs=1e-12)
    assert M.trajectory_error_original(late, straight) > 0.1


def test_sideways_offset_gives_offset_error():
    curve = _line(64, 0.1)  # along +x
    root = curve + np.array([0.0, 0.0, 0.3])  # 0.3 m to the side
    assert M.trajectory_error_original(root, curve) == pytest.approx(0.3)
    assert M.trajectory_error_symmetric(root, curve) == pytest.approx(0.3)
    assert M.endpoint_error(root, curve) == pytest.approx(0.3)
    # Rotating both paths about Y changes nothing; the symmetric error is symmetric.
    r2, c2 = _rotate_y(root, 0.7), _rotate_y(curve, 0.7)
    assert M.trajectory_error_original(r2, c2) == pytest.approx(0.3)
    assert M.trajectory_error_symmetric(c2, r2) == pytest.approx(0.3)


def test_original_error_window_by_hand():
    # The root lags the curve by 20 samples on a line of 0.1 m/sample. With window 16, for
    # t = 0, 8, 16 the curve point where the root is (index 0) is within reach: e = 0. For t ≥ 24
    # the nearest reachable index is t − 16, 4 samples ahead of the root: e = 0.4 m.
    # T = 64: terms t = 0..56 (8 of them), five of 0.4 → 2.0 / 8 = 0.25.
    curve = _line(64, 0.1)
    root = curve[np.maximum(np.arange(64) - 20, 0)]
    assert M.trajectory_error_original(root, curve) == pytest.approx(0.25)
    assert M.trajectory_error_original(root, curve, window=32) == pytest.approx(0.0, abs=1e-12)
    # Every sample and window 1 (j in {t − 1, t}): t = 0 gives 0; t = 1..19 (root at the
    # origin) the nearest is curve[t − 1], 0.1 (t − 1); t = 20..63 it is 1.9 m (curve[t − 1]).
    expected = (0.1 * sum(range(19)) + 44 * 1.9) / 64
    assert M.trajectory_error_original(root, curve, every=1, window=1) == pytest.approx(expected)


def test_original_error_divisor_quirk():
    # T = 10, every 8: terms t = 0 and 8, divisor ⌊10/8⌋ = 1 (the reference's formula).
    curve = _line(10, 0.1)
    root = curve + np.array([0.0, 0.0, 0.3])
    assert M.trajectory_error_original(root, curve) == pytest.approx(0.6)


def test_symmetric_error_stationary_root_and_different_lengths():
    # A root that never moves sits at the start; the curve's equal-arc points are at
    # s = linspace(0, L): mean distance L/2.
    curve = _line(30, 0.1)  # L = 2.9
    root = np.zeros((30, 3))
    assert M.trajectory_error_symmetric(root, curve, num_points=11) == pytest.approx(1.45)
    # A root going twice as far along the same line: points at 2s vs s, mean |s| = L/2.
    assert M.trajectory_error_symmetric(2 * curve, curve, num_points=5) == pytest.approx(1.45)
    # Resampling is on arc length, not on samples: a path with standing-still frames and
    # uneven spacing along the same line has zero error.
    uneven = curve[np.array([0, 0, 0, 3, 3, 10, 11, 12, 20, 29, 29])]
    assert M.trajectory_error_symmetric(uneven, curve, num_points=64) == pytest.approx(0.0, abs=1e-12)


def test_endpoint_error_and_path_length_ratio_by_hand():
    curve = np.zeros((3, 3))
    curve[:, 0] = [0.0, 2.0, 4.0]
    curve[:, 2] = [0.0, 3.0, 6.0]  # ends at (4, 6), length 2·√13
    root = np.array([[0.0, 1.0, 0.0], [0.5, 0.9, 1.0], [1.0, 0.8, 2.0]])  # ends at (1, 2)
    assert M.endpoint_error(root, curve) == pytest.approx(5.0)  # √(3² + 4²); y ignored
    assert M.path_length_ratio(root, curve) == pytest.approx(math.sqrt(5) / (2 * math.sqrt(13)))
    # A path twice as long (scaled about the start) has ratio 2, whatever its height does.
    c = np.cumsum(np.random.default_rng(5).normal(size=(40, 3)), axis=0)
    c[:, 1] = 0.0
    r = 2.0 * c
    r[:, 1] = 1.0 + 0.1 * np.cos(np.arange(40))
    assert M.path_length_ratio(r, c) == pytest.approx(2.0)


# ---------------------------------------------------------------------------------------------
# Foot skating


def _toes(T, v_right, v_left, height=0.02):
    """(T, 2, 3) toes moving along x at v m/sample each, at a fixed height."""
    t = np.arange(T, dtype=np.float64)
    toes = np.zeros((T, 2, 3))
    toes[:, 0, 0], toes[:, 1, 0] = v_right * t, v_left * t
    toes[:, 1, 2] = 0.2  # the feet are apart sideways
    toes[:, :, 1] = height
    return toes


def test_foot_skate_original():
    T = 20
    thr = M.FOOT_SKATE_THRESHOLD_M
    assert thr == pytest.approx(0.028222)
    # Both toes sliding at v > threshold: every step counts v, divided by T.
    v = 0.05
    assert M.foot_skate_original(_toes(T, v, v)) == pytest.approx(v * (T - 1) / T)
    # Both sliding below threshold: nothing counts.
    assert M.foot_skate_original(_toes(T, 0.02, 0.02)) == 0.0
    # One planted while the other swings fast: the slower (planted) toe is 0.
    assert M.foot_skate_original(_toes(T, 0.0, 0.3)) == 0.0
    # Vertical toe motion is not skating.
    lift = _toes(T, 0.0, 0.0)
    lift[:, :, 1] = 0.1 * np.arange(T)[:, None]
    assert M.foot_skate_original(lift) == 0.0
    # Hand example, T = 4: slower-toe steps 0.05, 0.01, 0.04 -> (0.05 + 0.04) / 4.
    toes = np.zeros((4, 2, 3))
    toes[:, 0, 0] = np.cumsum([0.0, 0.05, 0.01, 0.04])
    toes[:, 1, 2] = np.cumsum([0.0, 0.06, 0.5, 0.3])
    assert M.foot_skate_original(toes) == pytest.approx(0.09 / 4)


def test_contact_height_threshold():
    heights = np.arange(11) * 0.01  # 0 .. 0.1 m: the 10th percentile is the second value
    assert gait.contact_height_threshold(heights) == pytest.approx(0.01)
    assert gait.contact_height_threshold(heights, percentile=50.0) == pytest.approx(0.05)


def test_skate_ratio():
    fps, h = 30.0, 0.05
    T = 10
    # Planted (on the floor, still): contacts, none sliding.
    assert M.skate_ratio(_toes(T, 0.0, 0.0), fps, h) == 0.0
    # Both sliding at 1 m/s (1/30 m per frame) > 0.5 m/s: every contact slides.
    assert M.skate_ratio(_toes(T, 1 / fps, 1 / fps), fps, h) == 1.0
    # One planted, one sliding: half the contacts slide.
    assert M.skate_ratio(_toes(T, 0.0, 1 / fps), fps, h) == 0.5
    # Below the speed threshold (0.4 m/s): no sliding.
    assert M.skate_ratio(_toes(T, 0.4 / fps, 0.4 / fps), fps, h) == 0.0
    # Feet in the air: no contacts at all -> nan, not a perfect 0.
    assert math.isnan(M.skate_ratio(_toes(T, 1 / fps, 0.0, height=0.5), fps, h))
    # By hand: a sliding right toe touches down at frame 6 (contact steps 6→7, 7→8, 8→9: 3 of
    # them, all sliding); the left toe is planted throughout (9 contacts, none sliding): 3 / 12.
    toes = _toes(T, 1 / fps, 0.0)
    toes[:6, 0, 1] = 0.2
    assert M.skate_ratio(toes, fps, h) == pytest.approx(3 / 12)


# ---------------------------------------------------------------------------------------------
# Gait: a walker, a glider, a floater, a hopper


def _walker(seconds=10.0, fps=30.0, cycle_hz=0.9, speed=1.2, stance=0.6, lift=0.1):
    """Toe tracks (T, 2, 3) of an ideal walk: each toe is planted (height 0, not moving) for
    `stance` of its gait cycle and swings forward in the rest, a minimum-jerk stride along the
    floor under a half-sine of height `lift` (it lifts before it speeds up); the right toe runs
    half a cycle behind the left. Both keep pace with a body at `speed`."""
    t = np.arange(int(seconds * fps)) / fps
    stride = speed / cycle_hz
    toes = np.zeros((len(t), 2, 3))
    for k, shift in enumerate((0.0, 0.5)):
        u = t * cycle_hz + shift
        cycle, frac = np.floor(u), u - np.floor(u)
        swing = np.clip((frac - stance) / (1 - stance), 0.0, 1.0)  # 0 in stance, 0 -> 1 in swing
        ahead = swing**3 * (10 - 15 * swing + 6 * swing**2)
        toes[:, k, 2] = (cycle + ahead) * stride  # forward: one stride per cycle, only in swing
        toes[:, k, 1] = lift * np.sin(np.pi * swing)
        toes[:, k, 0] = 0.1 if k == 0 else -0.1
    return toes


def test_gait_of_an_ideal_walker():
    fps = 30.0
    toes = _walker(fps=fps)
    h = gait.toe_heights(toes)
    chex.assert_shape(h, (len(toes), 2))
    assert gait.support(h, 0.02) == 1.0  # stance 0.6 > 0.5: a foot is always down
    assert gait.lower_foot_height(h) == 0.0
    assert gait.alternation(h) > 0.4
    assert gait.step_frequency_hz(h, fps) == pytest.approx(0.9, rel=0.01)
    assert M.foot_skate_original(toes[::2]) == 0.0  # planted toes do not move (15 Hz samples)
    assert M.skate_ratio(toes, fps, 0.02) == 0.0
    assert gait.height_range_m(np.stack([np.zeros(10), np.full(10, 0.9), np.zeros(10)], -1)) == 0.0


def test_gait_of_a_glider_a_floater_and_a_hopper():
    fps, T = 30.0, 300
    t = np.arange(T) / fps
    # glider: both toes slide at 1.2 m/s at a constant height (the clip's floor): always in
    # contact, so every contact slides; no steps at all
    glide = np.zeros((T, 2, 3))
    glide[:, :, 2] = 1.2 * t[:, None]
    glide[:, 1, 0] = -0.2
    h = gait.toe_heights(glide)
    assert gait.support(h, 0.02) == 1.0 and gait.lower_foot_height(h) == 0.0
    assert math.isnan(gait.alternation(h)) and math.isnan(gait.step_frequency_hz(h, fps))
    assert M.skate_ratio(glide, fps, 0.02) == 1.0
    # floater: a walker whose whole body rises 0.4 m over the clip; above the floor (the 5th
    # percentile of the lower toe, near the start) the lower toe's mean height is ~0.2 m
    float_ = _walker(seconds=T / fps, fps=fps)
    float_[..., 1] += np.linspace(0.0, 0.4, T)[:, None]
    h = gait.toe_heights(float_)
    assert gait.lower_foot_height(h) == pytest.approx(0.2 - np.percentile(np.linspace(0.0, 0.4, T), 5), abs=0.01)
    # the floor is 0.02 m up the rise (its 5th percentile): a toe within 2 cm of it only while the
    # rise is below 0.04 m, the first 10 % of the clip
    assert gait.support(h, 0.02) == pytest.approx(0.1, abs=0.01)
    # hopper: both feet together, airborne (a half-sine of 0.1 m) half of each 1 Hz cycle; sampled
    # finely so that the share of frames is the share of time
    t = np.arange(3000) / 300.0
    hop = np.zeros((len(t), 2, 3))
    frac = (t * 1.0) % 1.0
    hop[:, :, 1] = (0.1 * np.sin(np.pi * np.clip(2 * frac - 1, 0, 1)))[:, None]
    hop[:, 1, 0] = -0.2
    h = gait.toe_heights(hop)
    assert gait.alternation(h) == pytest.approx(-1.0)
    # on the floor (below 2 cm) for the grounded half plus the first and last 6.4 % of the flight
    assert gait.support(h, 0.02) == pytest.approx(0.5 + 0.5 * 2 * np.arcsin(0.2) / np.pi, abs=0.02)
    assert gait.step_amplitude_m(h) == 0.0 and math.isnan(gait.step_frequency_hz(h, 300.0))


@pytest.mark.parametrize("cycle_hz, fps, seconds", [(0.5, 15.0, 8.5), (0.93, 15.0, 8.5), (1.25, 30.0, 4.3),
                                                   (2.0, 60.0, 3.0)])
def test_step_frequency_of_sinusoidal_steps(cycle_hz, fps, seconds):
    # left - right toe height = 0.1 sin(2π f t + 0.3) plus a slow drift of both: f, to 2 %, even
    # over a few cycles (the drift is removed with the linear trend)
    t = np.arange(int(seconds * fps)) / fps
    s = 0.05 * np.sin(2 * np.pi * cycle_hz * t + 0.3)
    h = np.stack([0.05 + s, 0.05 - s], -1) + 0.02 * t[:, None]
    assert gait.step_frequency_hz(h, fps) == pytest.approx(cycle_hz, rel=0.02)
    assert gait.step_amplitude_m(h) == pytest.approx(0.1 / np.sqrt(2), rel=0.05)
    # a clip shorter than one cycle of the band's lowest frequency (0.4 Hz): unknown
    assert math.isnan(gait.step_frequency_hz(h[: int(2.4 * fps)], fps))


@pytest.mark.parametrize("cycle_hz, speed", [(0.9, 1.2), (1.1, 0.7)])
def test_stride_of_a_walk_at_known_speed_and_rate(cycle_hz, speed):
    # 10 s at 30 fps along a 40° heading, toes lifting in turn at cycle_hz: each cycle walks
    # speed / cycle_hz metres, by the spectrum and by counting alike
    fps = 30.0
    t = np.arange(300) / fps
    root = _rotate_y(_line(300, speed / fps), 0.7)
    s = np.sin(2 * np.pi * cycle_hz * t + 0.4)
    h = np.stack([0.08 * np.maximum(s, 0), 0.08 * np.maximum(-s, 0)], -1)
    assert gait.walking_speed_mps(root, fps) == pytest.approx(speed, rel=1e-9)
    assert gait.distance_per_cycle_m(root, h, fps) == pytest.approx(speed / cycle_hz, rel=0.02)
    c = gait.counted_gait_cycles(root, h, fps)
    # half-cycles between the first and last sign change of s (one at an edge may go uncounted)
    n_cross = np.sum(np.diff(np.sign(s)) != 0)
    assert c["cycles"] in ((n_cross - 1) / 2, (n_cross - 2) / 2)
    assert c["stride_m"] == pytest.approx(speed / cycle_hz, rel=0.02)
    assert c["frequency_hz"] == pytest.approx(cycle_hz, rel=0.02)
    assert c["distance_m"] == pytest.approx(c["cycles"] * speed / cycle_hz, rel=0.02)
    assert math.isnan(gait.counted_gait_cycles(root, np.zeros((300, 2)) + 0.01, fps)["stride_m"])


def test_travel_speed_takes_out_the_sway_and_keeps_the_ends():
    """A 6 s walk at 1.2 m/s along a 40° heading whose root sways sideways once per 1.1 Hz cycle
    (3 cm), surges forward twice per cycle and bobs: the raw path is longer than the distance
    walked (by about 0.8 %: a sideways speed of amplitude 0.21 m/s beside 1.2 m/s adds
    (0.21 / 1.2)² / 4 ≈ 0.77 %), a Gaussian-smoothed path padded with its end values is shorter,
    the one-cycle average is the speed to 0.5 %; under two cycles there is no speed."""
    from scipy.ndimage import gaussian_filter1d

    fps, speed, cycle_hz = 30.0, 1.2, 1.1
    t = np.arange(180) / fps
    side = 0.03 * np.sin(2 * np.pi * cycle_hz * t)
    fwd = speed * t + 0.01 * np.sin(4 * np.pi * cycle_hz * t + 0.3)
    root = _rotate_y(np.stack([side, 0.9 + 0.02 * np.cos(4 * np.pi * cycle_hz * t), fwd], -1), 0.7)
    assert gait.travel_speed_mps(root, fps, cycle_hz) == pytest.approx(speed, rel=0.005)
    assert gait.walking_speed_mps(root, fps) == pytest.approx(1.0077 * speed, rel=0.002)
    smooth = gaussian_filter1d(root, 0.5 * fps, axis=0, mode="nearest")
    assert gait.walking_speed_mps(smooth, fps) < 0.95 * speed
    assert math.isnan(gait.travel_speed_mps(root[:50], fps, cycle_hz))
    assert math.isnan(gait.travel_speed_mps(root, fps, float("nan")))


def test_linear_fit_pooled_and_within_groups():
    x = np.array([0.6, 1.0, 1.4, 0.6, 1.0, 1.4])
    y = np.array([0.7, 0.9, 1.1, 1.2, 1.4, 1.6])  # two groups, slope 0.5 each, levels 0.4 and 0.9
    g = np.array([0, 0, 0, 1, 1, 1])
    fit = M.linear_fit(x, y)
    assert fit["slope"] == pytest.approx(0.5) and fit["intercept"] == pytest.approx(0.65) and fit["n"] == 6
    assert M.linear_fit(x, y, g)["slope"] == pytest.approx(0.5)
    # the groups' levels tilt a pooled fit when their speeds differ, not the slope within them
    x2 = np.array([0.6, 0.8, 1.0, 1.2, 1.4, 1.6])
    y2 = 0.5 * x2 + np.where(g == 0, 0.9, 0.1)
    assert M.linear_fit(x2, y2)["slope"] < 0 and M.linear_fit(x2, y2, g)["slope"] == pytest.approx(0.5)
    assert math.isnan(M.linear_fit(np.ones(4), np.arange(4.0))["slope"])


# ---------------------------------------------------------------------------------------------
# Skeleton validity, smoothness


def test_bone_length_error_scaled_skeleton():
    rng = np.random.default_rng(6)
    parents = [-1, 0, 1, 2, 0, 4]
    lengths = np.array([0.1, 0.45, 0.4, 0.2, 0.3])
    pairs = np.array([(parents[j], j) for j in range(1, 6)])
    T = 7
    joints = np.zeros((T, 6, 3))
    joints[:, 0] = rng.normal(size=(T, 3))
    for b, (p, c) in enumerate(pairs):  # random bone directions, exact lengths
        d = rng.normal(size=(T, 3))
        joints[:, c] = joints[:, p] + lengths[b] * d / np.linalg.norm(d, axis=-1, keepdims=True)
    assert M.bone_length_error(joints, pairs, lengths) == pytest.approx(0.0, abs=1e-12)
    assert M.bone_length_error(1.1 * joints, pairs, lengths) == pytest.approx(0.1)
    assert M.bone_length_error(0.8 * joints, pairs, lengths) == pytest.approx(0.2)


def test_facing_error_by_hand():
    """Root (joint 0) and two hips (1 left, 2 right) 0.1 m either side of it."""
    T = 20

    def body(step_xz, left_xz):
        root = np.stack([step_xz[0] * np.arange(T), np.full(T, 0.9), step_xz[1] * np.arange(T)], -1)
        half = 0.1 * np.array([left_xz[0], 0.0, left_xz[1]])
        return np.stack([root, root + half, root - half], 1)

    # walking along +x faces +x when the left hip is at -z (left-right turned a quarter is +x)
    assert M.facing_error_deg(body((0.1, 0), (0, -1)), 1, 2) == pytest.approx(0.0, abs=1e-9)
    assert M.facing_error_deg(body((0, 0.1), (0, -1)), 1, 2) == pytest.approx(90.0)  # sideways
    assert M.facing_error_deg(body((-0.1, 0), (0, -1)), 1, 2) == pytest.approx(180.0)  # backwards
    assert M.facing_error_deg(body((-0.1, 0), (0, -1)), 1, 2, forward_offset_rad=np.pi) == pytest.approx(0.0, abs=1e-9)
    # hips twisted by 30 degrees
    t = np.radians(30)
    assert M.facing_error_deg(body((0.1, 0), (-np.sin(t), -np.cos(t))), 1, 2) == pytest.approx(30.0)
    assert np.isnan(M.facing_error_deg(body((0, 0), (0, -1)), 1, 2))  # standing still


def test_ground_penetration_counts():
    heights = np.array([
        [0.02, 0.10],
        [-0.01, 0.10],  # below
        [0.00, 0.00],  # on the floor: not below
        [-0.03, -0.02],  # below (counted once)
        [0.05, -0.001],  # below by 1 mm
    ])
    assert M.ground_penetration(heights) == pytest.approx(3 / 5)
    assert M.ground_penetration(heights, tolerance_m=0.005) == pytest.approx(2 / 5)
    assert M.ground_penetration(heights, tolerance_m=0.05) == 0.0


@pytest.mark.parametrize("fps", [15.0, 30.0, 120.0])
def test_mean_jerk_of_polynomials(fps):
    # x(t) = a t³ + b t² + c t + d with t in seconds: the third difference of a cubic is exact,
    # Δ³x = 6 a h³ with h = 1/fps, so the jerk is ‖6a‖ at every frame and for every fps.
    T = 40
    t = np.arange(T) / fps
    a = np.array([[0.5, -1.0, 2.0], [0.0, 0.0, 3.0]])  # per joint, m/s³
    b = np.array([[1.0, 2.0, 0.0], [-4.0, 0.5, 1.0]])
    c = np.array([[0.3, 0.0, 1.0], [1.0, 1.0, 1.0]])
    joints = (a * t[:, None, None] ** 3 + b * t[:, None, None] ** 2 + c * t[:, None, None] + 1.0)
    chex.assert_shape(joints, (T, 2, 3))
    expected = np.mean(np.linalg.norm(6 * a, axis=-1))  # (6·√5.25 + 18) / 2
    assert M.mean_jerk(joints, fps) == pytest.approx(expected, rel=1e-5)
    # Linear motion has no jerk.
    assert M.mean_jerk(c * t[:, None, None] + 2.0, fps) == pytest.approx(0.0, abs=1e-6)


# ---------------------------------------------------------------------------------------------
# Style space


def test_interpolation_monotonicity():
    alphas = np.linspace(0.0, 1.0, 9)
    assert M.interpolation_monotonicity(alphas, alphas**3) == pytest.approx(1.0)
    assert M.interpolation_monotonicity(alphas, 1 - np.sqrt(alphas)) == pytest.approx(-1.0)
    assert math.isnan(M.interpolation_monotonicity(alphas, np.full(9, 0.3)))
    # Second method: Pearson correlation of the ranks.
    p = np.random.default_rng(7).uniform(size=9)
    ranks_a, ranks_p = scipy.stats.rankdata(alphas), scipy.stats.rankdata(p)
    expected = np.corrcoef(ranks_a, ranks_p)[0, 1]
    assert M.interpolation_monotonicity(alphas, p) == pytest.approx(expected)


def test_nearest_centroid():
    centroids = np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 10.0]])
    w = jnp.array([[1.0, 1.0], [9.0, -2.0], [2.0, 7.0], [6.0, 6.0], [4.0, 0.0]])
    pred = M.nearest_centroid(w, centroids)
    chex.assert_shape(pred, (5,))
    assert np.issubdtype(pred.dtype, np.integer)
    # (6, 6) is √52 from centroids 1 and 2 (√72 from 0): the tie goes to the lower index.
    np.testing.assert_array_equal(pred, [0, 1, 2, 1, 0])
    labels = np.array([0, 1, 1, 1, 1])
    assert M.nearest_centroid_accuracy(w, labels, centroids) == pytest.approx(3 / 5)


def test_explained_variance():
    # Points (±a, 0), (0, ±b): centred, variances ∝ 2a² along x and 2b² along z.
    a, b = 3.0, 1.0
    X = np.array([[a, 0.0], [-a, 0.0], [0.0, b], [0.0, -b]]) + np.array([5.0, -2.0])
    ratios = np.asarray(pca(X).explained_variance_ratio_K)
    chex.assert_shape(ratios, (2,))
    np.testing.assert_allclose(ratios, [a**2 / (a**2 + b**2), b**2 / (a**2 + b**2)], rtol=1e-6)
    # Collinear data: one component explains everything; min(N, D) ratios, summing to 1.
    line = np.outer(np.arange(6.0), [1.0, 2.0, -1.0])
    ratios = np.asarray(pca(line).explained_variance_ratio_K)
    chex.assert_shape(ratios, (3,))
    np.testing.assert_allclose(ratios, [1.0, 0.0, 0.0], atol=1e-6)
    wide = np.random.default_rng(8).normal(size=(3, 5))
    ratios = np.asarray(pca(wide).explained_variance_ratio_K)
    chex.assert_shape(ratios, (3,))
    assert np.all(np.diff(ratios) <= 0) and np.sum(ratios) == pytest.approx(1.0, abs=1e-6)
    assert ratios[-1] == pytest.approx(0.0, abs=1e-6)  # 3 centred rows span 2 dimensions


# ---------------------------------------------------------------------------------------------
# Reporting


def test_mean_ci95_by_hand():
    # [1, 2, 3, 4]: mean 2.5, sample std √(5/3), t(0.975, 3) = 3.182446 (t table):
    # half-width = 3.182446 · 1.290994 / 2 = 2.054260.
    mean, half = M.mean_ci95([1.0, 2.0, 3.0, 4.0])
    assert mean == pytest.approx(2.5)
    assert half == pytest.approx(2.054260, abs=1e-6)
    # NaNs are dropped: the same numbers.
    assert M.mean_ci95(np.array([1.0, np.nan, 2.0, 3.0, 4.0])) == pytest.approx((mean, half))
    m1, h1 = M.mean_ci95([0.7])
    assert m1 == 0.7 and math.isnan(h1)
    assert all(math.isnan(x) for x in M.mean_ci95([np.nan, np.nan]))
    # Identical values: zero width.
    assert M.mean_ci95([2.0, 2.0, 2.0]) == (2.0, 0.0)


# ---------------------------------------------------------------------------------------------
# Bad inputs

_P = _line(16, 0.1)
_TOES = np.zeros((5, 2, 3))
_NAN_P = _P.copy()
_NAN_P[3, 0] = np.nan

BAD_INPUTS = [
    (lambda: M.style_recognition(np.zeros(4), np.zeros(4, int)), "logits_NxC.*rank"),
    (lambda: M.style_recognition(np.zeros((3, 4)), np.zeros(2, int)), "labels_N.*length"),
    (lambda: M.style_recognition(np.zeros((2, 4)), np.array([0, 4])), "labels_N.*\\[0, 4\\)"),
    (lambda: M.style_recognition(np.zeros((2, 4)), np.array([0.0, 1.5])), "labels_N.*integer"),
    (lambda: M.style_recognition(np.full((2, 4), np.nan), np.array([0, 1])), "logits_NxC.*NaN"),
    (lambda: M.style_recognition(np.zeros((0, 4)), np.zeros(0, int)), "logits_NxC.*empty"),
    (lambda: M.frechet_distance(np.zeros((5, 3)), np.zeros((5, 4))), "feats_b_MxF.*size 3"),
    (lambda: M.frechet_distance(np.zeros((1, 3)), np.zeros((5, 3))), "feats_a_NxF.*at least 2"),
    (lambda: M.frechet_distance(np.zeros((5, 3)), np.full((5, 3), np.inf)), "feats_b_MxF.*NaN"),
    (lambda: M.diversity(np.zeros((1, 3)), 5), "feats_NxF.*at least 2"),
    (lambda: M.diversity(np.zeros((4, 3)), 0), "num_pairs"),
    (lambda: M.multimodality(np.zeros((4, 3))), "feats_GxKxF.*rank"),
    (lambda: M.multimodality(np.zeros((4, 1, 3))), "feats_GxKxF.*K >= 2"),
    (lambda: M.trajectory_error_original(_P, _P[:10]), "curve_Tx3.*length"),
    (lambda: M.trajectory_error_original(_P[:, :2], _P), "root_Tx3.*size 3"),
    (lambda: M.trajectory_error_original(_P[:4], _P[:4]), "root_Tx3.*shorter than every"),
    (lambda: M.trajectory_error_original(_P, _P, every=0), "every"),
    (lambda: M.trajectory_error_original(_NAN_P, _P), "root_Tx3.*NaN"),
    (lambda: M.trajectory_error_symmetric(_P, _NAN_P), "curve_Tx3.*NaN"),
    (lambda: M.trajectory_error_symmetric(_P, _P, num_points=1), "num_points"),
    (lambda: M.trajectory_error_symmetric(_P[:1], _P), "root_Tx3.*at least 2"),
    (lambda: M.endpoint_error(_P[None], _P), "root_Tx3.*rank"),
    (lambda: M.endpoint_error(_P, np.zeros((0, 3))), "curve_Tx3.*empty"),
    (lambda: M.path_length_ratio(_P, np.zeros((5, 3))), "curve_Tx3.*zero floor path length"),
    (lambda: M.foot_skate_original(np.zeros((5, 3, 3))), "toes_world_Tx2x3.*size 2"),
    (lambda: M.foot_skate_original(_TOES[:1]), "toes_world_Tx2x3.*at least 2"),
    (lambda: M.foot_skate_original(_TOES, threshold_m=-1.0), "threshold_m"),
    (lambda: gait.contact_height_threshold(np.zeros((3, 2))), "foot_heights_real_N.*rank"),
    (lambda: gait.contact_height_threshold(np.zeros(3), percentile=101), "percentile"),
    (lambda: M.skate_ratio(_TOES, 0.0, 0.05), "fps"),
    (lambda: M.skate_ratio(_TOES, 30.0, np.nan), "height_threshold_m"),
    (lambda: M.skate_ratio(_TOES[..., :2], 30.0, 0.05), "toes_world_Tx2x3.*size 3"),
    (lambda: M.bone_length_error(np.zeros((2, 3, 3)), np.array([[0, 3]]), [1.0]), "bone_pairs_Bx2.*\\[0, 3\\)"),
    (lambda: M.bone_length_error(np.zeros((2, 3, 3)), np.array([[0, 1]]), [1.0, 2.0]), "target_lengths_B"),
    (lambda: M.bone_length_error(np.zeros((2, 3, 3)), np.array([[0, 1]]), [0.0]), "target_lengths_B.*> 0"),
    (lambda: M.bone_length_error(np.zeros((2, 3, 3)), np.array([0, 1]), [1.0]), "bone_pairs_Bx2.*rank"),
    (lambda: M.ground_penetration(np.zeros(5)), "foot_heights_TxK.*rank"),
    (lambda: M.ground_penetration(np.zeros((5, 2)), tolerance_m=-0.1), "tolerance_m"),
    (lambda: M.mean_jerk(np.zeros((3, 2, 3)), 30.0), "joints_TxJx3.*at least 4"),
    (lambda: M.mean_jerk(np.zeros((5, 2, 3)), -1.0), "fps"),
    (lambda: M.interpolation_monotonicity(np.zeros(3), np.zeros(4)), "p_b_N.*length"),
    (lambda: M.interpolation_monotonicity([0.0, np.nan], [1.0, 2.0]), "alphas_N.*NaN"),
    (lambda: M.nearest_centroid(np.zeros((3, 2)), np.zeros((4, 3))), "centroids_CxD.*size 2"),
    (lambda: M.nearest_centroid_accuracy(np.zeros((3, 2)), np.zeros(2, int), np.zeros((4, 2))), "labels_N.*length"),
    (lambda: M.mean_ci95([]), "values.*empty"),
    (lambda: gait.toe_heights(np.zeros((5, 2))), "toes_world_Tx2x3.*rank"),
    (lambda: gait.toe_heights(_TOES, floor_percentile=-1), "floor_percentile"),
    (lambda: gait.support(np.zeros((5, 2)), 0.0), "contact_height_m"),
    (lambda: gait.alternation(np.zeros((5, 3))), "heights_Tx2.*size 2"),
    (lambda: gait.step_frequency_hz(np.zeros((50, 2)), 0.0), "fps"),
    (lambda: gait.step_frequency_hz(np.zeros((50, 2)), 30.0, band_hz=(2.0, 1.0)), "band_hz"),
    (lambda: gait.height_range_m(np.zeros((5, 2))), "root_Tx3.*size 3"),
]


@pytest.mark.parametrize("call, match", BAD_INPUTS,
                         ids=[m.split(".")[0] + str(i) for i, (_, m) in enumerate(BAD_INPUTS)])
def test_bad_inputs_raise(call, match):
    with pytest.raises(ValueError, match=match):
        call()
