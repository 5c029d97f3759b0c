import dataclasses
import re
from pathlib import Path

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from motiongan_jax.config import DataConfig
from motiongan_jax.data import clip_cache, file_labels, gait_stats, sampling
from motiongan_jax.motion import representation

# ---------------------------------------------------------------------------------------------
# labels, discovery, splits
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name, rule, style, trial", [
    ("Sad_03.bvh", "paper", "Sad", 3),
    ("OldMan_walk_12.bvh", "paper", "OldMan", 12),
    ("dataset-2_walk-turn-left_active_007.bvh", "bandai", "active", 7),
    ("dataset-1_walk_not-confident_002.bvh", "bandai", "not-confident", 2),
    ("dataset-1_walk_not-confident_002.bvh", "bandai_session", "d1_not-confident", 2),
    ("dataset-2_walk-turn-left_active_007.bvh", "bandai_session", "d2_active", 7),
    ("137_04.bvh", "cmu", "Cat", 4),
    ("142_03.bvh", "cmu", "Clumsy", 3),
    ("142_22.bvh", "cmu", "Sneaky", 22),
])
def test_labels_from_file_names(name, rule, style, trial):
    label = file_labels.label_from_filename(name, rule)
    assert (label.style, label.trial) == (style, trial)


def test_unlabelled_names():
    assert file_labels.label_from_filename("131_01.bvh", "cmu") is None  # not a styled-walk trial
    assert file_labels.label_from_filename("walk.bvh", "paper") is None
    assert file_labels.label_from_filename("Sad_03.bvh", "bandai") is None


TINY_BVH = """HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation
  JOINT LeftUpLeg
  {
    OFFSET 1 -1 0
    CHANNELS 3 Zrotation Yrotation Xrotation
    End Site
    {
      OFFSET 0 -8 0
    }
  }
  JOINT RightUpLeg
  {
    OFFSET -1 -1 0
    CHANNELS 3 Zrotation Yrotation Xrotation
    End Site
    {
      OFFSET 0 -8 0
    }
  }
}
MOTION
Frames: 3
Frame Time: 0.0083333
0 17 0 0 0 0 0 0 0 0 0 0
0 17 1 0 0 0 10 0 0 0 0 0
0 17 2 0 0 0 20 0 0 0 0 0
"""


def test_discover_split_and_file_lists(tmp_path):
    for name in ("Sad_01.bvh", "Sad_02.bvh", "Sad_04.bvh", "Happy_04.bvh", "sub/Happy_05.bvh"):
        (tmp_path / name).parent.mkdir(exist_ok=True)
        (tmp_path / name).write_text(TINY_BVH)
    entries = file_labels.discover(tmp_path, "paper")
    assert [p.name for p, _ in entries] == ["Happy_04.bvh", "Sad_01.bvh", "Sad_02.bvh", "Sad_04.bvh", "Happy_05.bvh"]
    train, val = file_labels.split_by_trial(entries, 4, 0)
    assert sorted(p.name for p, _ in val) == ["Happy_04.bvh", "Sad_04.bvh"]
    assert len(train) == 3
    file_labels.write_file_lists(tmp_path / "out", train, val, root=tmp_path)
    assert (tmp_path / "out" / "val_files.txt").read_text().split() == ["Happy_04.bvh", "Sad_04.bvh"]
    (tmp_path / "nolabel.bvh").write_text(TINY_BVH)
    with pytest.raises(file_labels.DataError, match="no style label"):
        file_labels.discover(tmp_path, "paper")


def test_cache_key_covers_contents_and_settings(tmp_path, monkeypatch):
    monkeypatch.setenv("MOTIONGAN_CACHE", str(tmp_path / "cache"))
    f = tmp_path / "Sad_01.bvh"
    f.write_text(TINY_BVH)
    label = file_labels.FileLabel("Sad", 1)
    fresh = clip_cache.preprocess_clip(f, label, 0.05, 0, use_cache=False)
    first = clip_cache.preprocess_clip(f, label, 0.05, 0)
    cached = list((tmp_path / "cache" / "clips").glob("*.npz"))
    assert len(cached) == 1
    again = clip_cache.preprocess_clip(f, label, 0.05, 0)
    np.testing.assert_array_equal(again.pose_FxR, fresh.pose_FxR)
    np.testing.assert_array_equal(again.root_Fx3, first.root_Fx3)
    assert again.layout.joint_names == fresh.layout.joint_names
    # Each change makes a new entry: a stale one is never read.
    assert clip_cache.preprocess_clip(f, label, 0.05, 1).root_Fx3.shape[0] == 2
    assert clip_cache.preprocess_clip(f, label, 0.01, 0).root_Fx3[0, 1] == pytest.approx(0.17)
    f.write_text(TINY_BVH.replace("0 17 2 0", "0 17 5 0"))
    changed = clip_cache.preprocess_clip(f, label, 0.05, 0)
    assert changed.root_Fx3[2, 2] == pytest.approx(0.25)
    assert len(list((tmp_path / "cache" / "clips").glob("*.npz"))) == 4


# ---------------------------------------------------------------------------------------------
# batches
# ---------------------------------------------------------------------------------------------

J_REL = 4


def _layout() -> representation.RowLayout:
    names = ("root",) + tuple(f"j{k}" for k in range(1, J_REL + 1))
    return representation.RowLayout(names, (-1, 0, 1, 0, 3), tuple(range(J_REL + 1)),
                                    ((0, 1), (1, 2), (0, 3), (3, 4)), np.ones(4))


def _straight_clip(n: int, speed: float, label: str, rng) -> clip_cache.Clip:
    """A root moving along +x at `speed` m/frame, at 1 m height, with a random rigid pose."""
    t = np.arange(n, dtype=np.float32)
    root = np.stack([speed * t, np.ones(n), np.zeros(n)], -1).astype(np.float32)
    pose_J3 = rng.normal(size=(J_REL, 3)).astype(np.float32)
    pose = np.broadcast_to(pose_J3.reshape(-1), (n, 3 * J_REL)).copy()
    return clip_cache.Clip(f"{label}.bvh", file_labels.FileLabel(label, 1), 120.0, root, pose, _layout())


CFG = DataConfig(frame_nums=128, frame_step=8, control_point_interval=64, window_stride=4,
                 curve_noise=0.0, rotate=False, fps_factors=(1.0,))


@pytest.fixture(scope="module")
def clips():
    rng = np.random.default_rng(0)
    return [_straight_clip(400, 0.01, "A", rng), _straight_clip(300, 0.02, "B", rng)]


def test_batch_shapes_and_straight_walk(clips):
    arrays = sampling.build_arrays(clips, ("A", "B"), CFG)
    sample = jax.jit(sampling.make_sample_batch(CFG, 6))
    batch = sample(arrays, jax.random.key(0), 0)
    T = CFG.window_T
    chex.assert_shape(batch["root_BxTx3"], (6, T, 3))
    chex.assert_shape(batch["pose_BxTxR"], (6, T, 3 * J_REL))
    chex.assert_shape(batch["curve_BxTx3"], (6, T, 3))
    chex.assert_shape(batch["label_B"], (6,))
    chex.assert_tree_all_finite(batch)
    speed = jnp.where(batch["label_B"] == 0, 0.01, 0.02)
    # constant speed along a line: equal arc length == equal time, so the curve is the root path
    np.testing.assert_allclose(batch["curve_BxTx3"][..., 0], batch["root_BxTx3"][..., 0], atol=2e-5)
    np.testing.assert_array_equal(batch["curve_BxTx3"][..., 1], 0.0)
    steps = np.diff(batch["root_BxTx3"][..., 0], axis=1)
    np.testing.assert_allclose(steps, np.broadcast_to((speed * CFG.frame_step)[:, None], steps.shape), rtol=1e-4)


def test_batches_are_functions_of_key_and_step(clips):
    cfg = dataclasses.replace(CFG, curve_noise=0.02, rotate=True, fps_factors=(0.5, 1.0, 1.5))
    arrays = sampling.build_arrays(clips, ("A", "B"), cfg)
    sample = jax.jit(sampling.make_sample_batch(cfg, 4))
    a = sample(arrays, jax.random.key(1), 3)
    b = sample(arrays, jax.random.key(1), 3)
    c = sample(arrays, jax.random.key(1), 4)
    chex.assert_trees_all_equal(a, b)
    assert not np.allclose(a["curve_BxTx3"], c["curve_BxTx3"])


def test_rotation_keeps_shape_and_height(clips):
    cfg = dataclasses.replace(CFG, rotate=True)
    arrays = sampling.build_arrays(clips, ("A", "B"), cfg)
    plain = jax.jit(sampling.make_sample_batch(CFG, 8))(arrays, jax.random.key(2), 0)
    rot = jax.jit(sampling.make_sample_batch(cfg, 8))(arrays, jax.random.key(2), 0)
    p0 = np.asarray(plain["pose_BxTxR"]).reshape(8, -1, J_REL, 3)
    p1 = np.asarray(rot["pose_BxTxR"]).reshape(8, -1, J_REL, 3)
    np.testing.assert_allclose(np.linalg.norm(p1, axis=-1), np.linalg.norm(p0, axis=-1), rtol=1e-5)
    np.testing.assert_allclose(p1[..., 1], p0[..., 1], atol=1e-6)  # about the vertical axis
    np.testing.assert_allclose(rot["root_BxTx3"][..., 1], plain["root_BxTx3"][..., 1], atol=1e-6)
    # the curve turns with the motion: it still follows the root on the floor
    np.testing.assert_allclose(rot["curve_BxTx3"][..., [0, 2]], rot["root_BxTx3"][..., [0, 2]], atol=1e-4)


def test_fps_augmentation_changes_the_step(clips):
    cfg = dataclasses.replace(CFG, fps_factors=(0.5, 1.0, 1.5))
    arrays = sampling.build_arrays([clips[0]], ("A",), cfg)
    batch = jax.jit(sampling.make_sample_batch(cfg, 64))(arrays, jax.random.key(3), 0)
    step_frames = np.round(np.diff(np.asarray(batch["root_BxTx3"])[..., 0], axis=1)[:, 0] / 0.01).astype(int)
    assert set(step_frames) <= {4, 8, 9, 10, 11, 12}
    assert {4, 8} <= set(step_frames)


def test_epochs_visit_each_window_once():
    key = jax.random.key(0)
    n, b = 20, 4
    seen = np.concatenate([np.asarray(sampling.epoch_indices(key, s, n, b)) for s in range(n // b)])
    assert sorted(seen) == list(range(n))
    nxt = np.concatenate([np.asarray(sampling.epoch_indices(key, s, n, b)) for s in range(n // b, 2 * n // b)])
    assert sorted(nxt) == list(range(n)) and not np.array_equal(seen, nxt)


def test_short_clips_are_reported(clips):
    with pytest.raises(file_labels.DataError, match="frame_nums"):
        sampling.build_arrays(clips, ("A", "B"), dataclasses.replace(CFG, frame_nums=512, frame_step=8))


def test_bandai_dataset_end_to_end(shared_data, repo):
    """The real Bandai dataset-2 through the bandai config: labels, split, layout, a batch."""
    from motiongan_jax.config import load_config, override

    cfg = load_config(repo / "configs" / "bandai.py", check=False)
    cfg = override(cfg, [f"data.data_dir={shared_data / 'bandai' / 'dataset-2'}"]).data
    messages = []
    ds = clip_cache.load_dataset(cfg, log=messages.append)
    assert ds.style_names == ("active", "elderly", "exhausted", "feminine", "masculine", "normal", "youthful")
    assert ds.layout.num_rows == 60 and ds.fps == pytest.approx(30.0, rel=1e-4)
    # 522 files; those no longer than one window (128 frames) give no window and are dropped
    skipped = int(re.search(r"skipping (\d+) clip", " ".join(messages)).group(1)) if messages else 0
    assert len(ds.train) + len(ds.val) + skipped == 522 and len(ds.train) + len(ds.val) > 400
    assert all(c.label.trial % 4 == 0 for c in ds.val) and all(c.label.trial % 4 for c in ds.train)
    arrays = sampling.build_arrays(ds.train, ds.style_names, cfg)
    batch = jax.jit(sampling.make_sample_batch(cfg, 8))(arrays, jax.random.key(0), 0)
    chex.assert_shape(batch["pose_BxTxR"], (8, cfg.window_T, 60))
    chex.assert_tree_all_finite(batch)
    # a walk: the root travels ~1 m/s; hips ~0.9 m above the floor before rotation (rotation keeps y)
    speed = np.linalg.norm(np.diff(np.asarray(batch["root_BxTx3"])[..., [0, 2]], axis=1), axis=-1).mean()
    assert 0.02 < speed < 0.2  # metres per 15 Hz sample
    assert 0.7 < float(np.median(batch["root_BxTx3"][..., 1])) < 1.1


def test_bandai_two_sessions_keep_their_styles_apart(shared_data, repo):
    """dataset-1 + dataset-2 under bandai_session: 15 + 7 = 22 labels; the two 20-31-frame
    dataset-1 clips (too short for a window, and with other End Sites) are dropped, not fatal."""
    from motiongan_jax.config import load_config, override

    cfg = load_config(repo / "configs" / "bandai.py", check=False)
    cfg = override(cfg, [f"data.data_dir={shared_data / 'bandai'}", "data.label_rule=bandai_session",
                         "data.val_modulus=2"]).data
    messages = []
    ds = clip_cache.load_dataset(cfg, log=messages.append)
    assert len(ds.style_names) == 22
    assert sum(s.startswith("d1_") for s in ds.style_names) == 15 and "d2_elderly" in ds.style_names
    assert any(m.startswith("skipping") for m in messages)
    used = {Path(c.source).name for c in ds.train + ds.val}
    assert "dataset-1_walk_normal_002.bvh" not in used and "dataset-1_walk-back_normal_001.bvh" not in used
    assert 60 < sum(n.startswith("dataset-1") for n in used) <= 73
    assert all(len(c.root_Fx3) > cfg.frame_nums for c in ds.train + ds.val)


def test_gait_statistics_recover_the_embedded_styles(repo):
    """Measured without annotation, the embedded walks' stride lengths and gait phase agree with the
    gait parameters each clip was generated with (its styles.json entry)."""
    import json

    from motiongan_jax.config import load_config

    cfg = load_config(repo / "configs" / "tiny.py").data
    ds = clip_cache.load_dataset(cfg)
    truth = json.loads((clip_cache.resolve_data_dir(cfg) / "styles.json").read_text())["clips"]
    gait = gait_stats.gait_targets(ds.train, ds.style_names, ds.layout, ds.fps / cfg.frame_step)
    assert gait.sample_hz == ds.fps / cfg.frame_step and 0.0 <= gait.stride_speed_slope <= 1.0
    assert gait.toe_joints == representation.foot_joints(ds.layout)
    want = [np.median([truth[Path(c.source).stem]["stride_length"] for c in ds.train if c.label.style == s])
            for s in ds.style_names]
    np.testing.assert_allclose(gait.stride_m_C, want, rtol=0.05)
    # step heights (toes' left − right) order the styles as the ankle lift they were made with
    lifts = [np.median([truth[Path(c.source).stem]["foot_lift"] for c in ds.train if c.label.style == s])
             for s in ds.style_names]
    from scipy.stats import spearmanr

    assert spearmanr(gait.step_height_m_C, lifts).correlation > 0.8
    assert int(np.argmax(gait.step_height_m_C)) == int(np.argmax(lifts))
    assert 0.02 <= gait.contact_height_m < 0.03  # planted toes sit on the floor: ~2 cm above the 10th percentile
    for clip in ds.train[:: len(ds.train) // 6]:
        phase, valid = gait_stats.clip_gait_phase(clip, ds.layout, gait.toe_joints)
        chex.assert_shape((phase, valid), (len(clip.root_Fx3),))
        assert valid.mean() > 0.95  # steady walks: the steps never fade
        cycles_per_s = (phase[-1] - phase[0]) / (2 * np.pi) / ((len(phase) - 1) / clip.fps)
        assert cycles_per_s == pytest.approx(truth[Path(clip.source).stem]["cadence"] / 2, rel=0.03)
        assert np.mean(np.diff(phase) > 0) > 0.99


def test_stride_speed_slope_within_styles_by_hand():
    """Two styles whose clips lie on lines of slope 0.6 in log speed, log stride, at different
    levels: pooled about each style's own means the slope is 0.6, where one line through all the
    clips would mix the levels in; a style of one clip adds nothing; slopes outside [0, 1] are
    held to it, and without speed differences there is no slope."""
    x_a, x_b = np.log([0.8, 1.0, 1.3]), np.log([1.2, 1.5])
    y_a, y_b = 0.6 * x_a - 0.3, 0.6 * x_b + 0.4
    assert gait_stats.stride_speed_slope([x_a, x_b, np.log([2.0])], [y_a, y_b, np.log([3.0])]) == pytest.approx(0.6)
    pooled_all = np.polyfit(np.concatenate([x_a, x_b]), np.concatenate([y_a, y_b]), 1)[0]
    assert pooled_all > 1.0  # the levels differ with speed: a single line would overstate the slope
    assert gait_stats.stride_speed_slope([x_a], [-0.5 * x_a]) == 0.0
    assert gait_stats.stride_speed_slope([x_a], [2.0 * x_a]) == 1.0
    assert gait_stats.stride_speed_slope([np.zeros(3)], [np.arange(3.0)]) == 0.0
