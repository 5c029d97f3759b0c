"""generate/stream.py: a walker fed its path piece by piece (the shipped model).

Checked against a second method, whole-path generation (walk.generate_motion) of the same
points: the stream's path, pose and gait phase agree within the tolerances below; across
every advance the positions, root velocities and phase continue without a jump larger than the
walk's own sample-to-sample change; the walker's state stays bounded however long it walks; bad
input is refused with a message. One walker configuration (one compiled window) for all.
"""

import chex
import numpy as np
import pytest

from motiongan_jax.generate import stream, walk
from motiongan_jax.model import apply as model_apply
from motiongan_jax.model import pretrained

# stated tolerances of stream vs whole path (default HISTORY/LOOKAHEAD, a 1.5 m radius curve)
TOL_ROOT_XZ_M = 0.05  # the root's floor position, any sample
TOL_POSE_RMS_M = 0.03  # root-relative joints, RMS over the walk
TOL_PHASE_RAD = 1e-3  # the gait clock is the walk's own: equal up to float32 rounding


@pytest.fixture(scope="module")
def shipped():
    state, meta, cfg, layout = pretrained.load_model(None, None, "ema", None)
    return state, layout, walk.sample_rate(meta, cfg)


@pytest.fixture(scope="module")
def w(shipped):
    return np.asarray(model_apply.style_codes(shipped[0], [0, 1]))


def _curve(M, rate, speed=1.2, radius=1.5):
    s = np.arange(M) * speed / rate
    return np.stack([radius * np.sin(s / radius), radius * (1 - np.cos(s / radius))], 1)


def _walk(shipped, w, pts, pieces=5):
    state, layout, rate = shipped
    wk = stream.Walker(state, layout, w, rate, start_xz=pts[0])
    wk.feed_points(pts[1:1 + pieces])
    outs = []
    i = 1 + pieces
    while wk.emitted < len(pts):
        if i < len(pts):
            wk.feed_points(pts[i:i + pieces])
            i += pieces
        outs.append(wk.advance(flush=i >= len(pts)))
    return wk, outs


def test_stream_equals_whole_path(shipped, w):
    state, layout, rate = shipped
    M = 200
    pts = _curve(M, rate)
    wk, outs = _walk(shipped, w[0], pts)
    pos = np.concatenate([o.positions for o in outs])
    chex.assert_shape(pos, (M, layout.num_rel_joints + 1, 3))
    curve = np.stack([pts[:, 0], np.zeros(M), pts[:, 1]], 1)
    ref = walk.generate_motion(state, layout, curve, w[:1])
    ref_pos = ref.positions[0]
    err_xz = np.abs(pos[:, 0, [0, 2]] - ref_pos[:, 0, [0, 2]]).max()
    rel = (pos - pos[:, :1]) - (ref_pos - ref_pos[:, :1])
    rms = np.sqrt((rel ** 2).sum(-1).mean())
    print(f"stream vs whole path: root xz max {err_xz:.4f} m, pose rms {rms:.4f} m")
    assert err_xz < TOL_ROOT_XZ_M and rms < TOL_POSE_RMS_M
    if wk.gait:
        phase = np.concatenate([o.phase for o in outs])
        vel = np.asarray(walk.trajectory.velocity(curve.astype(np.float32)[None]))
        ref_phase = model_apply.walked_phase(state, vel, w[:1])[0]
        np.testing.assert_allclose(phase, ref_phase, atol=TOL_PHASE_RAD)


def test_continuous_across_advances(shipped, w):
    state, layout, rate = shipped
    wk = stream.Walker(state, layout, w[0], rate)
    heading = 0.0
    outs = []
    for k in range(40):
        heading += 0.15 if (k // 10) % 2 else -0.1
        wk.feed_steps(np.tile([np.cos(heading), np.sin(heading)], (4, 1)), np.full(4, 1.3))
        if k == 20:
            wk.set_style(w[1], blend_s=1.0)
        outs.append(wk.advance())
    seams = np.cumsum([len(o.curve) for o in outs])[:-1]
    seams = seams[(seams > 1) & (seams < seams[-1])]
    pos = np.concatenate([o.positions for o in outs])
    assert [o.index0 for o in outs[1:]] == list(np.cumsum([len(o.curve) for o in outs])[:-1])
    step = np.linalg.norm(np.diff(pos, axis=0), axis=-1)  # (T-1, J) per-joint displacement
    typical = np.percentile(step, 99, axis=0)
    at_seams = step[seams - 1]
    # a seam's joint displacement is no larger than the walk's own 99th-percentile step (x 1.5)
    assert (at_seams <= 1.5 * typical + 1e-3).all(), (at_seams.max(0) / typical).max()
    rv = np.concatenate([o.root_velocity for o in outs])
    dv = np.linalg.norm(np.diff(rv, axis=0), axis=-1)
    assert dv[seams - 1].max() <= 1.5 * np.percentile(dv, 99) + 1e-4
    if wk.gait:
        phase = np.concatenate([o.phase for o in outs])
        d = np.diff(phase)
        assert (d >= -1e-6).all() and d.max() < 2 * np.pi * 0.5  # runs forward, never restarts
    # feet on the floor throughout: the lowest joint's 5th percentile at 0 within 3 cm
    lowest = pos[..., 1].min(-1)
    assert abs(np.percentile(lowest, 5)) < 0.03


def test_state_bounded(shipped, w):
    state, layout, rate = shipped
    wk = stream.Walker(state, layout, w[0], rate)
    sizes = []
    for k in range(120):
        wk.feed_steps([[1.0, 0.1 * np.sin(k / 5)]] * 8, [1.0] * 8)
        wk.advance()
        sizes.append(wk.state_size())
    assert wk.emitted > 2 * wk.ring
    assert max(sizes[60:]) <= max(sizes[30:60])  # flat once the ring is full


def test_bad_input(shipped, w):
    state, layout, rate = shipped
    wk = stream.Walker(state, layout, w[0], rate)
    with pytest.raises(stream.StreamError, match="finite"):
        wk.feed_steps([[np.nan, 1.0]], [1.0])
    with pytest.raises(stream.StreamError, match="m/s"):
        wk.feed_steps([[1.0, 0.0]], [1e6])
    with pytest.raises(stream.StreamError, match="zero"):
        wk.feed_steps([[0.0, 0.0]], [1.0])
    with pytest.raises(stream.StreamError, match="MAX_AHEAD"):
        wk.feed_steps([[1.0, 0.0]] * (stream.MAX_AHEAD + 1), [1.0] * (stream.MAX_AHEAD + 1))
    with pytest.raises(stream.StreamError, match="style code"):
        wk.set_style(np.zeros(3))
    assert len(wk.advance().curve) == 0  # nothing known ahead yet: nothing to emit


def test_revised_path_turns_the_walker(shipped, w):
    """A caller that steers revises the predicted path ahead: the walker turns at once and follows."""
    state, layout, rate = shipped
    wk = stream.Walker(state, layout, w[0], rate)
    wk.feed_steps([[1.0, 0.0]] * 64, [1.2] * 64)
    for _ in range(4):
        wk.advance(8)
    turned = wk.emitted
    here = wk._points[wk.emitted - 1 - wk._base, [0, 2]]
    ahead = here + np.outer(np.arange(1, 65), [0.0, 1.2 / rate])  # now straight along +z
    wk.revise_ahead(ahead)
    outs = [wk.advance(8) for _ in range(4)]
    assert outs[0].index0 == turned
    root = np.concatenate([o.positions[:, 0] for o in outs])
    d = root[-1, [0, 2]] - root[-9, [0, 2]]  # heading over the last second
    assert d[1] > 3 * abs(d[0]), d  # walking along +z within 2 s of the turn
    with pytest.raises(stream.StreamError, match="finite"):
        wk.revise_ahead([[np.nan, 0.0]])
    assert len(wk._points) > 1  # a refused revision keeps the path


def test_seam_steps_and_seam_values_by_hand():
    """evaluation/streaming.py's seam measures: the steps that reach across a boundary, and toes
    gliding on the floor at 0.1 m per sample except a 0.3 m jump into sample 10 (a boundary):
    seam / rest speed is 3 at 10 Hz; a boundary elsewhere sees no difference."""
    from motiongan_jax.evaluation import streaming

    np.testing.assert_array_equal(np.flatnonzero(streaming.seam_steps([10], 20, 1)), [9])
    np.testing.assert_array_equal(np.flatnonzero(streaming.seam_steps([10, 0], 20, 3)), [7, 8, 9])
    L, rate = 20, 10.0
    x = np.cumsum(np.r_[0.0, np.full(L - 1, 0.1)])
    x[10:] += 0.2  # the step 9 -> 10 is 0.3 m
    joints = np.zeros((L, 3, 3))
    joints[:, :, 0] = x[:, None]  # root and both toes glide together, on the floor
    joints[:, 0, 1] = 0.9
    phase = 0.5 * np.arange(L)
    v = streaming.seam_values(joints, phase, (1, 2), rate, 0.02, [10])
    np.testing.assert_allclose(v["toe_speed"][0], [3.0, 3.0])  # both toes, the seam step
    np.testing.assert_allclose(v["toe_speed"][1], 1.0)
    assert streaming._ratio([v["toe_speed"]]) == pytest.approx(3.0)
    np.testing.assert_allclose(v["phase"][0], 0.0)  # the clock steps evenly
    assert streaming._ratio([streaming.seam_values(joints, phase, (1, 2), rate, 0.02, [5])["toe_speed"]]) < 1.0


def test_style_blends_linearly_from_where_it_is(shipped, w):
    """set_style moves w in a straight line to the new code over blend_s seconds of samples,
    starting at the next sample to emit; a change during a blend starts from the code reached."""
    state, layout, rate = shipped
    wk = stream.Walker(state, layout, w[0], rate)
    assert wk.style_progress(0) == 1.0  # no blend under way
    np.testing.assert_array_equal(wk.style_at(0), w[0])
    wk.feed_steps([[1.0, 0.0]] * (wk.lookahead + 8), [1.2] * (wk.lookahead + 8))
    wk.advance(8)
    wk.set_style(w[1], blend_s=1.0)
    n = round(rate)  # samples in one second
    for k in (0, 1, n // 3, n - 1, n, n + 7):
        a = min(k / n, 1.0)
        assert wk.style_progress(8 + k) == pytest.approx(a)
        np.testing.assert_allclose(wk.style_at(8 + k), (1 - a) * w[0] + a * w[1], rtol=1e-5, atol=1e-6)
    wk.feed_steps([[1.0, 0.0]] * 5, [1.2] * 5)
    wk.advance(5)  # 5 samples into the blend
    halfway = wk.style_at(13)
    wk.set_style(w[0], blend_s=2.0)
    np.testing.assert_allclose(wk.style_at(13), halfway, rtol=1e-6)  # no jump
    np.testing.assert_allclose(wk.style_at(13 + n), 0.5 * halfway + 0.5 * w[0], rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(wk.style_at(13 + 2 * n), w[0], rtol=1e-6)
    np.testing.assert_allclose(wk.path_point(wk.emitted - 1), [(wk.emitted - 1) * 1.2 / rate, 0.0], atol=1e-9)
    with pytest.raises(stream.StreamError, match="not held"):
        wk.path_point(wk.known)
