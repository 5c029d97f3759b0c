"""The embedded default dataset (motiongan_jax/data/synthetic.py): skeleton, determinism, physical
sanity of the walks measured through forward kinematics, recoverable style parameters, and the
on-disk dataset."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from expected import CMU_NAMES

from motiongan_jax.data import synthetic
from motiongan_jax.motion import bvh, kinematics
from motiongan_jax.motion.representation import layout_from_skeleton

U = synthetic.UNITS_TO_M
FPS = 60.0
SECONDS = 10.0
IDX = {n: i for i, n in enumerate(synthetic.JOINT_NAMES)}

ZERO_LENGTH = {"LHipJoint", "RHipJoint", "LowerBack", "Neck", "LeftShoulder", "LeftFingerBase",
               "LThumb", "RightShoulder", "RightFingerBase", "RThumb"}
# The paper's 28 kept joints (DESIGN.md §2.2), with the file root's own name.
PAPER_KEPT = (
    "Hips", "LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToeBase", "LeftToeBase_EndSite", "RightUpLeg",
    "RightLeg", "RightFoot", "RightToeBase", "RightToeBase_EndSite", "Spine", "Spine1", "Neck1",
    "Head", "Head_EndSite", "LeftArm", "LeftForeArm", "LeftHand", "LeftHandIndex1",
    "LeftHandIndex1_EndSite", "LThumb_EndSite", "RightArm", "RightForeArm", "RightHand",
    "RightHandIndex1", "RightHandIndex1_EndSite", "RThumb_EndSite",
)


# ----------------------------------------------------------------------------------------------
# Measurements (world positions in metres, frame 0 = T-pose excluded by the callers)
# ----------------------------------------------------------------------------------------------


def world_m(motion) -> np.ndarray:
    return kinematics.world_positions(motion) * U


def moving_average(x: np.ndarray, n: int) -> np.ndarray:
    k = np.ones(n) / n
    return np.stack([np.convolve(x[:, i], k, mode="valid") for i in range(x.shape[1])], -1)


def stride_frequency(w: np.ndarray, fps: float) -> float:
    """Gait cycles per second from the left-minus-right ankle height (odd harmonics only, so the
    fundamental dominates): peak of a zero-padded, Hann-windowed FFT, refined parabolically."""
    s = w[:, IDX["LeftFoot"], 1] - w[:, IDX["RightFoot"], 1]
    s = (s - s.mean()) * np.hanning(len(s))
    n = 32 * len(s)
    mag = np.abs(np.fft.rfft(s, n))
    freqs = np.fft.rfftfreq(n, 1.0 / fps)
    band = (freqs > 0.3) & (freqs < 3.0)
    i = int(np.flatnonzero(band)[np.argmax(mag[band])])
    a, b, c = np.log(mag[i - 1:i + 2])
    shift = 0.5 * (a - c) / (a - 2 * b + c)
    return float(freqs[i] + shift * (freqs[1] - freqs[0]))


def path_length(w: np.ndarray, window: int) -> float:
    """Arc length of the root's floor path, smoothed over `window` frames (one gait cycle) so
    that the lateral sway does not count."""
    p = moving_average(w[:, 0][:, [0, 2]], window)
    return float(np.sum(np.linalg.norm(np.diff(p, axis=0), axis=1)))


def hips_forward(w: np.ndarray) -> np.ndarray:
    """Unit floor direction the pelvis faces: (left hip - right hip) x up."""
    lr = w[:, IDX["LeftUpLeg"]] - w[:, IDX["RightUpLeg"]]
    f = np.cross(lr, np.array([0.0, 1.0, 0.0]))[:, [0, 2]]
    return f / np.linalg.norm(f, axis=1, keepdims=True)


def torso_lean_deg(w: np.ndarray) -> float:
    """Mean forward angle of the Hips -> Neck1 vector from the vertical."""
    v = w[:, IDX["Neck1"]] - w[:, IDX["Hips"]]
    fwd = hips_forward(w)
    return float(np.mean(np.rad2deg(np.arctan2(np.sum(v[:, [0, 2]] * fwd, 1), v[:, 1]))))


def lowest_foot(w: np.ndarray) -> np.ndarray:
    return synthetic.foot_heights(w, units_to_m=U).min(-1)


# ----------------------------------------------------------------------------------------------
# Fixtures
# ----------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def walks():
    """One 10 s clip per style: (the clip's own jittered GaitParams, motion, world positions of
    frames 1..)."""
    out = {}
    n = int(SECONDS * FPS) + 1
    for i, (name, params) in enumerate(synthetic.STYLES.items()):
        motion = synthetic.generate_clip(params, key_or_seed=1000 + i, num_frames=n, fps=FPS)
        out[name] = (synthetic.clip_params(params, 1000 + i), motion, world_m(motion)[1:])
    return out


# ----------------------------------------------------------------------------------------------
# Skeleton
# ----------------------------------------------------------------------------------------------


def test_skeleton_topology_names_channels():
    sk = synthetic.cmu_skeleton()
    assert sk.names == CMU_NAMES
    assert sk.num_joints == 38
    assert sum(not e for e in sk.is_end_site) == 31
    assert sum(sk.is_end_site) == 7
    assert all(n.endswith("_EndSite") == e for n, e in zip(sk.names, sk.is_end_site))
    assert sk.channels[0] == ("Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation")
    for j in range(1, 38):
        assert sk.channels[j] in ((), ("Zrotation", "Yrotation", "Xrotation"))
    assert sk.num_channels == 96 == synthetic.NUM_CHANNELS
    assert all(p < j for j, p in enumerate(sk.parents)) and sk.parents[0] == -1
    # parents match CMU's hierarchy
    parent_name = {n: (sk.names[p] if p >= 0 else None) for n, p in zip(sk.names, sk.parents)}
    assert parent_name["LeftUpLeg"] == "LHipJoint" and parent_name["LHipJoint"] == "Hips"
    assert parent_name["LowerBack"] == "Hips" and parent_name["Neck"] == "Spine1"
    assert parent_name["LeftShoulder"] == "Spine1" and parent_name["LThumb"] == "LeftHand"
    assert parent_name["RThumb_EndSite"] == "RThumb"


def test_skeleton_zero_length_joints_and_representation():
    sk = synthetic.cmu_skeleton()
    zero = {n for n, o in zip(sk.names[1:], sk.offsets[1:]) if np.sum(o * o) <= 1e-8}
    assert zero == ZERO_LENGTH
    layout = layout_from_skeleton(sk, U)
    assert layout.joint_names == PAPER_KEPT
    assert layout.num_rows == 81


def test_skeleton_geometry():
    sk = synthetic.cmu_skeleton()
    tpose = bvh.Motion(sk, 1 / 60, np.zeros((1, sk.num_channels)))
    p = kinematics.world_positions(tpose)[0]
    # left at +X, right at -X, faces +Z (toes ahead of ankles), Y up
    for part in ("UpLeg", "Leg", "Foot", "ToeBase", "Arm", "Hand"):
        assert p[IDX["Left" + part], 0] > 0.5 and p[IDX["Right" + part], 0] < -0.5
    assert p[IDX["LeftToeBase_EndSite"], 2] > p[IDX["LeftFoot"], 2] + 2.0
    assert p[IDX["Head_EndSite"], 1] > p[IDX["Neck1"], 1] > p[IDX["Spine"], 1] > 0
    # plausible adult proportions in CMU units (1 unit = 0.056444 m)
    hip_height = -np.min(p[:, 1])
    assert 16.5 < hip_height < 18.0
    assert np.linalg.norm(sk.offsets[IDX["LeftLeg"]]) == pytest.approx(7.5, abs=0.5)  # thigh
    assert np.linalg.norm(sk.offsets[IDX["LeftFoot"]]) == pytest.approx(7.3, abs=0.5)  # shin
    assert 1.3 < (p[IDX["Head_EndSite"], 1] + hip_height) * U < 1.8  # standing height, metres
    # mirror symmetry
    for j, n in enumerate(sk.names):
        m = n.replace("Left", "Right").replace("LThumb", "RThumb").replace("LHip", "RHip")
        if m != n:
            np.testing.assert_allclose(sk.offsets[IDX[m]], sk.offsets[j] * [-1, 1, 1])


# ----------------------------------------------------------------------------------------------
# Determinism and seeds
# ----------------------------------------------------------------------------------------------


def test_generate_clip_deterministic():
    p = synthetic.STYLES["Normal"]
    a = synthetic.generate_clip(p, key_or_seed=7, num_frames=121, fps=60.0)
    b = synthetic.generate_clip(p, key_or_seed=7, num_frames=121, fps=60.0)
    c = synthetic.generate_clip(p, key_or_seed=8, num_frames=121, fps=60.0)
    np.testing.assert_array_equal(a.values, b.values)
    assert np.max(np.abs(a.values[1:] - c.values[1:])) > 1.0
    assert a.values.shape == (121, 96) and a.frame_time == pytest.approx(1 / 60)
    # seed forms: sequences of ints, SeedSequence, JAX keys
    s1 = synthetic.generate_clip(p, key_or_seed=(3, 4), num_frames=31, fps=30.0)
    s2 = synthetic.generate_clip(p, key_or_seed=np.random.SeedSequence([3, 4]), num_frames=31, fps=30.0)
    np.testing.assert_array_equal(s1.values, s2.values)
    jax = pytest.importorskip("jax")
    k1 = synthetic.generate_clip(p, key_or_seed=jax.random.PRNGKey(5), num_frames=31, fps=30.0)
    k2 = synthetic.generate_clip(p, key_or_seed=jax.random.key(5), num_frames=31, fps=30.0)
    np.testing.assert_array_equal(k1.values, k2.values)
    with pytest.raises(ValueError):
        synthetic.generate_clip(p, key_or_seed=-1, num_frames=31)


def test_frame0_is_tpose_and_jitter():
    p = synthetic.STYLES["OldMan"]  # every parameter non-zero
    m = synthetic.generate_clip(p, key_or_seed=1, num_frames=61, fps=60.0)
    assert synthetic.clip_params(p, 1) == p.jittered(np.random.default_rng(np.random.SeedSequence([1])))
    assert synthetic.clip_params(p, 1, jitter=0.0) == p
    assert np.all(m.values[0, 3:] == 0.0)
    w = world_m(m)
    assert abs(lowest_foot(w[:1])[0]) < 1e-6  # T-pose stands on the floor
    np.testing.assert_allclose(w[0, 0, [0, 2]], w[1, 0, [0, 2]], atol=0.2)
    # per-clip parameter variation: a few percent, different per seed, none when disabled
    j1 = p.jittered(np.random.default_rng(1))
    j2 = p.jittered(np.random.default_rng(2))
    r1 = np.array(dataclasses.astuple(j1)) / np.array(dataclasses.astuple(p))
    assert np.all(np.abs(r1 - 1) <= 0.08 + 1e-12) and np.any(np.abs(r1 - 1) > 0.005)
    assert j1 != j2
    a = synthetic.generate_clip(p, key_or_seed=1, num_frames=61, jitter=0.0)
    b = synthetic.generate_clip(p, key_or_seed=1, num_frames=61, jitter=0.04)
    assert not np.array_equal(a.values, b.values)
    # jitter changes the gait, not the path's shape: same start, same initial heading
    fa, fb = hips_forward(world_m(a)[1:11]), hips_forward(world_m(b)[1:11])
    assert np.degrees(np.arccos(np.clip(np.sum(fa * fb, 1), -1, 1))).max() < 3.0


def test_longer_clip_extends_the_same_walk():
    p = synthetic.STYLES["Drunk"]
    short = synthetic.generate_clip(p, key_or_seed=9, num_frames=301, fps=60.0)
    long = synthetic.generate_clip(p, key_or_seed=9, num_frames=901, fps=60.0)
    # identical except within ~1.5 s of the short clip's end (smoothing windows see the end)
    np.testing.assert_allclose(short.values[:200], long.values[:200], rtol=0, atol=1e-9)


# ----------------------------------------------------------------------------------------------
# Physical sanity via forward kinematics
# ----------------------------------------------------------------------------------------------


def test_styles_table():
    assert len(synthetic.STYLES) >= 8
    assert all("_" not in s and s.isalnum() for s in synthetic.STYLES)
    assert 8 <= len(synthetic.PARAM_NAMES) <= 10
    rows = np.array([dataclasses.astuple(p) for p in synthetic.STYLES.values()])
    # every parameter varies across styles, and no two styles are close
    assert np.all(rows.std(0) > 0)
    z = (rows - rows.mean(0)) / rows.std(0)
    d = np.linalg.norm(z[:, None] - z[None], axis=-1) + np.eye(len(rows)) * 99
    assert d.min() > 1.0
    for p in synthetic.STYLES.values():
        assert p.speed == pytest.approx(p.stride_length * p.cadence / 2)


def test_feet_on_floor_and_planted(walks):
    for name, (_, _, w) in walks.items():
        low = lowest_foot(w)
        assert np.percentile(low, 1) > -0.02, name  # no sinking
        assert np.percentile(low, 95) < 0.02, name  # and no floating: one foot is down
        for side in ("Left", "Right"):  # a ball on the floor does not slide
            ball = w[:, IDX[side + "ToeBase"]]
            on = (ball[1:, 1] < 0.01) & (ball[:-1, 1] < 0.01)
            speed = np.linalg.norm(np.diff(ball[:, [0, 2]], axis=0), axis=1)[on] * FPS
            assert on.mean() > 0.2 and np.percentile(speed, 90) < 0.05, (name, side)


def test_bones_keep_their_lengths(walks):
    _, m, w = walks["Drunk"]
    sk = m.skeleton
    for j in range(1, sk.num_joints):
        d = np.linalg.norm(w[:, j] - w[:, sk.parents[j]], axis=1)
        np.testing.assert_allclose(d, np.linalg.norm(sk.offsets[j]) * U, atol=1e-9)


def test_speed_distance_and_facing(walks):
    for name, (params, _, w) in walks.items():
        cycle = int(round(FPS / params.stride_frequency))
        dist = path_length(w, cycle)
        expected = params.speed * (len(w) - cycle) / FPS
        assert dist == pytest.approx(expected, rel=0.10), name
        # hips face along the path tangent (the pelvis twist averages out)
        tangent = np.diff(moving_average(w[:, 0][:, [0, 2]], cycle), axis=0)
        tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
        fwd = moving_average(hips_forward(w), cycle)[1:]
        err = np.rad2deg(np.arctan2(fwd[:, 0] * tangent[:, 1] - fwd[:, 1] * tangent[:, 0],
                                    np.sum(fwd * tangent, 1)))
        assert np.mean(np.abs(err)) < 5.0, name
        assert abs(np.mean(err)) < 3.0, name


def test_cadence_and_stride_match_params(walks):
    for name, (params, _, w) in walks.items():
        style = synthetic.STYLES[name]
        assert params.cadence == pytest.approx(style.cadence, rel=0.081)  # per-clip jitter
        assert params.stride_length == pytest.approx(style.stride_length, rel=0.081)
        f = stride_frequency(w, FPS)
        assert 2 * f == pytest.approx(params.cadence, rel=0.10), name
        cycle = int(round(FPS / params.stride_frequency))
        stride = path_length(w, cycle) / ((len(w) - cycle) / FPS * f)
        assert stride == pytest.approx(params.stride_length, rel=0.15), name


def test_style_parameters_are_visible(walks):
    def knee_height(style):  # how high the knees come up in swing
        w = walks[style][2]
        return np.percentile(w[:, [IDX["LeftLeg"], IDX["RightLeg"]], 1], 98)

    def hip_height(style):
        return np.mean(walks[style][2][:, 0, 1])

    def stance_knee(style):  # median knee flexion while that foot's ball or heel is down
        w = walks[style][2]
        out = []
        for side in ("Left", "Right"):
            thigh = w[:, IDX[side + "Leg"]] - w[:, IDX[side + "UpLeg"]]
            shin = w[:, IDX[side + "Foot"]] - w[:, IDX[side + "Leg"]]
            cos = np.sum(thigh * shin, 1) / np.linalg.norm(thigh, axis=1) / np.linalg.norm(shin, axis=1)
            down = synthetic.foot_heights(w, units_to_m=U)[:, 0 if side == "Left" else 1] < 0.005
            out.append(np.rad2deg(np.arccos(np.clip(cos, -1, 1)))[down])
        return np.median(np.concatenate(out))

    def head_pitch(style):  # forward angle of Head -> Head_EndSite from vertical
        w = walks[style][2]
        v = w[:, IDX["Head_EndSite"]] - w[:, IDX["Head"]]
        return np.mean(np.rad2deg(np.arctan2(np.sum(v[:, [0, 2]] * hips_forward(w), 1), v[:, 1])))

    def bounce(style):  # pelvis vertical excursion
        y = walks[style][2][:, 0, 1]
        return np.percentile(y, 95) - np.percentile(y, 5)

    def sway(style):  # amplitude of the pelvis' side-to-side motion at the stride frequency
        params, _, w = walks[style]
        n = int(round(FPS / params.stride_frequency))
        mid = slice(n // 2, len(w) - n + 1 + n // 2)
        dev = w[mid, 0][:, [0, 2]] - moving_average(w[:, 0][:, [0, 2]], n)
        lr = (w[mid, IDX["LeftUpLeg"]] - w[mid, IDX["RightUpLeg"]])[:, [0, 2]]
        lat = np.sum(dev * lr, 1) / np.linalg.norm(lr, axis=1)
        t = np.arange(len(lat)) / FPS
        return 2 * np.abs(np.mean(lat * np.exp(-2j * np.pi * stride_frequency(w, FPS) * t)))

    def elbow(style):
        w = walks[style][2]
        a = w[:, IDX["LeftForeArm"]] - w[:, IDX["LeftArm"]]
        b = w[:, IDX["LeftHand"]] - w[:, IDX["LeftForeArm"]]
        cos = np.sum(a * b, 1) / np.linalg.norm(a, axis=1) / np.linalg.norm(b, axis=1)
        return np.mean(np.rad2deg(np.arccos(np.clip(cos, -1, 1))))

    def arm_range(style):  # forward-backward range of the wrists relative to the hips
        w = walks[style][2]
        fwd = hips_forward(w)
        rel = (w[:, IDX["LeftHand"]] - w[:, 0])[:, [0, 2]]
        a = np.sum(rel * fwd, 1)
        return np.percentile(a, 95) - np.percentile(a, 5)

    assert knee_height("Marching") > knee_height("Normal") + 0.08
    assert torso_lean_deg(walks["OldMan"][2]) > torso_lean_deg(walks["Normal"][2]) + 10.0
    assert hip_height("Sneaky") < hip_height("Normal") - 0.02
    assert stance_knee("Sneaky") > stance_knee("Normal") + 20.0
    assert head_pitch("Sad") > head_pitch("Normal") + 15.0
    assert arm_range("Marching") > 2 * arm_range("Sad")

    # Across all styles the measured quantities track the ground-truth parameters.
    styles = list(walks)
    pairs = {
        "torso_lean": [torso_lean_deg(walks[s][2]) for s in styles],
        "foot_lift": [knee_height(s) for s in styles],
        "arm_swing": [arm_range(s) for s in styles],
        "crouch": [stance_knee(s) for s in styles],
        "vertical_bounce": [bounce(s) for s in styles],
        "lateral_sway": [sway(s) for s in styles],
        "elbow_bend": [elbow(s) for s in styles],
        "head_tilt": [head_pitch(s) - torso_lean_deg(walks[s][2]) for s in styles],
    }
    for param, measured in pairs.items():
        truth = [getattr(walks[s][0], param) for s in styles]
        r = np.corrcoef(truth, measured)[0, 1]
        assert r > (0.7 if param == "crouch" else 0.8), (param, r)


# ----------------------------------------------------------------------------------------------
# Dataset on disk
# ----------------------------------------------------------------------------------------------


def test_write_dataset_roundtrip(tmp_path):
    out = synthetic.write_dataset(tmp_path / "ds", seed=3, clips_per_style=1, seconds=3.0, fps=30.0,
                                  styles=["Normal", "Marching"])
    assert out == tmp_path / "ds"
    assert sorted(p.name for p in out.iterdir()) == ["Marching_01.bvh", "Normal_01.bvh", "styles.json"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ds"]  # no temp dirs left behind
    for style in ("Normal", "Marching"):
        m = bvh.read_bvh(out / f"{style}_01.bvh")
        ref = synthetic.generate_clip(synthetic.STYLES[style], key_or_seed=synthetic.clip_seed(3, style, 1),
                                      num_frames=91, fps=30.0)
        assert m.skeleton.names == ref.skeleton.names
        assert m.skeleton.channels == ref.skeleton.channels
        np.testing.assert_allclose(m.skeleton.offsets, ref.skeleton.offsets, atol=1e-4)
        assert m.values.shape == (91, 96)
        assert m.frame_time == pytest.approx(1 / 30, rel=1e-4)
        np.testing.assert_allclose(m.values, ref.values, rtol=0, atol=5.1e-5)
    meta = json.loads((out / "styles.json").read_text())
    assert meta["version"] == synthetic.VERSION and meta["seed"] == 3 and meta["fps"] == 30.0
    assert meta["units_to_m"] == U and "0.056444" in meta["units"]
    assert set(meta["styles"]) == {"Normal", "Marching"}
    assert meta["styles"]["Marching"] == synthetic.STYLES["Marching"].to_dict()
    assert set(meta["param_units"]) == set(synthetic.PARAM_NAMES)
    assert set(meta["clips"]) == {"Normal_01", "Marching_01"}
    assert meta["clips"]["Normal_01"] == synthetic.clip_params(
        synthetic.STYLES["Normal"], synthetic.clip_seed(3, "Normal", 1)).to_dict()
    with pytest.raises(FileExistsError):
        synthetic.write_dataset(out, seed=3, clips_per_style=1, seconds=3.0, fps=30.0, styles=["Normal"])


def test_write_dataset_is_byte_identical_and_subset_stable(tmp_path):
    kw = dict(clips_per_style=2, seconds=1.0, fps=30.0)
    a = synthetic.write_dataset(tmp_path / "a", seed=5, styles=["Sad", "Drunk"], **kw)
    b = synthetic.write_dataset(tmp_path / "b", seed=5, styles=["Drunk"], **kw)
    c = synthetic.write_dataset(tmp_path / "c", seed=6, styles=["Drunk"], **kw)
    for n in ("Drunk_01.bvh", "Drunk_02.bvh"):
        assert (a / n).read_bytes() == (b / n).read_bytes()
        assert (a / n).read_bytes() != (c / n).read_bytes()
    assert (a / "Drunk_01.bvh").read_bytes() != (a / "Drunk_02.bvh").read_bytes()
    again = synthetic.write_dataset(tmp_path / "a", seed=5, styles=["Sad", "Drunk"], overwrite=True, **kw)
    for n in ("Sad_01.bvh", "Drunk_02.bvh", "styles.json"):
        assert (again / n).read_bytes() == (a / n).read_bytes()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a", "b", "c"]


@pytest.fixture
def small_default(monkeypatch, tmp_path):
    """default_dataset_dir with a cache under tmp_path and a tiny dataset instead of the default."""
    monkeypatch.setenv("MOTIONGAN_CACHE", str(tmp_path / "cache"))
    real = synthetic.write_dataset
    calls = []

    def small(out_dir, *, seed=0, **_):
        calls.append(out_dir)
        return real(out_dir, seed=seed, clips_per_style=1, seconds=0.5, fps=30.0, styles=["Normal"])

    monkeypatch.setattr(synthetic, "write_dataset", small)
    return real, calls


def test_default_dataset_dir_caches(small_default, tmp_path):
    _, calls = small_default
    d = synthetic.default_dataset_dir(seed=4)
    assert d == tmp_path / "cache" / f"synthetic-v{synthetic.VERSION}-seed4"
    assert (d / "Normal_01.bvh").is_file() and (d / "styles.json").is_file()
    assert synthetic.default_dataset_dir(seed=4) == d
    assert len(calls) == 1  # the second call reuses the cache


def test_default_dataset_dir_race_loser_uses_winner(small_default, monkeypatch, tmp_path):
    real, _ = small_default
    target = tmp_path / "cache" / f"synthetic-v{synthetic.VERSION}-seed2"
    gen = synthetic.generate_clip
    state = {"done": False}

    def racing_generate(*a, **k):
        # Another process finishes first, while this one is still generating.
        if not state["done"]:
            state["done"] = True
            real(target, seed=2, clips_per_style=1, seconds=0.5, fps=30.0, styles=["Normal"])
        return gen(*a, **k)

    monkeypatch.setattr(synthetic, "generate_clip", racing_generate)
    winner = (target / "Normal_01.bvh").read_bytes() if target.exists() else None
    assert winner is None
    d = synthetic.default_dataset_dir(seed=2)
    assert d == target and (d / "styles.json").is_file()
    assert [p.name for p in (tmp_path / "cache").iterdir()] == [target.name]  # loser cleaned up
