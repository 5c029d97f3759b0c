"""Style-space analysis and style search (motiongan_jax/analysis/, bin/analyze.py)."""

import dataclasses
import json
from pathlib import Path

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import load_cli

from motiongan_jax.analysis import (
    adain as adain_lib,
)
from motiongan_jax.analysis import (
    clips,
    style_space,
)
from motiongan_jax.analysis import (
    probe as probe_lib,
)
from motiongan_jax.analysis import (
    search as search_lib,
)
from motiongan_jax.data import curves, synthetic
from motiongan_jax.generate import styles as styles_lib
from motiongan_jax.generate import user_curves
from motiongan_jax.generate import walk as walk_lib
from motiongan_jax.model import apply as model_apply
from motiongan_jax.model import checkpoint, pretrained
from motiongan_jax.motion import bvh, kinematics, representation, trajectory


@pytest.fixture(scope="module")
def run(trained_tiny):
    """The tiny config trained for its 4 steps (conftest): (workdir, state, meta, cfg, layout)."""
    return (trained_tiny, *checkpoint.load_run(trained_tiny))


# ---------------------------------------------------------------------------------------------
# PCA, distances, nearest styles


def test_pca_matches_numpy_svd():
    rng = np.random.default_rng(0)
    X = rng.normal(size=(40, 6)) * np.array([5.0, 3.0, 2.0, 1.0, 0.5, 0.1]) @ np.linalg.qr(
        rng.normal(size=(6, 6)))[0] + 3.0
    p = style_space.pca(X)
    chex.assert_shape([p.components_KxD], (6, 6))
    chex.assert_shape([p.mean_D, p.explained_variance_ratio_K, p.singular_values_K], (6,))
    Xc = X - X.mean(0)
    _, S, Vt = np.linalg.svd(Xc, full_matrices=False)
    np.testing.assert_allclose(np.asarray(p.singular_values_K), S, rtol=1e-4)
    np.testing.assert_allclose(np.asarray(p.explained_variance_K), S**2 / (len(X) - 1), rtol=1e-4)
    np.testing.assert_allclose(np.asarray(p.explained_variance_ratio_K), S**2 / np.sum(S**2), rtol=1e-4, atol=1e-7)
    # components = numpy's up to sign; orthonormal; sign convention: largest entry positive
    comps = np.asarray(p.components_KxD)
    np.testing.assert_allclose(np.abs(comps @ Vt.T), np.eye(6), atol=1e-4)
    np.testing.assert_allclose(comps @ comps.T, np.eye(6), atol=1e-5)
    assert np.all(comps[np.arange(6), np.argmax(np.abs(comps), 1)] > 0)
    assert abs(float(np.sum(p.explained_variance_ratio_K)) - 1) < 1e-5
    # projection and exact reconstruction with every component
    Z = np.asarray(style_space.pca_transform(p, X))
    np.testing.assert_allclose(Z @ comps + np.asarray(p.mean_D), X, atol=1e-4)
    np.testing.assert_allclose(Z.var(0, ddof=1), np.asarray(p.explained_variance_K), rtol=1e-3)
    two = style_space.pca(X, 2)
    chex.assert_shape(two.components_KxD, (2, 6))
    assert float(np.sum(two.explained_variance_ratio_K)) < 1.0
    np.testing.assert_allclose(np.asarray(two.components_KxD), comps[:2], atol=1e-6)
    with pytest.raises(ValueError, match="num_components"):
        style_space.pca(X, 7)


def test_nearest_styles_on_hand_made_points():
    # on a line: A 0, B 1, C 3, D 7, E -0.5
    pts = np.array([[0.0, 0.0], [1.0, 0.0], [3.0, 0.0], [7.0, 0.0], [-0.5, 0.0]])
    names = ["A", "B", "C", "D", "E"]
    d = style_space.pairwise_distances(pts)
    np.testing.assert_allclose(np.asarray(d), np.abs(pts[:, None, 0] - pts[None, :, 0]), atol=1e-6)
    near = style_space.nearest_styles(d, names, k=3)
    got = {r["style"]: [n for n, _ in r["nearest"]] for r in near}
    assert got == {"A": ["E", "B", "C"], "B": ["A", "E", "C"], "C": ["B", "A", "E"],
                   "D": ["C", "B", "A"], "E": ["A", "B", "C"]}
    assert near[3]["nearest"][0][1] == pytest.approx(4.0)
    md = style_space.nearest_markdown(near)
    assert "| style | 1st | 2nd | 3rd |" in md and "| D | C (4) | B (6) | A (7) |" in md
    assert len([line for line in md.splitlines() if line.startswith("| ")]) == 1 + len(names)


def test_interpolate_mix_arithmetic_by_hand():
    a, b, c = jnp.array([1.0, 2.0]), jnp.array([3.0, -2.0]), jnp.array([0.5, 0.5])
    np.testing.assert_allclose(style_space.interpolate(a, b, 0.25), [1.5, 1.0])
    np.testing.assert_allclose(style_space.interpolate(a, b, jnp.array([0.0, 1.0])), [[1.0, 2.0], [3.0, -2.0]])
    np.testing.assert_allclose(style_space.mix(jnp.stack([a, b, c]), [0.5, 0.25, 0.25]), [1.375, 0.625])
    np.testing.assert_allclose(style_space.mix(jnp.stack([a, b]), [1.0, 3.0], normalize=True), [2.5, -1.0])
    np.testing.assert_allclose(style_space.arithmetic([("+", a), ("-", b), (1, c)]), [-1.5, 4.5])
    with pytest.raises(ValueError):
        style_space.arithmetic([(2, a)])


# ---------------------------------------------------------------------------------------------
# Linear probe


def test_probe_recovers_a_linear_map_and_not_noise():
    rng = np.random.default_rng(1)
    X = rng.normal(size=(120, 6))
    M, c = rng.normal(size=(6, 3)), np.array([1.0, -2.0, 0.5])
    Y = X @ M + c
    res = probe_lib.linear_probe(X, Y, folds=5)
    chex.assert_shape(res.pred_NxP, (120, 3))
    np.testing.assert_allclose(res.r2_P, 1.0, atol=1e-4)
    np.testing.assert_allclose(res.pred_NxP, Y, atol=1e-3)
    # grouped (leave-one-group-out), on raw codes
    groups = np.repeat(np.arange(8), 15)
    np.testing.assert_allclose(probe_lib.linear_probe(X, Y, groups_N=groups, components=None).r2_P, 1.0, atol=1e-4)
    noise = probe_lib.linear_probe(X, rng.normal(size=(120, 2)), folds=5)
    assert np.all(noise.r2_P < 0.1) and np.all(noise.r2_P > -0.3), noise.r2_P


# ---------------------------------------------------------------------------------------------
# On the trained tiny model


def test_style_codes_and_gait_parameters(run):
    _, state, meta, cfg, _ = run
    names = meta["style_names"]
    codes = style_space.label_codes(state, names, k=3, key=jax.random.key(2))
    D = cfg.model.w_dim
    chex.assert_shape(codes.zero_CxD, (len(names), D))
    chex.assert_shape(codes.samples_CxKxD, (len(names), 3, D))
    labels = jnp.arange(len(names))
    np.testing.assert_allclose(codes.zero_CxD, model_apply.generator(state).style(
        labels, jnp.zeros((len(names), cfg.model.z_dim))), rtol=1e-5, atol=1e-9)
    z = jax.random.normal(jax.random.key(5), (len(names), cfg.model.z_dim))
    w = styles_lib.latent_codes(state, labels, z)
    chex.assert_shape(w, (len(names), D))
    np.testing.assert_allclose(w, model_apply.generator(state).style(labels, z), rtol=1e-5, atol=1e-9)
    assert not np.allclose(w, codes.zero_CxD)  # z reaches w
    gait = probe_lib.gait_parameters(meta, cfg)
    assert gait["param_names"] == list(synthetic.PARAM_NAMES) + ["speed"]
    want = [[getattr(synthetic.STYLES[s], n) for n in synthetic.PARAM_NAMES] + [synthetic.STYLES[s].speed]
            for s in names]
    np.testing.assert_allclose(gait["style_YxP"], want)
    assert len(gait["clips"]) == 5 * len(names)
    report = probe_lib.probe_report(codes, gait)
    assert set(report["per_style"]["r2_cv"]) == set(synthetic.PARAM_NAMES) | {"speed"}
    assert report["per_sample"]["points"] == 3 * len(names)


def test_w_blend_equals_adain_blend(run):
    _, state, meta, cfg, _ = run
    T, D = 64, cfg.model.w_dim  # the shapes of the search tests: their compiled G is reused
    curve = jnp.cumsum(jax.random.normal(jax.random.key(0), (1, T, 3)).at[..., 1].set(0), axis=1)
    vel = np.asarray(trajectory.velocity(curve))
    # codes far apart (|w| ~ 1, not the ~1e-5 codes of a 4-step model), so that they matter
    ws = jax.random.normal(jax.random.key(1), (3, D))
    by_w_fn = lambda w: model_apply.apply_code(state, vel, w)  # noqa: E731
    adain_fn = jax.jit(adain_lib.generator_apply_adain)
    by_adain_fn = lambda adain: adain_fn(state, vel, adain)  # noqa: E731
    outs = [by_w_fn(ws[i:i + 1]) for i in range(3)]
    scale = float(jnp.abs(outs[0][1]).mean())
    assert float(jnp.abs(outs[0][1] - outs[1][1]).max()) > 0.05 * scale  # the codes change the output
    styles = [jax.jit(adain_lib.adain_styles)(state, ws[i:i + 1]) for i in range(3)]
    chex.assert_shape(styles[0]["ec0_0"][0], (1, cfg.model.base_channels))
    # the override path itself reproduces G exactly
    np.testing.assert_allclose(by_adain_fn(styles[0])[1], outs[0][1], atol=1e-6)
    for weights in ([0.2, 0.5, 0.3], [1.5, -0.25, -0.25]):  # sums to 1, incl. extrapolation
        by_w = by_w_fn(style_space.mix(ws, weights)[None])
        by_adain = by_adain_fn(adain_lib.blend_adain(styles, weights))
        for x, y in zip(by_w, by_adain):
            chex.assert_equal_shape([x, y])
            np.testing.assert_allclose(x, y, atol=2e-5, rtol=1e-4)
    # weights that do not sum to 1: the AdaIN biases a_s, a_b are counted twice, outputs differ
    by_w = by_w_fn(style_space.mix(ws, [1.0, 1.0, 0.0])[None])
    by_adain = by_adain_fn(adain_lib.blend_adain(styles, [1.0, 1.0, 0.0]))
    assert float(jnp.abs(by_w[1] - by_adain[1]).max()) > 0.01 * scale


def test_search_schedule_warms_up_below_the_peak():
    sched = search_lib.search_schedule(0.1, 100, 10)
    lrs = np.array([float(sched(i)) for i in range(100)])
    assert lrs[0] == pytest.approx(0.01) and lrs[0] < 0.1
    assert np.all(np.diff(lrs[:10]) > 0) and lrs[9] == pytest.approx(0.1) and lrs[10] == pytest.approx(0.1)
    assert np.all(np.diff(lrs[10:]) < 0) and lrs[-1] < 1e-3


def test_motion_windows_are_aligned_and_npz_matches_bvh(run, tmp_path):
    _, state, meta, cfg, layout = run
    clip = Path(meta["data_dir"]) / f"{meta['style_names'][0]}_01.bvh"
    T, step = cfg.data.window_T, cfg.data.frame_step
    win = clips.motion_windows(clip, meta, cfg, layout, max_windows=3)
    chex.assert_shape([win.root_NxTx3, win.curve_NxTx3], (3, T, 3))
    chex.assert_shape(win.pose_NxTxR, (3, T, layout.num_rows))
    assert win.frame_step == step and list(win.start_frames) == [0, T * step, 2 * T * step]
    # the curve starts at the root's floor position of the window's first frame, on the floor
    np.testing.assert_allclose(win.curve_NxTx3[:, 0, 0::2], win.root_NxTx3[:, 0, 0::2], atol=1e-5)
    assert float(jnp.abs(win.curve_NxTx3[..., 1]).max()) == 0.0
    # and ends at the last frame: the same frames as the motion samples
    np.testing.assert_allclose(win.curve_NxTx3[:, -1, 0::2], win.root_NxTx3[:, -1, 0::2], atol=1e-4)
    # an .npz of the full skeleton's world positions (frame 0, the T-pose, dropped as start_offset does)
    motion = bvh.read_bvh(clip)
    pos = kinematics.world_positions(motion)[cfg.data.start_offset:] * representation.UNITS_TO_M["synthetic"]
    np.savez(tmp_path / "clip.npz", positions=pos, joint_names=np.array(motion.skeleton.names), fps=motion.fps)
    win2 = clips.motion_windows(tmp_path / "clip.npz", meta, cfg, layout, max_windows=3)
    np.testing.assert_allclose(win2.pose_NxTxR, win.pose_NxTxR, atol=1e-5)
    np.testing.assert_allclose(win2.curve_NxTx3, win.curve_NxTx3, atol=1e-4)
    # a 2x frame rate doubles the frame step and keeps the windows' duration
    np.savez(tmp_path / "fast.npz", positions=np.repeat(pos, 2, axis=0), joint_names=np.array(motion.skeleton.names),
             fps=2 * motion.fps)
    assert clips.motion_windows(tmp_path / "fast.npz", meta, cfg, layout, max_windows=1).frame_step == 2 * step
    with pytest.raises(style_space.AnalysisError, match="joints"):
        np.savez(tmp_path / "bad.npz", positions=pos[:, :5])
        clips.motion_windows(tmp_path / "bad.npz", meta, cfg, layout)


def _windows(curve_NxTx3, root_vel_NxTx3, pose_NxTxR, phase_NxT=None):
    N, T = curve_NxTx3.shape[:2]
    phase = np.zeros((N, T), np.float32) if phase_NxT is None else np.asarray(phase_NxT, np.float32)
    return clips.MotionWindows(trajectory.integrate(curve_NxTx3[:, 0], root_vel_NxTx3), pose_NxTxR, curve_NxTx3,
                               np.zeros(N, int), 1, "test", phase, np.ones((N, T), bool))


def test_style_search_recovers_a_known_mix(run):
    """A target made by G with a known mix of three codes; the search recovers the mix; G untouched.

    The tiny model has no gait clock: the search compares phase-free window statistics of G's walk
    on its own clock ("stats"). Its codes after 4 steps are ~1e-5 apart and barely move G, so the
    known styles here are codes of size ~1.
    Windows of 64 samples (G is convolutional in time): at the tiny config's own T = 16, G's
    bottleneck instance norms see only 2 time samples and the loss is too rough to descend."""
    _, state, meta, cfg, layout = run
    T, N = 64, 1
    curve = jnp.cumsum(jax.random.normal(jax.random.key(3), (N, T, 3)).at[..., 1].set(0), axis=1)
    codes = np.asarray(jax.random.normal(jax.random.key(5), (3, cfg.model.w_dim)))
    mix = np.array([0.25, 0.75, 0.0])
    probe = _windows(curve, jnp.zeros((N, T, 3)), jnp.zeros((N, T, layout.num_rows)))
    rv, pose = search_lib.reconstruct(state, probe, mix @ codes)
    target = _windows(curve, rv, pose)
    before = jax.tree.map(np.array, state.g_params)
    found = search_lib.search_style(state, codes, ["a", "b", "c"], target, keep=2)
    assert found.loss_kind == "stats" and found.starts == ("b", "a")  # the screen ranks the styles
    # in units of the best known style's loss as it is: b's is 1, a's and c's more
    assert found.screen_C[1] == pytest.approx(1.0) and found.screen_C[0] > 1 and found.screen_C[2] > 1
    # window statistics do not pin a mix exactly (nearby mixes walk nearly alike): the found mix
    # is nearer the true one than any known style is, and fits better than any of them
    onehot = np.linalg.norm(np.eye(3) - mix, axis=1).min()
    assert np.linalg.norm(found.weights_C - mix) < 0.5 * onehot, (found.weights_C, mix)
    assert found.loss < 0.5, (found.screen_C, found.final_loss_K)
    np.testing.assert_allclose(found.w_D, found.weights_C @ codes, rtol=1e-5, atol=1e-6)
    assert found.nearest[0][0] == "b" and found.mix()[0][0] == "b"
    text = found.mix_text()
    assert styles_lib.parse_style(text, ["a", "b", "c"]).kind == "mix" and text.startswith("b:0.7")
    # rounded alone these weights sum to 0.999 (0.843 + 2 x 0.078), which the style language would
    # renormalise to 0.844: the largest takes the remainder, and the text reads back as itself
    odd = dataclasses.replace(found, weights_C=np.array([0.0783, 0.8434, 0.0783]))
    assert odd.mix() == [["b", 0.844], ["a", 0.078], ["c", 0.078]]
    assert styles_lib.parse_style(odd.mix_text(), ["a", "b", "c"]).text == odd.mix_text() == "b:0.844,a:0.078,c:0.078"
    chex.assert_shape(found.history_KxS, (2, search_lib.STEPS))
    jax.tree.map(np.testing.assert_array_equal, before, jax.tree.map(np.array, state.g_params))


def test_style_search_refuses_a_motion_without_steps(run):
    _, state, meta, cfg, layout = run
    T = cfg.data.window_T
    t = _windows(jnp.zeros((1, T, 3)), jnp.zeros((1, T, 3)), jnp.zeros((1, T, layout.num_rows)))
    t = dataclasses.replace(t, phase_valid_NxT=np.zeros((1, T), bool))
    codes = np.zeros((len(meta["style_names"]), cfg.model.w_dim), np.float32)
    with pytest.raises(ValueError, match="walks G at a measured phase, but this G has no gait clock"):
        search_lib.search_style(state, codes, meta["style_names"], t, loss="phase")
    with pytest.raises(ValueError, match="loss must be one of"):
        search_lib.search_style(state, codes, meta["style_names"], t, loss="nope")


# the shipped model's searches here: 3 of search.STEPS' 30 (each step is G's backward pass; the
# screen of every style as it is and a few steps find the styles below; docs/RESULTS.md measures the
# full search)
SEARCH_STEPS = 3


@pytest.fixture(scope="module")
def shipped():
    """The shipped model (a G with a gait clock) and the known styles' codes at z = 0."""
    state, meta, cfg, layout = pretrained.load_model()
    return state, meta, cfg, layout, np.asarray(style_space.label_codes(state, meta["style_names"], k=1).zero_CxD)


def test_search_finds_the_style_of_a_held_out_clip_from_any_gait_phase(shipped):
    """A clip of the embedded dataset the model never saw (trial 5), and the same with its start
    cut by half a gait cycle, so that every window starts elsewhere in the cycle: the same style
    is found both times (G walks each window at the clip's measured phase)."""
    state, meta, cfg, layout, codes = shipped
    names = meta["style_names"]
    root, pose, fps = clips.load_motion(synthetic.default_dataset_dir() / "OldMan_05.bvh", meta, cfg, layout)
    found = []
    for shift in (0, 33):  # frames at 60 fps: OldMan's gait cycle is about 66
        t = clips.model_rate_windows(root[shift:], pose[shift:], fps, meta, cfg, layout, spread=search_lib.WINDOWS,
                                     phase=True)
        chex.assert_shape(t.phase_NxT, (search_lib.WINDOWS, cfg.data.window_T))
        found.append(search_lib.search_style(state, codes, names, t, steps=SEARCH_STEPS))
    assert [f.loss_kind for f in found] == ["phase"] * 2
    assert [f.nearest[0][0] for f in found] == ["OldMan"] * 2, [f.mix() for f in found]
    weights = np.stack([f.weights_C for f in found])
    assert np.abs(weights - weights[0]).max() < 0.2, weights


def test_a_clip_on_another_skeleton_is_retargeted_onto_the_models(shipped, tmp_path):
    """A held-out clip written onto the SMPL rig (other joint names, metres, no clavicles) reads back
    through the retargeting as the model's rows: the root and the feet within 2 cm of the clip's own
    in every frame (the retargeting's round trip, tests/test_retarget.py).
    A skeleton whose legs match no built-in map is refused, naming the joints it lacks."""
    from motiongan_jax.motion import retarget, rigs

    state, meta, cfg, layout, codes = shipped
    path = synthetic.default_dataset_dir() / "OldMan_05.bvh"
    root, pose, fps = clips.load_motion(path, meta, cfg, layout)
    world = np.asarray(representation.from_rows(root, pose, layout))
    smpl = retarget.retarget(world, layout.joint_names, layout.parents, layout.rest_offsets_m,
                             rigs.load_rig("smpl"), fps)
    other = tmp_path / "oldman_smpl.bvh"
    bvh.write_bvh(other, smpl.motion)
    root2, pose2, fps2 = clips.load_motion(other, meta, cfg, layout)
    assert fps2 == pytest.approx(fps)
    F = min(len(root), len(root2))  # the start offset is taken from both files
    back = np.asarray(representation.from_rows(root2, pose2, layout))
    shift = len(root) - F
    feet = [layout.joint_names.index(n) for n in ("LeftToeBase", "RightToeBase", "LeftFoot", "RightFoot")]
    err = np.linalg.norm(back[-F:] - world[shift:][:F], axis=-1)
    assert err[:, 0].max() < 0.02 and err[:, feet].max() < 0.02, (err[:, 0].max(), err[:, feet].max())
    renamed = tmp_path / "renamed.bvh"
    renamed.write_text(other.read_text().replace("left_knee", "left_shin"))
    with pytest.raises(style_space.AnalysisError, match=r"renamed\.bvh: not the model's skeleton: .* lacks .*"
                                                         r"cannot be retargeted onto it: .*no joint for left knee"):
        clips.load_motion(renamed, meta, cfg, layout)


def test_search_finds_the_style_of_gs_own_walk_at_any_phase(shipped):
    """G walks a circle in a known style from two gait phases half a cycle apart; the search on its
    walk finds that style both times."""
    state, meta, cfg, layout, codes = shipped
    names = meta["style_names"]
    rate = walk_lib.sample_rate(meta, cfg)
    T = search_lib.WINDOWS * cfg.data.window_T
    pts = curves.shape_curve("circle", length=(T - 0.5) * 1.2 / rate, scale=3.0, num_points=400)
    curve = user_curves.prepare_curve(user_curves.Curve(pts, "circle"), rate, 1.2)
    c = names.index("Sneaky")
    gen = walk_lib.generate_motion(state, layout, curve, codes[[c, c]], np.array([0.0, np.pi], np.float32))
    for b in range(2):
        root = gen.positions[b, :, 0]
        pose = (gen.positions[b, :, 1:] - root[:, None]).reshape(len(root), -1)
        t = clips.model_rate_windows(root, pose, rate, meta, cfg, layout, spread=search_lib.WINDOWS, phase=True)
        found = search_lib.search_style(state, codes, names, t, steps=SEARCH_STEPS)
        assert found.nearest[0][0] == "Sneaky", found.mix()
    # a motion whose toes never alternate has no phase to walk at: refused, naming it
    still = dataclasses.replace(t, phase_valid_NxT=np.zeros_like(t.phase_valid_NxT))
    with pytest.raises(style_space.AnalysisError, match="no steps found"):
        search_lib.search_style(state, codes, names, still)


# ---------------------------------------------------------------------------------------------
# Command line


def _cli(repo):
    return load_cli("analyze")


def test_cli_writes_every_file(run, repo, tmp_path, capsys):
    wd, _, meta, _, layout = run
    clip = Path(meta["data_dir"]) / f"{meta['style_names'][1]}_02.bvh"
    out = tmp_path / "out"
    rc = _cli(repo).main(["--workdir", str(wd), "--out", str(out), "--k", "3", "--search", str(clip),
                          "--search-steps", "10", "--search-keep", "2", "--search-curve", "line"])
    assert rc == 0, capsys.readouterr().err
    for name in ("pca.png", "heatmap.png", "nearest.md", "analysis.json", "search.json", "search.npz"):
        assert (out / name).stat().st_size > 0, name
    report = json.loads((out / "analysis.json").read_text())
    C = len(meta["style_names"])
    assert report["pca"]["explained_variance_ratio"] and sum(report["pca"]["explained_variance_ratio"]) <= 1 + 1e-5
    assert np.asarray(report["distance"]["matrix"]).shape == (C, C)
    assert set(report["probe"]["per_style"]["r2_cv"]) == set(synthetic.PARAM_NAMES) | {"speed"}
    assert (out / "nearest.md").read_text().count("\n| ") == C + 1  # header + one row per style
    search = json.loads((out / "search.json").read_text())
    assert search["file_name_style"] == meta["style_names"][1] and len(search["nearest"]) == 3
    assert search["loss"] == "stats" and search["windows"] == search_lib.WINDOWS  # the tiny G has no gait clock
    assert search["window_T"] == run[3].data.window_T and len(search["starts"]) == 2
    assert search["final_loss"] <= min(search["screen_loss"].values()) * 1.001
    assert abs(sum(a for _, a in search["mix"]) - 1) < 0.01
    with np.load(out / "search.npz") as z:
        # the found code walks the whole line (one frame per curve sample, no multiple of 8 cut)
        # at the clip's speed, from (0, height, 0)
        Tw = z["positions"].shape[0]
        assert Tw == z["curve"].shape[0] and Tw >= 16 and z["w"].shape == (len(search["w"]),)
        chex.assert_shape([z["positions"]], (Tw, layout.num_joints, 3))
        np.testing.assert_allclose(z["root"][0], [0.0, search["walk"]["start_height_m"], 0.0], atol=1e-5)
        np.testing.assert_allclose(np.diff(z["curve"][:, 0]), search["speed_m_per_sample"], rtol=1e-3)


def test_cli_errors_are_messages(repo, tmp_path, capsys, run):
    cli = _cli(repo)
    assert cli.main(["--workdir", str(tmp_path / "nothing"), "--out", str(tmp_path / "o")]) == 2
    assert "no checkpoints" in capsys.readouterr().err
    blocker = tmp_path / "file"
    blocker.write_text("x")
    assert cli.main(["--workdir", str(run[0]), "--out", str(blocker / "sub"), "--k", "2"]) == 2
    assert "cannot write" in capsys.readouterr().err
