"""Generation: style specs, curves, G on long curves, root height, outputs and bin/generate.py.

The model is the tiny config's G and D with seeded random parameters, saved as a checkpoint
exactly as the training loop saves one (train.run_meta, checkpoint.save): generation only reads
a checkpoint, and this skips the data pipeline and the ~40 s of compiling and training (a
trained tiny model exercises nothing more here; tests/test_train.py covers training). G compiles once per (batch, T); the tests share
T = 96 (six times the window T 16) and batch 1 where they can.
"""

import importlib.util
import os
import re
import subprocess
import sys

import chex
import jax
import numpy as np
import pytest

from motiongan_jax import bvh, checkpoint, curves, generate as gen, ik, kinematics, representation, synthetic
from motiongan_jax import step as step_lib
from motiongan_jax.config import load_config, override, to_dict
from random_model import random_run as _random_run

T_LONG = 96
SPEED = 1.2


@pytest.fixture(scope="module")
def run_dir(repo, tmp_path_factory):
    return _random_run(load_config(repo / "configs" / "tiny.py"), tmp_path_factory.mktemp("gen_run"))


@pytest.fixture(scope="module")
def run(run_dir):
    return checkpoint.load_run(run_dir)


@pytest.fixture(scope="module")
def cli(repo):
    spec = importlib.util.spec_from_file_location("_generate_cli", repo / "bin" / "generate.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.main


NAMES = ("Childish", "Drunk", "Happy", "Marching", "Normal", "OldMan", "Sad", "Sneaky", "Strong")


def _line(T=T_LONG):
    """A straight curve that resamples to exactly T samples at SPEED and 15 Hz."""
    return gen.Curve(curves.shape_curve("line", scale=(T - 1) * SPEED / 15 + 1e-6), "line")


# ---------------------------------------------------------------------------------------------
# style specs


def test_parse_style_names_mixes_expressions_and_random():
    assert gen.parse_style("Happy", NAMES) == gen.StyleSpec("label", (("Happy", 1.0),), text="Happy")
    assert gen.parse_style(" happy ", NAMES).terms == (("Happy", 1.0),)
    mix = gen.parse_style("Sad:0.3, Happy:0.7", NAMES)
    assert mix.kind == "mix" and mix.terms == (("Sad", 0.3), ("Happy", 0.7))
    assert gen.parse_style("Sad:1,Happy:1", NAMES).terms == (("Sad", 0.5), ("Happy", 0.5))  # normalised
    expr = gen.parse_style("OldMan - Normal + Marching", NAMES)
    assert expr.kind == "expr" and expr.terms == (("OldMan", 1.0), ("Normal", -1.0), ("Marching", 1.0))
    assert expr.text == "OldMan - Normal + Marching"
    assert gen.parse_style("-Sad+0.5*Happy", NAMES).terms == (("Sad", -1.0), ("Happy", 0.5))
    # a style name containing '-' (Bandai's not-confident) is one operand
    bandai = ("normal", "not-confident", "proud")
    assert gen.parse_style("not-confident", bandai).terms == (("not-confident", 1.0),)
    assert gen.parse_style("proud - not-confident", bandai).terms == (("proud", 1.0), ("not-confident", -1.0))
    r0, r1 = (gen.parse_style("random", NAMES, seed=s) for s in (0, 0))
    assert r0 == r1 and r0.kind == "label" and r0.terms[0][0] in NAMES
    assert len({gen.parse_style("random", NAMES, seed=s).terms[0][0] for s in range(12)}) > 1


@pytest.mark.parametrize("text, match", [
    ("Hapy", r"unknown style 'Hapy'; did you mean 'Happy'\? Valid styles: Childish, Drunk"),
    ("Sad:0.5,Hapy:0.5", r"unknown style 'Hapy'; did you mean 'Happy'"),
    ("OldMan - Nrmal", r"unknown style 'Nrmal'; did you mean 'Normal'"),
    ("Sad:", "malformed mix 'Sad:': weight of 'Sad'"),
    ("Sad:x,Happy:1", "malformed mix .* 'x' is not a number"),
    ("Sad:0.5,,Happy:0.5", "malformed mix .*empty entry"),
    ("Sad,Happy", "malformed mix 'Sad,Happy': entry 'Sad' is not Name:weight"),
    ("Sad:1,Sad:2", "a style appears twice"),
    ("Sad:1,Happy:-1", "sum to 0"),
    ("Sad +", "malformed expression 'Sad \\+': ends with an operator"),
    ("Sad + - Happy", "malformed expression .*expected a style name at position 7"),
    ("Sad Happy", "unknown style 'Sad Happy'; did you mean 'Happy'"),
    ("", "empty style"),
    ("missing.npy", "style file 'missing.npy' not found"),
])
def test_parse_style_errors_name_the_problem(text, match):
    with pytest.raises(gen.StyleError, match=match):
        gen.parse_style(text, NAMES)


def test_style_codes_mix_endpoints_are_exact_and_arithmetic_is_in_w(run, tmp_path):
    state, meta, _, _ = run
    names = meta["style_names"]
    specs = [gen.parse_style(s, names) for s in
             ("Sad", "Happy", "Sad:1,Happy:0", "Sad:0,Happy:1", "Sad:0.5,Happy:0.5",
              "OldMan - Normal + Marching", "OldMan", "Normal", "Marching")]
    w = gen.style_codes(state, specs, names)
    chex.assert_shape(w, (len(specs), gen.w_dim(state)))
    np.testing.assert_array_equal(w[2], w[0])  # α = 0: style A's w exactly
    np.testing.assert_array_equal(w[3], w[1])
    np.testing.assert_allclose(w[4], (w[0].astype(float) + w[1]) / 2, rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(w[5], w[6].astype(float) - w[7] + w[8], rtol=1e-6, atol=1e-12)
    # the same as the Latent Transform with z = 0
    direct = np.asarray(step_lib.latent_w(state, np.array([names.index("Sad")])))[0]
    np.testing.assert_allclose(w[0], direct, rtol=1e-6, atol=1e-12)
    # a raw w file, and one of the wrong size (incompatible with this checkpoint)
    np.save(tmp_path / "w.npy", w[1])
    np.testing.assert_array_equal(gen.style_codes(state, [gen.parse_style(str(tmp_path / "w.npy"), names)], names)[0], w[1])
    np.savetxt(tmp_path / "bad.txt", np.zeros(gen.w_dim(state) + 3))
    with pytest.raises(gen.StyleError, match=f"has {gen.w_dim(state) + 3} values.*w has {gen.w_dim(state)}"):
        gen.style_codes(state, [gen.parse_style(str(tmp_path / "bad.txt"), names)], names)
    # z modes
    z_dim = step_lib.generator_z_dim(state)
    chex.assert_shape(gen.z_codes(state, "zero"), (1, z_dim))
    assert not np.any(gen.z_codes(state, "zero"))
    np.testing.assert_array_equal(gen.z_codes(state, "seed", 3), gen.z_codes(state, "seed", 3))
    chex.assert_shape(gen.z_codes(state, "3", 0), (3, z_dim))
    chex.assert_shape(gen.style_codes(state, specs[:2], names, gen.z_codes(state, 3)), (6, gen.w_dim(state)))
    with pytest.raises(gen.GenerateError, match="--z must be"):
        gen.z_codes(state, "lots")


# ---------------------------------------------------------------------------------------------
# curves


def test_prepare_curve_spacing_trimming_and_extension():
    notes = []
    c = gen.prepare_curve(_line(), 15.0, SPEED, log=notes.append)
    chex.assert_shape(c, (T_LONG, 3))
    assert c.dtype == np.float32 and not np.any(c[:, 1])
    np.testing.assert_allclose(np.linalg.norm(np.diff(c, axis=0), axis=1), SPEED / 15, rtol=1e-5)
    assert "96 samples" in notes[0] and "trimmed" not in notes[0]
    c = gen.prepare_curve(_line(T_LONG + 5), 15.0, SPEED, log=notes.append)
    assert len(c) == T_LONG and "trimmed to 96" in notes[-1] and "5 samples" in notes[-1]
    c = gen.prepare_curve(gen.Curve(np.array([[0.0, 0.0], [0.5, 0.0]]), "short"), 15.0, SPEED, log=notes.append)
    assert len(c) == gen.MIN_T and "extended" in notes[-1]
    np.testing.assert_allclose(np.diff(c[:, 0]), SPEED / 15, rtol=1e-5)
    c = gen.prepare_curve(gen.load_curve("circle", scale=1.0), 15.0, 0.6)  # speed sets the spacing
    np.testing.assert_allclose(np.linalg.norm(np.diff(c, axis=0), axis=1), 0.04, rtol=1e-3)
    with pytest.raises(gen.GenerateError, match="speed must be"):
        gen.prepare_curve(_line(), 15.0, -1.0)


def test_bad_curves_are_clear_errors(tmp_path):
    (tmp_path / "empty.csv").write_text("# nothing\n")
    (tmp_path / "same.csv").write_text("1,1\n1,1\n1,1\n")
    (tmp_path / "tiny.json").write_text("[[0, 0], [0.01, 0]]")
    with pytest.raises(curves.CurveFileError, match="empty.csv: no x,z rows"):
        gen.load_curve(str(tmp_path / "empty.csv"))
    with pytest.raises(curves.DegenerateCurveError, match="zero length"):
        gen.load_curve(str(tmp_path / "same.csv"))
    with pytest.raises(curves.DegenerateCurveError, match="shorter than one spacing"):
        gen.prepare_curve(gen.load_curve(str(tmp_path / "tiny.json")), 15.0, SPEED)
    with pytest.raises(gen.GenerateError, match="not a shape name .*no such file"):
        gen.load_curve("squiggle")
    with pytest.raises(gen.GenerateError, match="scale must be"):
        gen.load_curve("circle", scale=0)


def test_bvh_curve_uses_the_pelvis_path_at_its_own_speed(tmp_path):
    motion = synthetic.generate_clip(synthetic.STYLES["Normal"], key_or_seed=0, num_frames=240)
    bvh.write_bvh(tmp_path / "walk.bvh", motion)
    c = gen.load_curve(str(tmp_path / "walk.bvh"), control_seconds=2.0)
    assert c.smooth_interval == 120 and len(c.points) == 240
    assert c.speed_m_per_s == pytest.approx(synthetic.STYLES["Normal"].speed, rel=0.1)


# ---------------------------------------------------------------------------------------------
# generation


def test_a_curve_six_windows_long_walks_on_the_floor(run):
    state, meta, cfg, layout = run
    assert cfg.data.window_T == 16 and gen.sample_rate(meta, cfg) == 15.0
    curve = gen.prepare_curve(_line(), gen.sample_rate(meta, cfg), SPEED)
    w = gen.style_codes(state, [gen.parse_style("Happy", meta["style_names"])], meta["style_names"])
    out = gen.generate_motion(state, layout, curve, w)
    J = layout.num_joints
    chex.assert_shape(out.positions, (1, T_LONG, J, 3))
    chex.assert_shape(out.root_velocity, (1, T_LONG, 3))
    chex.assert_shape(out.pose, (1, T_LONG, 3 * (J - 1)))
    chex.assert_tree_all_finite((out.positions, out.floor_shift_m))
    lowest = out.positions[0, :, :, 1].min(axis=-1)
    assert np.percentile(lowest, gen.FLOOR_PERCENTILE) == pytest.approx(0.0, abs=1e-9)
    # the root starts at the curve's start on the floor plan and follows G's velocity after it
    np.testing.assert_allclose(out.positions[0, 0, 0, [0, 2]], curve[0, [0, 2]], atol=1e-6)
    np.testing.assert_allclose(np.diff(out.positions[0, :, 0], axis=0), out.root_velocity[0, 1:], atol=1e-9)
    # the root is curves.integrate from the curve start (y = 0), lifted by the floor shift
    root = np.asarray(curves.integrate(curve[:1] * [1, 0, 1], out.root_velocity.astype(np.float32)))[0]
    np.testing.assert_allclose(out.positions[0, :, 0] - [0, out.floor_shift_m[0], 0], root, rtol=1e-5, atol=1e-4)
    with pytest.raises(gen.GenerateError, match="multiple of 8"):
        gen.generate_motion(state, layout, curve[:90], w)


def test_figures_panels():
    interp = gen.figure_specs("interp", "Sad, Happy", NAMES)
    assert [s.terms for _, s in interp] == [(("Sad", 1 - a), ("Happy", a)) for a in gen.INTERP_ALPHAS]
    arith = gen.figure_specs("arith", "OldMan - Normal + Marching", NAMES)
    assert [t for t, _ in arith] == ["OldMan", "Normal", "Marching", "OldMan - Normal + Marching"]
    assert [t for t, _ in gen.figure_specs("styles", None, NAMES)] == list(NAMES)
    assert [t for t, _ in gen.figure_specs("styles", "Sad,Happy", NAMES)] == ["Sad", "Happy"]
    with pytest.raises(gen.StyleError, match="two styles"):
        gen.figure_specs("interp", "Sad", NAMES)
    with pytest.raises(gen.StyleError, match="expression"):
        gen.figure_specs("arith", "Sad", NAMES)


# ---------------------------------------------------------------------------------------------
# the command line


def test_cli_npz_subprocess_then_bvh_round_trip(repo, run_dir, cli, tmp_path, capsys):
    """One real subprocess (.npz); the .bvh of the same motion in-process; FK of the re-read BVH
    matches the npz's skeleton positions and the generated bone directions."""
    csv = tmp_path / "path.csv"
    length = (T_LONG - 1) * SPEED / 15 + 1e-6
    csv.write_text("x,z\n" + "".join(f"{x},0\n" for x in np.linspace(0, length, 20)))
    common = ["--workdir", str(run_dir), "--style", "Sad:0.3,Happy:0.7", "--curve", str(csv)]
    res = subprocess.run([sys.executable, str(repo / "bin" / "generate.py"), *common,
                          "--out", str(tmp_path / "walk.npz")], capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == str(tmp_path / "walk.npz")
    assert "96 samples" in res.stderr
    z = np.load(tmp_path / "walk.npz")
    J = len(z["joint_names"])
    chex.assert_shape([z["positions"], z["positions_skeleton"]], (T_LONG, J, 3))
    chex.assert_shape(z["curve"], (T_LONG, 3))
    assert list(z["parents"]) == list(checkpoint.load_run(run_dir)[3].parents)
    assert float(z["fps"]) == 15.0 and str(z["style"]) == "Sad:0.3,Happy:0.7"

    assert cli([*common, "--out", str(tmp_path / "walk.bvh"), "--bvh-units", "cm"]) == 0
    motion = bvh.read_bvh(tmp_path / "walk.bvh")
    assert motion.frame_time == pytest.approx(1 / 15)
    layout = representation.layout_from_skeleton(motion.skeleton, 0.01)
    assert layout.joint_names == tuple(z["joint_names"])
    world = kinematics.world_positions(motion)[:, list(layout.source_index)] * 0.01
    np.testing.assert_allclose(world, z["positions_skeleton"], atol=1e-5)
    angle = np.arctan2(*[f(ik.bone_directions(world, layout.parents), ik.bone_directions(z["positions"], layout.parents))
                         for f in (lambda a, b: np.linalg.norm(np.cross(a, b), axis=-1),
                                   lambda a, b: np.sum(a * b, axis=-1))])
    assert angle.max() < 1e-4  # measured 5e-8 rad (BVH text: 6 decimals of cm and degrees)
    np.testing.assert_allclose(representation.bone_lengths(
        (world[:, 1:] - world[:, :1]).reshape(T_LONG, -1), layout), np.broadcast_to(layout.bone_lengths_m, (T_LONG, J - 1)),
        atol=1e-6)


def test_cli_params_choose_the_moving_average_or_the_raw_g(repo, cli, tmp_path):
    cfg = override(load_config(repo / "configs" / "tiny.py"), ["train.g_ema_decay=0.999"])
    wd = _random_run(cfg, tmp_path / "run")  # g_ema_params random too, so unlike g_params
    common = ["--workdir", str(wd), "--style", "Happy", "--curve", "line", "--length", str((T_LONG - 1) * SPEED / 15 + 1e-6)]
    out = {}
    for name, extra in (("default", []), ("ema", ["--params", "ema"]), ("raw", ["--params", "raw"])):
        assert cli([*common, *extra, "--out", str(tmp_path / f"{name}.npz")]) == 0
        out[name] = np.load(tmp_path / f"{name}.npz")["positions"]
    np.testing.assert_array_equal(out["default"], out["ema"])
    assert np.abs(out["ema"] - out["raw"]).max() > 1e-3
    # the same as a run without an average whose G holds the average's values
    raw, meta, plain_cfg, _ = checkpoint.load_run(wd, params="raw")
    plain_cfg = override(plain_cfg, ["train.g_ema_decay=0.0"])
    plain = raw.replace(g_params=raw.g_ema_params, g_ema_params=None)
    checkpoint.save(checkpoint.manager(tmp_path / "plain" / "checkpoints"), 4, plain,
                    {**meta, "config": to_dict(plain_cfg)})
    assert cli([*common, "--workdir", str(tmp_path / "plain"), "--out", str(tmp_path / "plain.npz")]) == 0
    np.testing.assert_array_equal(np.load(tmp_path / "plain.npz")["positions"], out["ema"])


def test_a_checkpoint_from_before_the_moving_average_still_loads(run_dir, run, tmp_path):
    """Checkpoints saved before TrainState had g_ema_params hold the other fields only."""
    state, meta = run[0], checkpoint.read_meta(checkpoint.manager(run_dir / "checkpoints"))[1]
    older = {f: getattr(state, f) for f in ("g_params", "d_params", "d_sn_state", "opt_g_state", "opt_d_state", "step")}
    checkpoint.save(checkpoint.manager(tmp_path / "checkpoints"), 4, older, meta)
    loaded = checkpoint.load_run(tmp_path)[0]
    assert loaded.g_ema_params is None
    for a, b in zip(jax.tree.leaves(loaded), jax.tree.leaves(state), strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    # a run that keeps an average cannot resume from it: the error names the checkpoint
    cfg = override(run[2], ["train.g_ema_decay=0.9"])
    like = jax.eval_shape(lambda: step_lib.init_state(cfg, run[3], len(NAMES), jax.random.key(0)))
    with pytest.raises(checkpoint.CheckpointError, match="does not fit this model"):
        checkpoint.restore(checkpoint.manager(tmp_path / "checkpoints"), 4, like)


def test_cli_gif_and_list_styles(run_dir, cli, tmp_path, capsys):
    out = tmp_path / "walk.gif"
    args = ["--workdir", str(run_dir), "--style", "Happy", "--curve", "line", "--length",
            str((T_LONG - 1) * SPEED / 15 + 1e-6), "--out", str(out)]
    assert cli(args) == 0
    from PIL import Image

    with Image.open(out) as im:
        assert im.n_frames == T_LONG
    capsys.readouterr()
    assert cli(["--workdir", str(run_dir), "--list-styles"]) == 0
    assert capsys.readouterr().out.split() == list(NAMES)


def test_cli_figure_png(run_dir, cli, tmp_path):
    out = tmp_path / "interp.png"
    assert cli(["--workdir", str(run_dir), "--figure", "interp", "--style", "Sad,Happy", "--curve", "line",
                "--length", str((T_LONG - 1) * SPEED / 15 + 1e-6), "--out", str(out)]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize("extra, out_name, match", [
    (["--style", "Hapy"], "a.bvh", "unknown style 'Hapy'; did you mean 'Happy'"),
    (["--style", "Sad:0.5,Happy"], "a.npz", "malformed mix"),
    (["--style", "Sad + "], "a.npz", "malformed expression"),
    (["--style", "W.npy"], "a.bvh", "w has 8"),
    (["--curve", "EMPTY.csv"], "a.bvh", "no x,z rows"),
    (["--curve", "SAME.csv"], "a.bvh", "zero length"),
    (["--workdir", "NOWHERE"], "a.bvh", "no checkpoints in"),
    ([], "no_dir/a.bvh", "directory .*no_dir does not exist"),
    ([], "a.avi", "unsupported format '.avi'"),
    ([], "/proc/a.bvh", "cannot write /proc/a.bvh: directory /proc (is not writable|does not exist)"),
])
def test_cli_errors_exit_non_zero_and_leave_no_file(run_dir, cli, tmp_path, capsys, extra, out_name, match):
    (tmp_path / "EMPTY.csv").write_text("")
    (tmp_path / "SAME.csv").write_text("0,0\n0,0\n")
    np.save(tmp_path / "W.npy", np.zeros(5))
    args = {"--workdir": str(run_dir), "--style": "Happy", "--curve": "line"}
    for k, v in zip(extra[::2], extra[1::2]):
        args[k] = str(tmp_path / v) if v.isupper() or v.endswith((".npy", ".csv")) else v
    argv = [x for kv in args.items() for x in kv] + ["--out", str(tmp_path / out_name)]
    before = set(p.name for p in tmp_path.iterdir())
    assert cli(argv) == 2
    err = capsys.readouterr().err
    assert err.splitlines()[-1].startswith("error: ") and re.search(match, err), err
    assert set(p.name for p in tmp_path.iterdir()) == before  # nothing written, no temp file


def test_cli_mp4_without_ffmpeg_is_a_clear_error(run_dir, cli, tmp_path, capsys, monkeypatch):
    import shutil

    monkeypatch.setattr(shutil, "which", lambda name: None)
    monkeypatch.setitem(sys.modules, "imageio_ffmpeg", None)
    assert cli(["--workdir", str(run_dir), "--style", "Happy", "--curve", "line", "--out",
                str(tmp_path / "a.mp4")]) == 2
    assert "needs ffmpeg" in capsys.readouterr().err
    assert not list(tmp_path.iterdir())


def _ffmpeg_or_skip():
    from motiongan_jax import viz

    try:
        viz.video_writer("probe.mp4", 15.0)
    except RuntimeError as e:  # neither an ffmpeg on PATH nor imageio-ffmpeg (the viz extra)
        pytest.skip(str(e))


def _frames(path):
    """Frames in a video, counted by imageio-ffmpeg (None without it)."""
    try:
        import imageio_ffmpeg
    except ImportError:
        return None
    return imageio_ffmpeg.count_frames_and_secs(str(path))[0]


def test_mp4_few_frames_odd_pixel_size_written_atomically(tmp_path):
    """6 frames at 183 x 183 pixels: H.264 in yuv420p needs even sizes, which the writer rounds."""
    from motiongan_jax import viz

    _ffmpeg_or_skip()
    joints = np.zeros((6, 3, 3))
    joints[:, 1, 1], joints[:, 2, 1] = 0.5, 1.0
    joints[:, :, 0] += np.arange(6)[:, None] * 0.1
    out = viz.animate_motions([joints], [-1, 0, 1], ["stick"], tmp_path / "a.mp4", fps=15, size=3, dpi=61)
    data = out.read_bytes()
    assert data[4:8] == b"ftyp"  # an ISO base media (MP4) file starts with its ftyp box
    assert _frames(out) in (None, 6)
    assert [p.name for p in tmp_path.iterdir()] == ["a.mp4"]  # no temporary file left


def test_cli_mp4(run_dir, cli, tmp_path, capsys):
    _ffmpeg_or_skip()
    out = tmp_path / "walk.mp4"
    assert cli(["--workdir", str(run_dir), "--style", "Happy", "--curve", "line", "--length",
                str((T_LONG - 1) * SPEED / 15 + 1e-6), "--out", str(out)]) == 0
    assert capsys.readouterr().out.strip() == str(out)
    assert out.read_bytes()[4:8] == b"ftyp"
    assert _frames(out) in (None, T_LONG)
    assert [p.name for p in tmp_path.iterdir()] == ["walk.mp4"]


def test_cli_mp4_failing_ffmpeg_is_a_clear_error(run_dir, cli, tmp_path, capsys, monkeypatch):
    import shutil

    if not os.access("/bin/false", os.X_OK):
        pytest.skip("no /bin/false to stand in for a broken ffmpeg")
    monkeypatch.setattr(shutil, "which", lambda name: "/bin/false")
    assert cli(["--workdir", str(run_dir), "--style", "Happy", "--curve", "line", "--out",
                str(tmp_path / "a.mp4")]) == 2
    assert re.search(r"error: .*a\.mp4: ffmpeg \(/bin/false\) failed with exit status 1", capsys.readouterr().err)
    assert not list(tmp_path.iterdir())


def test_unwritable_output_leaves_nothing(run, tmp_path):
    state, meta, cfg, layout = run
    (tmp_path / "file").write_text("")
    with pytest.raises(gen.GenerateError, match="is not a directory"):
        gen.check_output_path(tmp_path / "file" / "a.bvh")
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        if not os.access(ro, os.W_OK):  # (root may write anywhere)
            with pytest.raises(gen.GenerateError, match="not writable"):
                gen.check_output_path(ro / "a.bvh")
    finally:
        ro.chmod(0o700)
    # a failure while writing (here: non-finite positions) leaves no file and no temp file
    bad = gen.Generated(np.full((1, 16, layout.num_joints, 3), np.nan), None, None,
                        np.zeros((16, 3), np.float32), np.zeros((1, 8), np.float32), np.zeros(1))
    for name in ("a.bvh", "a.npz"):
        with pytest.raises(ik.IKError):
            gen.write_outputs(tmp_path / name, bad, ["x"], layout, 15.0)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file", "ro"]
