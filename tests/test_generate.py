"""Generation: style specs, curves, G on long curves, root height, outputs and bin/generate.py.

The model is conftest's random_tiny: the tiny config's G and D with seeded random parameters,
saved as a checkpoint exactly as the training loop saves one (train.run_meta, checkpoint.save).
Generation only reads a checkpoint, and this skips the ~40 s of compiling and training (a trained
tiny model exercises nothing more here; tests/test_train.py covers training). G compiles once per
(batch, T); the tests share T = 96 (six times the window T 16) and batch 1 where they can.
"""

import os
import re
import subprocess
import sys

import chex
import jax
import numpy as np
import pytest
from conftest import FAST, load_cli
from conftest import random_run as _random_run

from motiongan_jax.config import load_config, override, to_dict
from motiongan_jax.data import curves, synthetic
from motiongan_jax.generate import limits, styles, user_curves, walk, writers
from motiongan_jax.model import apply as model_apply
from motiongan_jax.model import checkpoint, pretrained
from motiongan_jax.model import state as model_state
from motiongan_jax.motion import bvh, ik, kinematics, representation, trajectory

T_LONG = 96
SPEED = 1.2


@pytest.fixture(scope="module")
def run_dir(random_tiny):
    return random_tiny


@pytest.fixture(scope="module")
def run(run_dir):
    return checkpoint.load_run(run_dir)


@pytest.fixture(scope="module")
def cli():
    return load_cli("generate").main


NAMES = ("Childish", "Drunk", "Happy", "Marching", "Normal", "OldMan", "Sad", "Sneaky", "Strong")


def _line(T=T_LONG):
    """A straight curve that resamples to exactly T samples at SPEED and 15 Hz."""
    return user_curves.Curve(curves.shape_curve("line", scale=(T - 1) * SPEED / 15 + 1e-6), "line")


# ---------------------------------------------------------------------------------------------
# style specs


def test_parse_style_names_mixes_expressions_and_random():
    assert styles.parse_style("Happy", NAMES) == styles.StyleSpec("label", (("Happy", 1.0),), text="Happy")
    assert styles.parse_style(" happy ", NAMES).terms == (("Happy", 1.0),)
    mix = styles.parse_style("Sad:0.3, Happy:0.7", NAMES)
    assert mix.kind == "mix" and mix.terms == (("Sad", 0.3), ("Happy", 0.7))
    assert styles.parse_style("Sad:1,Happy:1", NAMES).terms == (("Sad", 0.5), ("Happy", 0.5))  # normalised
    expr = styles.parse_style("OldMan - Normal + Marching", NAMES)
    assert expr.kind == "expr" and expr.terms == (("OldMan", 1.0), ("Normal", -1.0), ("Marching", 1.0))
    assert expr.text == "OldMan - Normal + Marching"
    assert styles.parse_style("-Sad+0.5*Happy", NAMES).terms == (("Sad", -1.0), ("Happy", 0.5))
    # a style name containing '-' (Bandai's not-confident) is one operand
    bandai = ("normal", "not-confident", "proud")
    assert styles.parse_style("not-confident", bandai).terms == (("not-confident", 1.0),)
    assert styles.parse_style("proud - not-confident", bandai).terms == (("proud", 1.0), ("not-confident", -1.0))
    r0, r1 = (styles.parse_style("random", NAMES, seed=s) for s in (0, 0))
    assert r0 == r1 and r0.kind == "label" and r0.terms[0][0] in NAMES
    assert len({styles.parse_style("random", NAMES, seed=s).terms[0][0] for s in range(12)}) > 1


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
    with pytest.raises(styles.StyleError, match=match):
        styles.parse_style(text, NAMES)


def test_style_codes_mix_endpoints_are_exact_and_arithmetic_is_in_w(run, tmp_path):
    state, meta, _, _ = run
    names = meta["style_names"]
    specs = [styles.parse_style(s, names) for s in
             ("Sad", "Happy", "Sad:1,Happy:0", "Sad:0,Happy:1", "Sad:0.5,Happy:0.5",
              "OldMan - Normal + Marching", "OldMan", "Normal", "Marching")]
    w = styles.spec_codes(state, specs, names)
    chex.assert_shape(w, (len(specs), styles.w_dim(state)))
    np.testing.assert_array_equal(w[2], w[0])  # α = 0: style A's w exactly
    np.testing.assert_array_equal(w[3], w[1])
    np.testing.assert_allclose(w[4], (w[0].astype(float) + w[1]) / 2, rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(w[5], w[6].astype(float) - w[7] + w[8], rtol=1e-6, atol=1e-12)
    # the same as the Latent Transform with z = 0
    direct = np.asarray(model_apply.style_codes(state, np.array([names.index("Sad")])))[0]
    np.testing.assert_allclose(w[0], direct, rtol=1e-6, atol=1e-12)
    # a raw w file, and one of the wrong size (incompatible with this checkpoint)
    np.save(tmp_path / "w.npy", w[1])
    np.testing.assert_array_equal(
        styles.spec_codes(state, [styles.parse_style(str(tmp_path / "w.npy"), names)], names)[0], w[1])
    np.savetxt(tmp_path / "bad.txt", np.zeros(styles.w_dim(state) + 3))
    with pytest.raises(styles.StyleError, match=f"has {styles.w_dim(state) + 3} values.*w has {styles.w_dim(state)}"):
        styles.spec_codes(state, [styles.parse_style(str(tmp_path / "bad.txt"), names)], names)
    # z modes
    z_dim = model_apply.z_dim(state)
    chex.assert_shape(styles.z_codes(state, "zero"), (1, z_dim))
    assert not np.any(styles.z_codes(state, "zero"))
    np.testing.assert_array_equal(styles.z_codes(state, "seed", 3), styles.z_codes(state, "seed", 3))
    chex.assert_shape(styles.z_codes(state, "3", 0), (3, z_dim))
    chex.assert_shape(styles.spec_codes(state, specs[:2], names, styles.z_codes(state, 3)), (6, styles.w_dim(state)))
    with pytest.raises(limits.GenerateError, match="--z must be"):
        styles.z_codes(state, "lots")


# ---------------------------------------------------------------------------------------------
# curves


def test_prepare_curve_spacing_keeps_every_sample():
    notes = []
    c = user_curves.prepare_curve(_line(), 15.0, SPEED, log=notes.append)
    chex.assert_shape(c, (T_LONG, 3))
    assert c.dtype == np.float32 and not np.any(c[:, 1])
    np.testing.assert_allclose(np.linalg.norm(np.diff(c, axis=0), axis=1), SPEED / 15, rtol=1e-5)
    assert "96 samples" in notes[0] and "walked in full" not in notes[0]
    # 101 samples: all kept (the whole curve is walked); G will run on 104
    c = user_curves.prepare_curve(_line(T_LONG + 5), 15.0, SPEED, log=notes.append)
    assert len(c) == T_LONG + 5 and "101 samples" in notes[-1] and "cropped back to its 101 samples" in notes[-1]
    assert walk.padded_length(101) == 104 and walk.padded_length(96) == 96 and walk.padded_length(3) == walk.MIN_T
    c = user_curves.prepare_curve(user_curves.Curve(np.array([[0.0, 0.0], [0.5, 0.0]]), "short"), 15.0, SPEED,
                                  log=notes.append)
    assert len(c) == 7 and f"at least {walk.MIN_T}" in notes[-1]  # 0.5 m at 8 cm: 0, 0.08, ..., 0.48
    np.testing.assert_allclose(np.diff(c[:, 0]), SPEED / 15, rtol=1e-5)
    c = user_curves.prepare_curve(user_curves.load_curve("circle", scale=1.0), 15.0, 0.6)  # speed sets the spacing
    np.testing.assert_allclose(np.linalg.norm(np.diff(c, axis=0), axis=1), 0.04, rtol=1e-3)
    with pytest.raises(limits.GenerateError, match="speed must be"):
        user_curves.prepare_curve(_line(), 15.0, -1.0)


def test_curve_limits_refuse_before_allocating(tmp_path, monkeypatch):
    import time

    t0 = time.perf_counter()
    with pytest.raises(limits.GenerateError, match=r"10,000,000 m is longer than the limit of 10,000 m"):
        user_curves.load_curve("line", length=1e7)
    with pytest.raises(limits.GenerateError, match="longer than the limit"):
        user_curves.load_curve("circle", scale=1e9)
    (tmp_path / "far.csv").write_text("0,0\n1e9,0\n")  # 93 GiB of samples, once
    with pytest.raises(limits.GenerateError, match=r"far.csv: 1,000,000,000 m is longer than the limit"):
        user_curves.load_curve(str(tmp_path / "far.csv"))
    calls = []
    monkeypatch.setattr(curves, "resample_polyline", lambda *a, **k: calls.append(a))
    # 5 km is allowed, but at 8 cm per sample it is 62,501 samples, more than G may walk
    with pytest.raises(limits.GenerateError, match=r"62,501 samples at 0.08 m .* limit of 36,000 \(40 minutes"):
        user_curves.prepare_curve(np.array([[0.0, 0.0], [5000.0, 0.0]]), 15.0, SPEED)
    with pytest.raises(limits.GenerateError, match="longer than the limit"):  # an array, the demo's way in
        user_curves.prepare_curve(np.array([[0.0, 0.0], [0.0, 2e4]]), 15.0, SPEED)
    with pytest.raises(limits.GenerateError, match=r"250,001 points are more than the limit of 250,000"):
        user_curves.prepare_curve(np.stack([np.arange(250_001) * 1e-3, np.zeros(250_001)], -1), 15.0, SPEED)
    assert not calls  # refused before resampling
    monkeypatch.setattr(limits, "MAX_CURVE_FILE_BYTES", 100)
    (tmp_path / "big.csv").write_text("".join(f"{i},0\n" for i in range(50)))
    with pytest.raises(limits.GenerateError, match=r"big.csv: .* larger than the limit"):
        user_curves.load_curve(str(tmp_path / "big.csv"))
    assert time.perf_counter() - t0 < 5.0
    # the bounds themselves: a 10-minute walk fits, at the default speed and the shipped 15 Hz
    assert (10 * 60 * 15 < limits.MAX_CURVE_SAMPLES
            and 10 * 60 * user_curves.DEFAULT_SPEED_M_PER_S < limits.MAX_CURVE_LENGTH_M)


def test_bad_curves_are_clear_errors(tmp_path):
    (tmp_path / "empty.csv").write_text("# nothing\n")
    (tmp_path / "same.csv").write_text("1,1\n1,1\n1,1\n")
    (tmp_path / "tiny.json").write_text("[[0, 0], [0.01, 0]]")
    with pytest.raises(curves.CurveFileError, match="empty.csv: no x,z rows"):
        user_curves.load_curve(str(tmp_path / "empty.csv"))
    with pytest.raises(curves.DegenerateCurveError, match="zero length"):
        user_curves.load_curve(str(tmp_path / "same.csv"))
    with pytest.raises(curves.DegenerateCurveError, match="shorter than one spacing"):
        user_curves.prepare_curve(user_curves.load_curve(str(tmp_path / "tiny.json")), 15.0, SPEED)
    with pytest.raises(limits.GenerateError, match="not a shape name .*no such file"):
        user_curves.load_curve("squiggle")
    with pytest.raises(limits.GenerateError, match="scale must be"):
        user_curves.load_curve("circle", scale=0)


def test_bvh_curve_uses_the_pelvis_path_at_its_own_speed(tmp_path):
    motion = synthetic.generate_clip(synthetic.STYLES["Normal"], key_or_seed=0, num_frames=240)
    bvh.write_bvh(tmp_path / "walk.bvh", motion)
    c = user_curves.load_curve(str(tmp_path / "walk.bvh"), control_seconds=2.0)
    assert c.smooth_interval == 120 and len(c.points) == 240
    assert c.speed_m_per_s == pytest.approx(synthetic.STYLES["Normal"].speed, rel=0.1)


# ---------------------------------------------------------------------------------------------
# generation


def test_a_curve_six_windows_long_walks_on_the_floor(run):
    state, meta, cfg, layout = run
    assert cfg.data.window_T == 16 and walk.sample_rate(meta, cfg) == 15.0
    curve = user_curves.prepare_curve(_line(), walk.sample_rate(meta, cfg), SPEED)
    w = styles.spec_codes(state, [styles.parse_style("Happy", meta["style_names"])], meta["style_names"])
    out = walk.generate_motion(state, layout, curve, w)
    J = layout.num_joints
    chex.assert_shape(out.positions, (1, T_LONG, J, 3))
    chex.assert_shape(out.root_velocity, (1, T_LONG, 3))
    chex.assert_shape(out.pose, (1, T_LONG, 3 * (J - 1)))
    chex.assert_tree_all_finite((out.positions, out.floor_shift_m))
    lowest = out.positions[0, :, :, 1].min(axis=-1)
    assert np.percentile(lowest, walk.FLOOR_PERCENTILE) == pytest.approx(0.0, abs=1e-9)
    # the root starts at the curve's start on the floor plan and follows G's velocity after it
    np.testing.assert_allclose(out.positions[0, 0, 0, [0, 2]], curve[0, [0, 2]], atol=1e-6)
    np.testing.assert_allclose(np.diff(out.positions[0, :, 0], axis=0), out.root_velocity[0, 1:], atol=1e-9)
    # the root is trajectory.integrate from the curve start (y = 0), lifted by the floor shift
    root = np.asarray(trajectory.integrate(curve[:1] * [1, 0, 1], out.root_velocity.astype(np.float32)))[0]
    np.testing.assert_allclose(out.positions[0, :, 0] - [0, out.floor_shift_m[0], 0], root, rtol=1e-5, atol=1e-4)
    # more motions x samples than one call may hold: refused before G runs
    with pytest.raises(limits.GenerateError, match=r"9 motions x 36,000 samples = 324,000 are more than the limit"):
        walk.generate_motion(state, layout, np.zeros((36_000, 3)), np.repeat(w, 9, 0))
    with pytest.raises(limits.GenerateError, match=r"36,001 samples are more than the limit of 36,000"):
        walk.generate_motion(state, layout, np.zeros((36_001, 3)), w)


def _arc_then_straight(M, turn_samples, spacing=SPEED / 15, rate=0.03):
    """(M, 3) samples at equal spacing: heading turns by `rate` rad per sample for
    `turn_samples` samples, then stays: from there on every step is the same vector."""
    heading = rate * np.minimum(np.arange(M), turn_samples)
    steps = spacing * np.stack([np.cos(heading), np.zeros(M), np.sin(heading)], -1)
    steps[0] = 0.0
    return np.cumsum(steps, axis=0).astype(np.float32)


def test_the_whole_curve_is_walked_and_the_motion_cropped_to_it(run):
    """A 90-sample curve: G runs on 96 (the curve extended straight), the motion has 90 frames.
    The curve turns, then goes straight from sample 80, so its straight extension is the
    96-sample curve itself: the motion is that curve's first 90 frames, up to the float32
    rounding of the extended points (a turning input: on a straight one G's instance norms
    would normalise rounding noise)."""
    state, meta, cfg, layout = run
    full = _arc_then_straight(T_LONG, 80)
    w = styles.spec_codes(state, [styles.parse_style("Sad", meta["style_names"])], meta["style_names"])
    ref = walk.generate_motion(state, layout, full, w)
    out = walk.generate_motion(state, layout, full[:90], w)
    chex.assert_shape(out.positions, (1, 90, layout.num_joints, 3))
    chex.assert_shape([out.root_velocity, out.curve], [(1, 90, 3), (90, 3)])
    # measured 1.5e-4 of the largest value; padding by standing still instead differs by 1.7
    scale = np.abs(ref.pose).max()
    np.testing.assert_allclose(out.pose, ref.pose[:, :90], atol=2e-3 * scale)
    np.testing.assert_allclose(out.root_velocity, ref.root_velocity[:, :90], atol=2e-3 * scale)
    # the feet go on the floor over the clip's own frames
    lowest = out.positions[0, :, :, 1].min(axis=-1)
    assert np.percentile(lowest, walk.FLOOR_PERCENTILE) == pytest.approx(0.0, abs=1e-9)
    np.testing.assert_allclose(out.positions[0, 0, 0, [0, 2]], full[0, [0, 2]], atol=1e-6)
    # a very short curve: 5 samples, G on MIN_T, 5 frames back
    assert walk.generate_motion(state, layout, full[:5], w).positions.shape[1] == 5
    with pytest.raises(limits.GenerateError, match=r"M >= 2"):
        walk.generate_motion(state, layout, full[:1], w)


def test_chunk_starts_and_weights():
    assert walk.chunk_starts(2048, 4096) == [0]
    assert walk.chunk_starts(2048, 1024) == [0, 512, 1024]  # (2048 - 1024) / (1024 - 512) + 1 chunks
    for T in (1032, 1536, 2056, 5000 // 8 * 8, 9000, 36_000):
        starts = walk.chunk_starts(T, 1024)
        assert starts[0] == 0 and starts[-1] == T - 1024 and all(s % 8 == 0 for s in starts)
        assert all(b - a <= 1024 - walk.CHUNK_OVERLAP for a, b in zip(starts, starts[1:])), T
        weights = walk.chunk_weights(starts, 1024)
        total = np.zeros(T)
        for s, w in zip(starts, weights):
            total[s:s + 1024] += w
        assert total.min() > 0.1, T  # every sample is covered
        # no sample within CHUNK_MARGIN of a chunk end that meets another chunk is used
        for i, w in enumerate(weights):
            if i > 0:
                assert not w[:walk.CHUNK_MARGIN].any()
                assert w[walk.CHUNK_MARGIN + walk.CHUNK_FADE:-walk.CHUNK_OVERLAP].min() == 1
            if i < len(weights) - 1:
                assert not w[-walk.CHUNK_MARGIN:].any()
    # where exactly two chunks overlap by CHUNK_OVERLAP the weights sum to 1 before normalising
    w0, w1 = walk.chunk_weights([0, 512], 1024)
    np.testing.assert_allclose(w0[512:] + w1[:512], 1.0, atol=1e-12)
    with pytest.raises(limits.GenerateError, match="chunk_T must be"):
        walk.chunk_starts(4096, 1000)


@pytest.fixture(scope="module")
def gait_model(repo):
    """The tiny G at its initialisation with a gait phase and a root-height head, plus the
    rest-pose prior and the curve frame (a G whose outputs look like a body following the curve;
    the random parameters of `run` make a chaotic G whose outputs depend on every statistic). Its
    stride head is set so that Sad and Happy stride 0.8 m and 1.4 m (at initialisation every
    stride is 1 m; one stride per style, walker.stride_speed off, so that a stride set by hand is the
    stride G walks at every speed)."""
    from flax import nnx

    cfg = override(load_config(repo / "configs" / "tiny.py"),
                   ["model.walker=default", "model.walker.exact_bones=false", "model.walker.stride_speed=false"])
    layout = representation.layout_from_skeleton(synthetic.cmu_skeleton(), synthetic.UNITS_TO_M)
    state = model_state.init_state(cfg, layout, len(NAMES), jax.random.key(0))
    from motiongan_jax.nn.walker import STRIDE_GAIN

    g = model_apply.generator(state)
    w = styles.spec_codes(state, [styles.parse_style(n, NAMES) for n in ("Sad", "Happy")], NAMES)
    g.stride_head.kernel[...] = (np.linalg.pinv(w) @ (np.log([0.8, 1.4]) / STRIDE_GAIN))[:, None]
    return state.replace(g_params=nnx.state(g, nnx.Param)), layout


def _wandering(T, seed=0, spacing=SPEED / 15, straight_from=None):
    """(T, 3) samples of a walk whose heading wanders smoothly (no period), straight from sample
    `straight_from` on if given (from there every step is the same vector)."""
    rng = np.random.default_rng(seed)
    heading = np.cumsum(np.convolve(rng.normal(0, 0.08, T + 200), np.ones(60) / 60, "same")[100:100 + T])
    if straight_from is not None:
        heading[straight_from:] = heading[straight_from]
    steps = spacing * np.stack([np.cos(heading), np.zeros(T), np.sin(heading)], -1)
    steps[0] = 0.0
    return np.cumsum(steps, axis=0).astype(np.float32)


def _wrap(a):
    """Angles to (-π, π]."""
    return np.angle(np.exp(1j * a))


def _compiled_fast(jitted):
    """`jitted` compiled once per input shape with XLA's backend optimiser off (as the train-step
    tests do): compiling dominates on CPU, and one pass and the chunks are compiled alike."""
    cache = {}

    def call(*args):
        key = (len(args),) + tuple((np.shape(a), str(np.asarray(a).dtype)) if a is not None else None
                                   for a in args[1:])
        if key not in cache:
            cache[key] = jitted.lower(*args).compile(compiler_options=FAST)
        return cache[key](*args)
    return call


def test_chunks_walk_one_gait_clock_and_stay_close_to_one_pass(gait_model, monkeypatch):
    """A curve of 1530 samples, two styles (strides 0.8 and 1.4 m) at their own phase offsets, G
    with a gait phase and a root-height head: G runs on the curve padded to 1536, in one pass and
    in chunks of 1024 (starts 0 and 512).

    Padding: the curve is straight from sample 1500, so its extension is the 1536-sample curve
    itself and the motion is that curve's first 1530 frames up to the float32 rounding of the
    extended points (measured 8e-7 of the largest pose value; bound 1e-5).
    The clock: each chunk's phase offset continues the walked distance, so the phase G walks in
    every chunk is one pass's up to float32 rounding of phases that reach 965 rad (measured
    1.5e-4 rad; bound 1e-3). The second chunk restarted at the walk's offset would be 1.3 and
    1.6 rad off.
    The outputs are close to one pass's, not equal to float rounding, and cannot be: G
    instance-normalises over its input's time axis, and each chunk's statistics are its own 1024
    samples, not all 1536. Measured: 3.8e-4 relative RMS of the pose rows, 0.17 mm mean
    root-relative joint error, a root path 0.10 m (0.08% of the walk) and a root height at most
    14 mm (within the first chunk, where its statistics differ most) off one pass's; bounds at
    about 3x. Where the second chunk alone is used the pose is 2.7e-4 off, and 6.8e-3 off with a
    restarted clock: the phase, not the statistics, is what a restart would break."""
    state, layout = gait_model
    M, L = 1530, 1024
    monkeypatch.setattr(model_apply, "g_apply", _compiled_fast(model_apply.g_apply))
    real = model_apply.g_apply
    full = _wandering(1536, straight_from=1500)
    w = styles.spec_codes(state, [styles.parse_style(n, NAMES) for n in ("Sad", "Happy")], NAMES)
    phi0 = np.array([0.5, 4.0])
    ref = walk.generate_motion(state, layout, full, w, phi0)
    calls, progress = [], []
    monkeypatch.setattr(model_apply, "g_apply",
                        lambda st, v, ww, ph, at=None: (calls.append((v, ww, ph)), real(st, v, ww, ph, at))[1])
    one = walk.generate_motion(state, layout, full[:M], w, phi0)
    assert [c[0].shape for c in calls] == [(2, 1536, 3)]
    calls.clear()
    ch = walk.generate_motion(state, layout, full[:M], w, phi0, chunk_T=L,
                              progress=lambda d, n: progress.append((d, n)))
    assert [c[0].shape for c in calls] == [(2, L, 3)] * 2 and progress == [(1, 2), (2, 2)]
    chex.assert_shape([one.positions, ch.positions], (2, M, layout.num_joints, 3))
    # the whole curve is walked: padded and cropped = the longer curve's first M frames
    scale = np.abs(ref.pose).max()
    np.testing.assert_allclose(one.pose, ref.pose[:, :M], atol=1e-5 * scale)
    np.testing.assert_allclose(one.root_velocity, ref.root_velocity[:, :M], atol=1e-5 * scale)
    # one clock: the phase G walks in each chunk is one pass's
    g = model_apply.generator(state)
    np.testing.assert_allclose(np.exp(np.asarray(g.log_stride(jax.numpy.asarray(w)))), [0.8, 1.4], rtol=1e-4)
    vel = trajectory.velocity(jax.numpy.asarray(np.stack([full] * 2)))
    clock = np.asarray(g.walked_phase(vel, jax.numpy.asarray(w), jax.numpy.asarray(phi0, jax.numpy.float32)))
    for (v, ww, ph), s in zip(calls, (0, 512)):
        err = np.abs(_wrap(np.asarray(g.walked_phase(v, ww, ph)) - clock[:, s:s + L])).max()
        assert err < 1e-3, (s, err)
    v1, w1, _ = calls[1]
    restart = jax.numpy.asarray(phi0, jax.numpy.float32)
    assert np.abs(_wrap(np.asarray(g.walked_phase(v1, w1, restart)) - clock[:, 512:])).min() > 1.0
    # the outputs: close to one pass (each chunk's own statistics)
    rel = lambda a, b: np.sqrt(np.mean((a - b) ** 2) / np.mean(b ** 2))  # noqa: E731
    rooted = lambda g: g.positions - g.positions[:, :, :1]  # noqa: E731
    height = lambda g: g.positions[:, :, 0, 1] - g.floor_shift_m[:, None]  # noqa: E731
    assert rel(ch.pose, one.pose) < 1.2e-3
    assert np.linalg.norm(rooted(ch) - rooted(one), axis=-1).mean() < 5e-4
    assert np.linalg.norm(ch.positions[:, :, 0, [0, 2]] - one.positions[:, :, 0, [0, 2]], axis=-1).mean() < 0.3
    assert np.abs(height(ch) - height(one)).max() < 0.04
    # where the second chunk alone is used, a restarted clock is far further off than the statistics
    tail = slice(512 + walk.CHUNK_MARGIN + walk.CHUNK_FADE, M)
    restarted = np.asarray(real(model_apply.generator_state(state), v1, w1, restart)[1])[:, tail.start - 512:M - 512]
    assert rel(restarted, one.pose[:, tail]) > 10 * rel(ch.pose[:, tail], one.pose[:, tail])
    # no seam: where the chunks blend, pose, root velocity and height change no faster than elsewhere
    seam = slice(512 + walk.CHUNK_MARGIN, 1024 - walk.CHUNK_MARGIN)
    for x in (ch.pose, ch.root_velocity, height(ch)[..., None]):
        jump = np.abs(np.diff(x, axis=1)).max(axis=(0, 2))
        assert jump[seam].max() < 1.5 * max(jump[:seam.start].max(), jump[seam.stop:].max())
    with pytest.raises(limits.GenerateError, match="phase offsets must be 2 finite numbers"):
        walk.generate_motion(state, layout, full[:M], w, np.zeros(3))


def test_motions_are_generated_in_groups_that_fit_batch_samples(run, monkeypatch):
    """5 motions at 96 samples with BATCH_SAMPLES 200: G gets 2 motions per call (the last group
    padded, so one compile), and the motions come back in order. G is a stand-in whose output
    depends on each motion's code and each sample's input, so a misplaced group would show."""
    state, meta, cfg, layout = run
    calls = []

    def fake_g(st, v, w, phase, phase_BxT=None):
        calls.append(v.shape)
        root = v * w[:, :1, None]
        pose = jax.numpy.broadcast_to(jax.numpy.cumsum(v[..., :1], axis=1) + w[:, None, 1:2],
                                      v.shape[:2] + (layout.num_rows,))
        return root, pose

    monkeypatch.setattr(model_apply, "g_apply", fake_g)
    curve = _wandering(T_LONG)
    w = np.random.default_rng(1).normal(size=(5, 8)).astype(np.float32)
    one = walk.generate_motion(state, layout, curve, w)
    assert calls == [(5, T_LONG, 3)]
    calls.clear()
    monkeypatch.setattr(walk, "BATCH_SAMPLES", 200)
    grouped = walk.generate_motion(state, layout, curve, w)
    assert calls == [(2, T_LONG, 3)] * 3
    np.testing.assert_array_equal(grouped.pose, one.pose)
    np.testing.assert_array_equal(grouped.positions, one.positions)


def test_figures_panels():
    interp = styles.figure_specs("interp", "Sad, Happy", NAMES)
    assert [s.terms for _, s in interp] == [(("Sad", 1 - a), ("Happy", a)) for a in styles.INTERP_ALPHAS]
    arith = styles.figure_specs("arith", "OldMan - Normal + Marching", NAMES)
    assert [t for t, _ in arith] == ["OldMan", "Normal", "Marching", "OldMan - Normal + Marching"]
    assert [t for t, _ in styles.figure_specs("styles", None, NAMES)] == list(NAMES)
    assert [t for t, _ in styles.figure_specs("styles", "Sad,Happy", NAMES)] == ["Sad", "Happy"]
    with pytest.raises(styles.StyleError, match="two styles"):
        styles.figure_specs("interp", "Sad", NAMES)
    with pytest.raises(styles.StyleError, match="expression"):
        styles.figure_specs("arith", "Sad", NAMES)


# ---------------------------------------------------------------------------------------------
# the command line


def test_cli_npz_subprocess_then_bvh_round_trip(repo, run_dir, cli, tmp_path, capsys):
    """One real subprocess (.npz); the .bvh of the same motion in-process, in both hierarchies;
    FK of the re-read BVH matches the npz's skeleton positions and the generated bone directions
    (all of them in the exact form; all but the best-fit ones, by the stated error, in the
    source form)."""
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

    capsys.readouterr()
    assert cli([*common, "--out", str(tmp_path / "walk.bvh"), "--bvh-units", "cm"]) == 0
    note = capsys.readouterr().err
    motion = bvh.read_bvh(tmp_path / "walk.bvh")
    assert motion.frame_time == pytest.approx(1 / 15)
    # the default hierarchy is the training skeleton's: its joints, the thumbs' own joints, nothing else
    assert not any("branch" in n for n in motion.skeleton.names)
    layout = representation.layout_from_skeleton(motion.skeleton, 0.01)
    assert layout.joint_names == tuple(z["joint_names"]) and layout.parents == tuple(z["parents"])
    world = kinematics.world_positions(motion)[:, list(layout.source_index)] * 0.01
    np.testing.assert_allclose(world, z["positions_skeleton"], atol=1e-5)  # the npz's FK is this file's
    angle = ik.bone_errors(z["positions"], world, layout.parents)
    kids = np.bincount(np.asarray(layout.parents[1:]), minlength=layout.num_joints)
    fitted = np.array([kids[p] > 1 and not n.startswith(("LThumb", "RThumb"))
                       for p, n in zip(layout.parents[1:], layout.joint_names[1:])])
    assert angle[:, ~fitted].max() < 1e-4  # measured 5e-8 rad (BVH text: 6 decimals of cm and degrees)
    # the best-fit bones: the stated error is the measured one
    m = re.search(r"the (\d+) bones leaving Hips, LeftHand, RightHand, Spine1 are best fits, ([\d.e+-]+) deg mean "
                  r"and ([\d.e+-]+) deg max", note)
    assert m and int(m.group(1)) == fitted.sum(), note
    assert float(m.group(3)) == pytest.approx(np.degrees(angle[:, fitted].max()), rel=0.05, abs=1e-3)
    np.testing.assert_allclose(representation.bone_lengths(
        (world[:, 1:] - world[:, :1]).reshape(T_LONG, -1), layout.bone_pairs),
        np.broadcast_to(layout.bone_lengths_m, (T_LONG, J - 1)), atol=1e-6)
    # the exact form: zero-length branch joints, every bone direction exact; it reads back to the layout too
    assert cli([*common, "--out", str(tmp_path / "exact.bvh"), "--bvh-hierarchy", "exact"]) == 0
    exact = bvh.read_bvh(tmp_path / "exact.bvh")
    assert sum(n.endswith("_branch") for n in exact.skeleton.names) == 8
    again = representation.layout_from_skeleton(exact.skeleton, 1.0)
    assert again.joint_names == layout.joint_names and again.parents == layout.parents
    world = kinematics.world_positions(exact)[:, list(again.source_index)]
    assert ik.bone_errors(z["positions"], world, layout.parents).max() < 1e-4


def test_cli_progress_shows_only_when_generation_is_slow(repo):
    import io

    module = load_cli("generate")
    now = [0.0]
    out = io.StringIO()
    bar = module.Progress(out, delay=2.0, clock=lambda: now[0])
    now[0] = 1.0
    bar(1, 4)  # one second in: quiet
    assert out.getvalue() == ""
    now[0] = 6.0
    bar(2, 4)
    assert out.getvalue().strip() == "generating [##########          ] 2/4 G calls, 6 s, about 6 s left"


def test_cli_params_choose_the_moving_average_or_the_raw_g(repo, cli, tmp_path):
    cfg = override(load_config(repo / "configs" / "tiny.py"), ["train.g_ema_decay=0.999"])
    wd = _random_run(cfg, tmp_path / "run")  # g_ema_params random too, so unlike g_params
    common = ["--workdir", str(wd), "--style", "Happy", "--curve", "line", "--length",
              str((T_LONG - 1) * SPEED / 15 + 1e-6)]
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
    (["--length", "1e7"], "a.bvh", r"10,000,000 m is longer than the limit of 10,000 m"),
    (["--curve", "FAR.csv"], "a.npz", r"FAR.csv: 1,000,000,000 m is longer than the limit"),
    (["--length", "2900"], "a.bvh", r"36,251 samples .* more than the limit of 36,000"),
    (["--length", "300"], "a.gif", r"a GIF of 1 panel\(s\) x 3,751 frames is more than the limit"),
    ([], "/proc/a.bvh", "cannot write /proc/a.bvh: directory /proc (is not writable|does not exist)"),
])
def test_cli_errors_exit_non_zero_and_leave_no_file(run_dir, cli, tmp_path, capsys, extra, out_name, match):
    (tmp_path / "EMPTY.csv").write_text("")
    (tmp_path / "SAME.csv").write_text("0,0\n0,0\n")
    (tmp_path / "FAR.csv").write_text("0,0\n1e9,0\n")
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


def test_cli_style_from_a_clip_walks_its_recovered_mix(cli, tmp_path, capsys):
    """--style-from: the shipped model recovers a held-out clip's style (it knows OldMan), prints it
    as a mix, and walks that mix (the same w as --style with the printed text) at the clip's speed."""
    clip = synthetic.default_dataset_dir() / "OldMan_05.bvh"
    out = tmp_path / "like.npz"
    # 3 search steps, as test_analysis.SEARCH_STEPS
    assert cli(["--style-from", str(clip), "--curve", "line", "--length", "3", "--out", str(out),
                "--search-steps", "3"]) == 0
    err = capsys.readouterr().err
    m = re.search(r"style of \S*OldMan_05\.bvh: (\S+) \(nearest known styles: OldMan \(", err)
    assert m, err
    speed = float(re.search(r"walking at the clip's speed, ([\d.]+) m/s", err).group(1))
    assert 0.5 < speed < 2.5
    meta = pretrained.read_export(pretrained.SHIPPED_MODEL).meta
    state = pretrained.load_model()[0]
    want = styles.spec_codes(state, [styles.parse_style(m.group(1), meta["style_names"])], meta["style_names"])
    with np.load(out) as z:
        np.testing.assert_allclose(z["w"], want[0], atol=1e-6)
        # a 3 m line at the clip's speed: one sample per speed / 15 Hz metres
        assert abs(len(z["positions"]) - (3.0 / (speed / 15.0) + 1)) <= 1.5


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
    with pytest.raises(limits.GenerateError, match="is not a directory"):
        writers.check_output_path(tmp_path / "file" / "a.bvh")
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        if not os.access(ro, os.W_OK):  # (root may write anywhere)
            with pytest.raises(limits.GenerateError, match="not writable"):
                writers.check_output_path(ro / "a.bvh")
    finally:
        ro.chmod(0o700)
    # a failure while writing (here: non-finite positions) leaves no file and no temp file
    bad = walk.Generated(np.full((1, 16, layout.num_joints, 3), np.nan), None, None,
                        np.zeros((16, 3), np.float32), np.zeros((1, 8), np.float32), np.zeros(1))
    for name in ("a.bvh", "a.npz"):
        with pytest.raises(ik.IKError):
            writers.write_outputs(tmp_path / name, bad, ["x"], layout, 15.0)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file", "ro"]
