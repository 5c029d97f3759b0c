"""The style evaluator and the evaluation driver (bin/train_evaluator.py, bin/evaluate.py).

Unit tests use hand-made windows with known answers; the CLI tests run the whole protocol on
the tiny config (conftest's checkpoint with seeded random parameters, as in tests/test_generate.py, and
an evaluator trained for a few steps) and check the report's structure and the real-data row,
whose values are known: real motion on its own curve has bone error ~0 and path ratio ~1.
"""

import dataclasses
import json
import shutil

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import load_cli

from motiongan_jax.data import curves, synthetic
from motiongan_jax.evaluation import clip_metrics, eval_curves, evaluator
from motiongan_jax.model import checkpoint
from motiongan_jax.motion import gait, representation, trajectory

# ---------------------------------------------------------------------------------------------
# canonicalisation


def _walk(T=16, R=6, heading=0.0, seed=0):
    """A window walking 1 m along `heading` (0 = +z) with random root-relative joints."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 1, T)
    root = np.stack([np.sin(heading) * t, np.ones(T), np.cos(heading) * t], -1)
    pose = rng.normal(size=(T, R)).astype(np.float32)
    return root.astype(np.float32), pose


def test_canonical_pose_removes_the_heading():
    root, pose = _walk(heading=0.0)
    out0 = np.asarray(evaluator.canonical_pose(root[None], pose[None]))[0]
    np.testing.assert_allclose(out0, pose, atol=1e-6)  # already walking along +z: unchanged
    for theta in (0.7, -2.0, np.pi):
        rot_root = np.asarray(trajectory.rotate_y(jnp.asarray(root), theta))
        rot_pose = np.asarray(trajectory.rotate_y(jnp.asarray(pose.reshape(16, 2, 3)), theta)).reshape(16, 6)
        out = np.asarray(evaluator.canonical_pose(rot_root[None], rot_pose[None]))[0]
        np.testing.assert_allclose(out, pose, atol=1e-5)


def _toy_sampler(num_styles=3, T=16, R=6, B=32):
    """Class c: joint rows offset by c along y plus noise; a trivially separable toy set."""
    def sample(key, step):
        k1, k2 = jax.random.split(jax.random.fold_in(key, step))
        labels = jax.random.randint(k1, (B,), 0, num_styles)
        root = jnp.broadcast_to(jnp.stack([jnp.zeros(T), jnp.ones(T), jnp.linspace(0, 1, T)], -1), (B, T, 3))
        pose = 0.3 * jax.random.normal(k2, (B, T, R)) + labels[:, None, None].astype(jnp.float32) * \
            jnp.asarray([0, 1, 0] * (R // 3), jnp.float32)
        return {"root_BxTx3": root, "pose_BxTxR": pose, "label_B": labels}
    return sample


def test_evaluator_learns_is_deterministic_and_round_trips(tmp_path):
    sample = _toy_sampler()
    ecfg = evaluator.EvaluatorConfig(channels=(8, 8, 8), steps=60, batch_size=32, lr=3e-3)
    ev = evaluator.train(sample, 6, ("a", "b", "c"), ecfg)
    ev2 = evaluator.train(sample, 6, ("a", "b", "c"), ecfg)
    assert ev.checksum == ev2.checksum  # same seed, same weights
    test = sample(jax.random.key(99), 0)
    logits, feats = evaluator.classify(ev, test["root_BxTx3"], test["pose_BxTxR"])
    chex.assert_shape(logits, (32, 3))
    chex.assert_shape(feats, (32, 8))
    assert np.mean(np.argmax(logits, -1) == np.asarray(test["label_B"])) > 0.9

    npz, side = evaluator.save(ev, tmp_path / "ev.npz")
    loaded = evaluator.load(npz)
    assert loaded.checksum == ev.checksum == json.loads(side.read_text())["checksum"]
    logits2, _ = evaluator.classify(loaded, test["root_BxTx3"], test["pose_BxTxR"])
    np.testing.assert_array_equal(logits2, logits)

    other = evaluator.train(sample, 6, ("a", "b", "c"), ecfg.__class__(**{**ecfg.__dict__, "seed": 1}))
    assert other.checksum != ev.checksum


def test_speed_free_evaluator_reads_poses_not_their_order(tmp_path):
    """The speed-free variant scores a window and the same window with its frames shuffled (or
    played at another rate: each frame twice) alike; the temporal evaluator does not. It still
    learns the toy styles, and its kind survives saving."""
    sample = _toy_sampler()
    ecfg = evaluator.EvaluatorConfig(channels=(8, 8, 8), steps=60, batch_size=32, lr=3e-3, speed_free=True)
    ev = evaluator.train(sample, 6, ("a", "b", "c"), ecfg)
    test = sample(jax.random.key(99), 0)
    root, pose = np.asarray(test["root_BxTx3"]), np.asarray(test["pose_BxTxR"])
    logits, _ = evaluator.classify(ev, root, pose)
    assert np.mean(np.argmax(logits, -1) == np.asarray(test["label_B"])) > 0.9
    perm = np.asarray(jax.random.permutation(jax.random.key(3), 16))
    shuffled, _ = evaluator.classify(ev, root, pose[:, perm])
    np.testing.assert_allclose(shuffled, logits, atol=1e-4)
    half = np.repeat(pose[:, :8], 2, axis=1)  # the first half of each window, each pose held twice
    slow, _ = evaluator.classify(ev, root, half)
    fast, _ = evaluator.classify(ev, root, np.concatenate([pose[:, :8], pose[:, :8]], 1))
    np.testing.assert_allclose(slow, fast, atol=1e-4)
    temporal = evaluator.train(sample, 6, ("a", "b", "c"), dataclasses.replace(ecfg, speed_free=False))
    a, _ = evaluator.classify(temporal, root, pose)
    b, _ = evaluator.classify(temporal, root, pose[:, perm])
    assert np.max(np.abs(a - b)) > 1e-3
    npz, _ = evaluator.save(ev, tmp_path / "sf.npz")
    loaded = evaluator.load(npz)
    assert loaded.meta["config"]["speed_free"] is True and loaded.checksum == ev.checksum
    np.testing.assert_array_equal(evaluator.classify(loaded, root, pose)[0], logits)


def test_evaluator_load_rejects_damage_and_missing_files(tmp_path):
    ev = evaluator.train(_toy_sampler(), 6, ("a", "b", "c"), evaluator.EvaluatorConfig(channels=(4, 4, 4), steps=2))
    npz, side = evaluator.save(ev, tmp_path / "ev.npz")
    with np.load(npz) as z:
        arrays = {k: z[k] for k in z.files}
    name = next(k for k in arrays if k.startswith("param:"))
    arrays[name] = arrays[name] + 1e-3
    np.savez(npz, **arrays)
    with pytest.raises(evaluator.EvaluatorError, match="checksum mismatch"):
        evaluator.load(npz)
    with pytest.raises(evaluator.EvaluatorError, match="no such file"):
        evaluator.load(tmp_path / "missing.npz")
    side.write_text(json.dumps({**json.loads(side.read_text()), "format_version": 99}))
    with pytest.raises(evaluator.EvaluatorError, match="format version"):
        evaluator.load(npz)


def test_clip_windows_positions():
    root = np.arange(40 * 3, dtype=np.float32).reshape(40, 3)
    pose = np.arange(40 * 6, dtype=np.float32).reshape(40, 6)
    r, p = evaluator.clip_windows(root, pose, T=4, frame_step=3, stride=10)
    # span (4-1)*3+1 = 10 frames; starts 0, 10, 20, 30
    chex.assert_shape([r, p], [(4, 4, 3), (4, 4, 6)])
    np.testing.assert_array_equal(r[1, :, 0], root[[10, 13, 16, 19], 0])
    r, _ = evaluator.clip_windows(root[:9], pose[:9], T=4, frame_step=3, stride=10)
    assert len(r) == 0


# ---------------------------------------------------------------------------------------------
# evaluation helpers


def test_foot_joints_by_name_and_by_height():
    layout = representation.layout_from_skeleton(synthetic.cmu_skeleton(), synthetic.UNITS_TO_M)
    left_toe, right_toe = representation.foot_joints(layout)
    assert {layout.joint_names[left_toe], layout.joint_names[right_toe]} == {"LeftToeBase", "RightToeBase"}
    renamed = layout.__class__(**{**layout.__dict__, "joint_names": tuple(f"j{i}" for i in range(layout.num_joints))})
    l2, r2 = representation.foot_joints(renamed)  # no names: the lowest joint on each side (toe end sites)
    rest = representation.rest_positions(layout)
    assert rest[l2, 1] == rest[:, 1].min() or rest[r2, 1] == rest[:, 1].min()
    assert np.sign(rest[l2, 0]) != np.sign(rest[r2, 0])
    # the hips for the facing metric: by name, else by the rest pose (left at +x)
    left, right = representation.facing_joints(layout)
    assert (layout.joint_names[left], layout.joint_names[right]) == ("LeftUpLeg", "RightUpLeg")
    l3, r3 = representation.facing_joints(renamed)
    assert rest[l3, 0] > 0 > rest[r3, 0] and layout.parents[l3] == layout.parents[r3] == 0


def test_heading_change_and_shape_curves():
    line = np.stack([np.zeros(50), np.zeros(50), np.linspace(0, 5, 50)], -1)
    assert eval_curves._heading_change_deg(line) == pytest.approx(0.0, abs=1e-9)
    t = np.linspace(0, np.pi / 2, 50)  # a quarter circle
    arc = np.stack([1 - np.cos(t), np.zeros(50), np.sin(t)], -1)
    assert eval_curves._heading_change_deg(arc) == pytest.approx(90.0, abs=3.0)
    shapes = eval_curves.shape_curves(15.0, 1.2, L=64, T=16)
    assert [c.name for c in shapes] == list(curves.SHAPES)
    for c in shapes:
        assert len(c.curve_Lx3) % 16 == 0 and len(c.curve_Lx3) <= 64
        np.testing.assert_allclose(c.curve_Lx3[0], 0.0, atol=1e-6)
        step = np.linalg.norm(np.diff(c.curve_Lx3, axis=0), axis=1)
        np.testing.assert_allclose(step, 1.2 / 15.0, rtol=0.05)


# ---------------------------------------------------------------------------------------------
# CLIs, end to end on the tiny config


def _load_cli(repo, name):
    return load_cli(name).main


@pytest.fixture(scope="module")
def tiny_run(random_tiny, tmp_path_factory):
    """A copy of conftest's random tiny run (the evaluator is written into it) with the
    config.json that training writes beside its checkpoints."""
    wd = tmp_path_factory.mktemp("eval_run") / "run"
    shutil.copytree(random_tiny, wd)
    _, meta = checkpoint.read_meta(checkpoint.manager(wd / "checkpoints"))
    (wd / "config.json").write_text(json.dumps(meta))
    return wd


def test_cli_train_evaluator_then_evaluate(repo, tiny_run, tmp_path, capsys):
    train_ev = _load_cli(repo, "train_evaluator")
    assert train_ev(["--workdir", str(tiny_run), "--steps", "20"]) == 0
    printed = capsys.readouterr().out
    assert "real held-out windows" in printed and "checksum" in printed
    ev = evaluator.load(tiny_run / "evaluator.npz")
    assert ev.meta["real_heldout"]["windows"] > 0

    assert train_ev(["--workdir", str(tiny_run), "--steps", "5", "--speed-free"]) == 0
    sf = evaluator.load(tiny_run / "evaluator_speed_free.npz")
    assert sf.meta["config"]["speed_free"] and sf.checksum in capsys.readouterr().out

    evaluate = _load_cli(repo, "evaluate")
    out = tmp_path / "eval"
    assert evaluate(["--workdir", str(tiny_run), "--out", str(out), "--seeds", "0,1,2", "--k", "3",
                     "--search-steps", "3", "--max-curves", "1", "--shapes", "line", "--realism-curves", "4",
                     "--stream-curves", "1"]) == 0
    report = json.loads((out / "report.json").read_text())
    h, r = report["header"], report["results"]
    assert h["evaluator_checksum"] == ev.checksum and h["checkpoint_step"] == 4
    assert h["g_params"] == "raw"  # the tiny run keeps no moving average
    assert h["feet"] == ["LeftToeBase", "RightToeBase"]
    assert len(h["curve_counts"]) == 2 and "synthetic" in h["curve_counts"]
    assert sum(h["curve_counts"].values()) == len(h["curves"])
    gen = r["generated"]
    for key in ("sra_top1", "fmd", "diversity", "multimodality", "traj_error_original_m", "foot_skate_original_m",
                "bone_length_error", "facing_error_deg", "jerk_ratio", "nearest_centroid_accuracy",
                "interp_monotonicity", "arithmetic_agreement"):
        assert key in gen and len(gen[key]["per_seed"]) == 3, key
    assert 0.0 <= gen["sra_top1"]["mean"] <= 1.0
    for p1, p2 in zip(gen["pca_explained_1"]["per_seed"], gen["pca_explained_2"]["per_seed"]):
        assert 0.0 < p1 <= p2 <= 1.0 + 1e-6
    # the real row: real motion has its own bone lengths and walks its own curve
    assert r["real"]["bone_length_error"] < 1e-3
    assert r["real"]["facing_error_deg"] < 10.0  # real walkers face where they go, up to pelvis sway
    assert r["real"]["path_length_ratio"] == pytest.approx(1.0, abs=0.05)
    assert r["real"]["jerk_ratio"] == 1.0
    # gait: the real held-out walks keep a foot down, lift their feet in turn, step at the embedded
    # styles' rates (0.6-1.3 gait cycles/s) and bounce a few centimetres
    assert r["contact_height_m"] == pytest.approx(0.02, abs=0.01)
    assert r["real"]["support"] > 0.95 and r["real"]["lower_foot_height_m"] < 0.005
    assert r["real"]["alternation"] > 0.4 and 0.6 < r["real"]["step_frequency_hz"] < 1.3
    assert 0.01 < r["real"]["root_height_range_m"] <= r["real"]["long_root_height_range_m"] < 0.15
    for key in ("support", "alternation", "step_frequency_hz", "long_support", "long_root_height_range_m"):
        assert len(gen[key]["per_seed"]) == 3, key
    for name, v in r["per_style"].items():  # the cadence compared on the paths of the same style's clips
        assert set(v["generated"]) >= {"step_frequency_same_curve_hz", "step_frequency_ratio", "support"}, name
    probe = r["discriminator_probe"]
    assert len(probe) == 5 and all(0.0 <= v["p_real"] <= 1.0 and 0.0 <= v["judged_real"] <= 1.0 for v in probe.values())
    assert np.asarray(r["confusion_generated"]).sum() > 0
    for f in ("report.md", "confusion.png", "pca_w.png"):
        assert (out / f).stat().st_size > 0
    md = (out / "report.md").read_text()
    assert ev.checksum in md and "| style accuracy top-1 (evaluator) |" in md
    assert "| support: frames with a toe within the contact height of the floor |" in md and "D's input" in md
    # realism, like for like: four held-out paths, both evaluators, every style swept over the speeds
    z = r["realism"]
    assert h["speed_free_evaluator_checksum"] == sf.checksum and z["speed_free_evaluator"]["checksum"] == sf.checksum
    assert z["paths"] == 4 and set(z["generated_tests_first_seed"]["tests"]) == {
        "posture", "gait", "speed", "all", "evaluator"}
    # one held-out clip per style: halves by path would hold different styles, so no real reference
    assert z["real_reference"] is None and "two_sample_gait" not in r["real"]
    for key in ("two_sample_gait", "two_sample_posture", "two_sample_all", "sra_top1_own_speed",
                "sra_top1_speed_free_own_speed", "sra_top1_speed_free_default_speed", "stride_speed_slope"):
        assert len(gen[key]["per_seed"]) == 3, key
    for g in ("gait", "posture", "speed", "all", "evaluator"):
        assert 0.0 <= gen[f"two_sample_{g}"]["mean"] <= 1.0
    # streaming: one held-out path walked whole and as a stream, per seed; the two agree (one walk:
    # the same G on the same path, code and phase), and the stream's seams are measured
    assert [b["seed"] for b in r["streaming"]] == [0, 1, 2] and all(b["curves"] == 1 for b in r["streaming"])
    for b in r["streaming"]:
        assert b["whole_support"] == pytest.approx(b["stream_support"], abs=0.2)
        assert np.isfinite(b["stream_max_rel_diff"]) and np.isfinite(b["stream_seam_jerk_ratio"])
    assert len(gen["stream_max_rel_diff"]["per_seed"]) == 3 and "## Streaming" in md
    styled = [v for v in r["per_style"].values() if "own_step_frequency_hz" in v["generated"]]
    assert len(styled) == len(r["per_style"])
    assert all(len(v["generated"]["step_frequency_hz@1.3"]["per_seed"]) == 3 for v in styled)
    # the real held-out clips' strides: counted gait cycles agree with the spectrum's distance per cycle
    clips = z["stride_clips"]
    assert len(clips) == len(h["val_files"])
    ratio = [c["counted_stride_m"] / c["distance_per_cycle_m"] for c in clips]
    assert np.median(ratio) == pytest.approx(1.0, abs=0.03)
    real_freq = [v["real"]["own_step_frequency_hz"] for v in r["per_style"].values()
                 if v["real"].get("own_step_frequency_hz") is not None]
    assert len(real_freq) == 4 and all(0.5 < f < 1.4 for f in real_freq)
    assert "## Realism, like for like" in md and "Features that separate most" in md


def test_cli_evaluate_errors(repo, tiny_run, tmp_path, capsys):
    evaluate = _load_cli(repo, "evaluate")
    assert evaluate(["--workdir", str(tiny_run), "--out", str(tmp_path / "o"),
                     "--evaluator", str(tmp_path / "none.npz")]) == 2
    assert "no such file" in capsys.readouterr().err
    assert evaluate(["--workdir", str(tmp_path / "nothing"), "--out", str(tmp_path / "o")]) == 2
    assert "no checkpoints" in capsys.readouterr().err
    assert evaluate(["--workdir", str(tiny_run), "--out", str(tmp_path / "o"), "--seeds", "a,b"]) == 2
    assert "--seeds" in capsys.readouterr().err
    assert evaluate(["--workdir", str(tiny_run), "--out", str(tmp_path / "o"), "--k", "1"]) == 2
    assert "--k >= 2" in capsys.readouterr().err  # one draw has no multimodality
    assert evaluate(["--out", str(tmp_path / "o")]) == 2  # the shipped model: no run to find an evaluator in
    assert "needs --evaluator" in capsys.readouterr().err
    assert evaluate(["--workdir", str(tiny_run), "--out", str(tmp_path / "o"),
                     "--speed-free-evaluator", str(tiny_run / "evaluator.npz")]) == 2
    assert "not a speed-free evaluator" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_gait_traces_and_plot_gait(repo, tiny_run, tmp_path, capsys):
    """plot_gait: per style, the toe heights of a held-out clip (as measured directly) beside G's on
    its path; the CLI writes the figure and refuses bad input with exit 2."""
    from motiongan_jax.data import clip_cache
    from motiongan_jax.generate import walk

    state, meta, cfg, layout = checkpoint.load_run(tiny_run)
    ds = clip_cache.load_dataset(cfg.data)
    feet = representation.foot_joints(layout)
    rate = walk.sample_rate(meta, cfg)
    traces = clip_metrics.gait_traces(state, cfg, layout, ds.val, tuple(meta["style_names"]), feet, rate, seconds=2.0)
    assert [t.style for t in traces] == sorted({c.label.style for c in ds.val})
    n = int(2.0 * rate) // 8 * 8
    for t in traces:
        chex.assert_shape((t.real_heights_Tx2, t.gen_heights_Tx2), (n, 2))
        clip = next(c for c in ds.val if c.source == t.source)
        step = cfg.data.frame_step
        real = np.asarray(representation.from_rows(clip.root_Fx3[: (n - 1) * step + 1: step],
                                                   clip.pose_FxR[: (n - 1) * step + 1: step], layout))
        np.testing.assert_allclose(t.real_heights_Tx2, gait.toe_heights(real[:, list(feet)]), atol=1e-9)
    plot = _load_cli(repo, "plot_gait")
    assert plot(["--workdir", str(tiny_run), "--out", str(tmp_path / "gait.png"), "--seconds", "2"]) == 0
    assert (tmp_path / "gait.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert plot(["--workdir", str(tiny_run), "--out", str(tmp_path / "g.png"), "--seconds", "-1"]) == 2
    assert plot(["--workdir", str(tmp_path / "none"), "--out", str(tmp_path / "g.png")]) == 2
    assert "error:" in capsys.readouterr().err and not (tmp_path / "g.png").exists()
