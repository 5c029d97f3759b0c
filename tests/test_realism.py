"""The realism measures (evaluation/realism.py): window gait features on a synthetic walk whose
cadence, speed, stride, step width and hip height are known by construction; the classifier
two-sample test on samples whose separability is known (identical -> 0.5, far apart -> 1.0)."""

import chex
import jax
import numpy as np
import pytest

from motiongan_jax.data import synthetic
from motiongan_jax.evaluation import realism
from motiongan_jax.motion import representation


@pytest.fixture(scope="module")
def cmu_layout():
    return representation.layout_from_skeleton(synthetic.cmu_skeleton(), synthetic.UNITS_TO_M)


def _sine_walk(layout, b, *, T=32, fps=15.0, f=0.9, v=1.2, lift=0.08, reach=0.2, heading=0.0, start=(0.0, 0.0)):
    """World joints T x J x 3: the rest pose carried along `heading` at v m/s; each toe and ankle
    lifts by lift·max(0, ±sin 2πft) and swings forward/back by ±reach·sin 2πft (left, right)."""
    rest = representation.rest_positions(layout)
    t = np.arange(T) / fps
    s = np.sin(2 * np.pi * f * t)
    j = np.repeat(rest[None], T, 0).astype(np.float64)
    j[:, :, 1] += 1.0  # the root 1 m up: the rest pose's toes are at -0.97
    for side, sign in ((0, 1.0), (1, -1.0)):
        for joint in (b.toes[side], b.ankles[side]):
            j[:, joint, 1] += lift * np.maximum(0.0, sign * s)
            j[:, joint, 2] += sign * reach * s
    j[:, :, 2] += (v * t)[:, None]
    c, sn = np.cos(heading), np.sin(heading)
    x, z = j[..., 0].copy(), j[..., 2].copy()
    j[..., 0], j[..., 2] = c * x + sn * z + start[0], -sn * x + c * z + start[1]
    return j


def test_body_joints_of_both_skeletons(cmu_layout):
    b = realism.body(cmu_layout)
    names = cmu_layout.joint_names
    assert [names[i] for i in b.toes + b.ankles + b.knees + b.hips] == [
        "LeftToeBase", "RightToeBase", "LeftFoot", "RightFoot", "LeftLeg", "RightLeg", "LeftUpLeg", "RightUpLeg"]
    assert [names[i] for i in b.hands] == ["LeftHand", "RightHand"] and names[b.head] == "Head"
    rest = representation.rest_positions(cmu_layout)
    thigh = np.linalg.norm(rest[b.hips[0]] - rest[b.knees[0]])
    shank = np.linalg.norm(rest[b.knees[0]] - rest[b.ankles[0]])
    assert b.leg_m == pytest.approx(thigh + shank) and 0.7 < b.leg_m < 1.0
    bandai = representation.layout_from_parents(
        ("Hips", "UpperLeg_L", "LowerLeg_L", "Foot_L", "Toes_L", "UpperLeg_R", "LowerLeg_R", "Foot_R", "Toes_R",
         "Spine", "Head", "Hand_L", "Hand_R"), (-1, 0, 1, 2, 3, 0, 5, 6, 7, 0, 9, 9, 9), np.ones(12) * 0.3,
        np.array([[0, 0, 0], [0.1, -0.1, 0], [0, -0.4, 0], [0, -0.4, 0], [0, -0.05, 0.1], [-0.1, -0.1, 0],
                  [0, -0.4, 0], [0, -0.4, 0], [0, -0.05, 0.1], [0, 0.3, 0], [0, 0.3, 0], [0.3, 0, 0], [-0.3, 0, 0]]))
    bb = realism.body(bandai)
    assert (bb.toes, bb.ankles, bb.knees, bb.hips, bb.hands, bb.head) == ((4, 8), (3, 7), (2, 6), (1, 5), (11, 12), 10)
    assert bb.leg_m == pytest.approx(0.8)
    # Bandai's BVH offsets lie along x, not y: the leg length does not depend on the rest pose's direction
    turned = bandai.__class__(**{**bandai.__dict__, "rest_offsets_m": tuple(
        (-y, x, z) for x, y, z in np.asarray(bandai.rest_offsets_m).tolist())})
    assert realism.body(turned).leg_m == pytest.approx(0.8)


def test_cycle_frequency_of_short_sines():
    """Two seconds at 15 Hz hold ~2 cycles: the least-squares fit still finds each frequency,
    whatever its offset, trend and phase."""
    fps, T = 15.0, 32
    t = np.arange(T) / fps
    freqs = np.array([0.5, 0.8, 0.96, 1.13, 1.6, 2.5])
    x = 0.05 * np.sin(2 * np.pi * freqs[:, None] * t + np.arange(6)[:, None]) + 0.3 + 0.02 * t
    est = realism.cycle_frequency_hz(x, fps)
    chex.assert_shape(est, (6,))
    np.testing.assert_allclose(est, freqs, rtol=0.01)
    assert np.isnan(realism.cycle_frequency_hz(np.ones((1, T)), fps)[0])


def test_window_features_of_a_known_walk(cmu_layout):
    b = realism.body(cmu_layout)
    fps, f, v, reach = 15.0, 0.9, 1.2, 0.2
    walks = np.stack([_sine_walk(cmu_layout, b, f=f, v=v, reach=reach),
                      _sine_walk(cmu_layout, b, f=f, v=v, reach=reach, heading=2.1, start=(3.0, -1.0))])
    X, names, groups = realism.window_features(walks, b, fps, contact_height_m=0.02)
    J = cmu_layout.num_joints
    chex.assert_shape(X, (2, (J - 1) * 3 + len(realism.GAIT_FEATURES) + len(realism.SPEED_FEATURES)))
    assert len(names) == len(groups) == X.shape[1] and set(groups) == set(realism.GROUPS)
    np.testing.assert_allclose(X[1], X[0], atol=1e-6)  # another heading and place: the same walk
    g = dict(zip(names, X[0]))
    leg = b.leg_m
    rest = representation.rest_positions(cmu_layout)
    assert g["cadence_steps_per_s"] == pytest.approx(2 * f, rel=0.01)
    assert g["speed_mps"] == pytest.approx(v, rel=1e-6)
    assert g["stride_leg"] == pytest.approx(v / f / leg, rel=0.01)
    # the feet's forward separation is 2·reach·sin: its 5th-95th percentile half-range
    sep = 2 * reach * np.sin(2 * np.pi * f * np.arange(32) / fps)
    assert g["step_length_leg"] == pytest.approx((np.percentile(sep, 95) - np.percentile(sep, 5)) / 2 / leg)
    assert g["step_width_leg"] == pytest.approx(abs(rest[b.ankles[0], 0] - rest[b.ankles[1], 0]) / leg)
    assert g["hip_height_leg"] == pytest.approx(-rest[b.toes[0], 1] / leg, rel=1e-6)
    assert g["step_height_leg"] == pytest.approx(np.std(0.08 * np.sin(2 * np.pi * f * np.arange(32) / fps)) / leg)
    assert g["alternation"] > 0.4 and g["lower_toe_leg"] == pytest.approx(0.0, abs=1e-9)
    assert g["hip_bob_leg"] == pytest.approx(0.0, abs=1e-12) and g["forward_lean_std_rad"] == pytest.approx(0, abs=1e-9)
    # toes that never swing forward are carried along with the body: they slide at its speed
    still = realism.window_features(_sine_walk(cmu_layout, b, f=f, v=v, reach=0.0)[None], b, fps, 0.02)[0][0]
    assert dict(zip(names, still))["planted_toe_slip"] == pytest.approx(1.0, rel=1e-6)


def test_group_folds_keep_paths_whole():
    groups = np.repeat(np.arange(10), 7)
    fold = realism.group_folds(groups, 4, realism.numpy_rng(jax.random.key(0)))
    chex.assert_shape(fold, (70,))
    for g in range(10):
        assert len(set(fold[groups == g])) == 1
    assert sorted(np.unique(fold)) == [0, 1, 2, 3]
    # the same key, the same folds (a generator seeded from it, drawn afresh)
    np.testing.assert_array_equal(fold, realism.group_folds(groups, 4, realism.numpy_rng(jax.random.key(0))))
    with pytest.raises(realism.RealismError, match="two groups"):
        realism.group_folds(np.zeros(5), 4, realism.numpy_rng(jax.random.key(1)))


def _samples(key, n_paths=16, per_path=12, F=8, shift=0.0):
    """Real and generated windows: per path a common offset (paths differ), plus noise; the
    generated ones are moved by `shift` standard deviations along feature 2."""
    k_off, k_r, k_g = jax.random.split(key, 3)
    off = 0.5 * np.asarray(jax.random.normal(k_off, (n_paths, 1, F)))
    real = off + np.asarray(jax.random.normal(k_r, (n_paths, per_path, F)))
    gen = off + np.asarray(jax.random.normal(k_g, (n_paths, per_path * 2, F)))
    gen[..., 2] += shift
    paths_r = np.repeat(np.arange(n_paths), per_path)
    paths_g = np.repeat(np.arange(n_paths), per_path * 2)
    return real.reshape(-1, F), gen.reshape(-1, F), paths_r, paths_g


def test_two_sample_test_identical_and_separated():
    accs = []
    for i in range(3):
        xr, xg, pr, pg = _samples(jax.random.key(i))
        res = realism.two_sample_test(xr, xg, pr, pg, realism.numpy_rng(jax.random.key(100 + i)))
        assert res["folds"] == 4 and res["paths"] == 16 and res["n_real"] == 192 and res["n_gen"] == 384
        accs.append(res["accuracy"])
    assert abs(np.mean(accs) - 0.5) < 0.07 and max(abs(a - 0.5) for a in accs) < 0.12
    xr, xg, pr, pg = _samples(jax.random.key(5), shift=6.0)
    res = realism.two_sample_test(xr, xg, pr, pg, realism.numpy_rng(jax.random.key(105)))
    assert res["accuracy"] > 0.97
    chex.assert_shape(res["coef_std"], (8,))
    assert int(np.argmax(np.abs(res["coef_std"]))) == 2 and res["coef_std"][2] > 0
    # the single-feature shifts find the moved feature, in real standard deviations
    shifts = realism.feature_shifts(xr, xg, [f"f{i}" for i in range(8)])
    assert shifts[0]["feature"] == "f2" and shifts[0]["d"] == pytest.approx(6.0 / np.std(xr[:, 2], ddof=1), rel=0.15)


def test_realism_tests_by_group_and_real_halves():
    xr, xg, pr, pg = _samples(jax.random.key(7), F=6, shift=6.0)
    names = ["a.x", "a.y", "cadence_steps_per_s", "stride_leg", "speed_mps", "speed_variation"]
    kinds = ["posture", "posture", "gait", "gait", "speed", "speed"]
    out = realism.realism_tests(xr, xg, names, kinds, pr, pg, realism.numpy_rng(jax.random.key(0)),
                                extra={"evaluator": (xr[:, :2], xg[:, :2])}, top=3)
    t = out["tests"]
    assert set(t) == {"posture", "gait", "speed", "all", "evaluator"}
    assert t["gait"]["accuracy"] > 0.95 and t["all"]["accuracy"] > 0.95  # feature 2 is a gait feature
    assert t["posture"]["accuracy"] < 0.65 and t["speed"]["accuracy"] < 0.65 and t["evaluator"]["accuracy"] < 0.65
    assert out["top_features"][0]["feature"] == "cadence_steps_per_s" and out["top_features"][0]["accuracy"] > 0.95
    assert t["all"]["top_coefficients"][0]["feature"] == "cadence_steps_per_s"
    assert set(out["gait_features"]) == {"cadence_steps_per_s", "stride_leg", "speed_mps", "speed_variation"}
    # the real reference: whole paths dealt to two halves, every style with two paths in both
    paths = np.array([3, 3, 1, 1, 2, 5, 5, 4])
    styles = np.array([0, 0, 0, 0, 1, 1, 1, 1])
    half = realism.split_halves(paths, styles)
    assert list(half) == [1, 1, 0, 0, 0, 0, 0, 1]


def test_real_reference_keeps_styles_with_two_paths():
    """The real-against-real reference: real windows of one distribution, split by path, test at
    chance; a style held by one path only is left out (it would sit in one half)."""
    from motiongan_jax.evaluation import own_paths

    k_x, k_e = jax.random.split(jax.random.key(11))
    paths = np.repeat(np.arange(17), 10)
    labels = np.where(paths < 8, 0, np.where(paths < 16, 1, 2))  # styles 0 and 1: 8 paths each; style 2: one
    X = np.asarray(jax.random.normal(k_x, (170, 5)))
    E = np.asarray(jax.random.normal(k_e, (170, 3)))
    names = ["a.x", "a.y", "cadence_steps_per_s", "stride_leg", "speed_mps"]
    kinds = ["posture", "posture", "gait", "gait", "speed"]
    ref = own_paths._reference(X, E, names, kinds, paths, labels)
    t = ref["tests"]
    assert t["all"]["n_real"] + t["all"]["n_gen"] == 160 and t["all"]["paths"] == 16
    assert all(abs(v["accuracy"] - 0.5) < 0.2 for v in t.values())
    assert own_paths._reference(X[:30], E[:30], names, kinds, paths[:30], labels[:30]) is None  # 3 paths
