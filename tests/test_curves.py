"""curves.py: spline vs scipy, equal arc length, noise, rotation, velocities, user curves."""

import json
import math

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from absl.testing import parameterized
from scipy.integrate import quad
from scipy.interpolate import CubicSpline, interp1d

from motiongan_jax.data import curves
from motiongan_jax.motion import trajectory

I = 16  # noqa: E741 - the paper's name for the control-point interval; small keeps every test tiny


def knot_frames(length, interval=I):
    """The knot frames the module must use, written out independently."""
    return list(range(0, length - 1, interval)) + [length - 1]


def wiggly_path(n, seed=0):
    """A walk-like floor path (metres): varying speed, turning, some sway."""
    t = np.arange(n, dtype=np.float64)
    rng = np.random.default_rng(seed)
    speed = 0.012 * (1 + 0.5 * np.sin(t / 23.0))
    heading = 0.8 * np.sin(t / 57.0) + rng.normal(0, 0.002, n).cumsum()
    xz = np.stack([np.cumsum(speed * np.cos(heading)), np.cumsum(speed * np.sin(heading))], -1)
    return xz + np.array([3.0, -2.0])


def scipy_equal_arclength(path, length, T, interval=I, sub=64):
    """Independent reference: scipy not-a-knot spline, dense chord table, np.interp inversion."""
    kt = knot_frames(length, interval)
    cs = CubicSpline(kt, path[kt], bc_type="not-a-knot")
    g = np.linspace(0, length - 1, sub * (length - 1) + 1)
    p = cs(g)
    cum = np.concatenate([[0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])
    x = np.interp(np.linspace(0, cum[-1], T), cum, g)
    return cs(x), cum[-1], cs


# ---------------------------------------------------------------------------------------------
# spline core
# ---------------------------------------------------------------------------------------------


# One padded batch covers every knot-count case: 2, 3, 4 (and 4 with n-1 = 3I: no duplicate
# knot, where the reference crashed), 7 with a 1-frame last segment, 7 with n-1 = 6I.
SPLINE_N = 97
SPLINE_LENGTHS = (12, 30, 40, 49, 82, 97)
fit_spline_jit = jax.jit(curves.fit_spline, static_argnames="interval")
eval_spline_jit = jax.jit(curves.eval_spline, static_argnames="interval")


@pytest.fixture(scope="module")
def fitted():
    """(path, x_BxP, spline values at x): knots first (repeated to 7), then 123 other frames."""
    path = np.stack([wiggly_path(SPLINE_N, seed=s) for s in range(len(SPLINE_LENGTHS))])
    padded = path.copy()
    xs = []
    for b, n in enumerate(SPLINE_LENGTHS):
        padded[b, n:] = np.nan  # padding must never be read
        kt = knot_frames(n)
        xs.append(np.concatenate([kt, [kt[-1]] * (7 - len(kt)), np.linspace(0, n - 1, 123)]))
    spline = fit_spline_jit(jnp.asarray(padded, jnp.float32), np.array(SPLINE_LENGTHS),
                            interval=I)
    chex.assert_shape(spline.m_BxKx2, (len(SPLINE_LENGTHS), curves.max_knots(SPLINE_N, I), 2))
    x = np.stack(xs)
    got = np.asarray(eval_spline_jit(spline, x, interval=I))
    chex.assert_shape(got, x.shape + (2,))
    chex.assert_tree_all_finite(got)
    return path, x, got


def test_spline_matches_scipy_not_a_knot_with_masked_padding(fitted):
    path, x, got = fitted
    assert [len(knot_frames(n)) for n in SPLINE_LENGTHS] == [2, 3, 4, 4, 7, 7]
    for b, n in enumerate(SPLINE_LENGTHS):
        kt = knot_frames(n)
        ref = CubicSpline(kt, path[b, kt], bc_type="not-a-knot")
        np.testing.assert_allclose(got[b], ref(x[b]), atol=2e-5, err_msg=f"length {n}")
        np.testing.assert_allclose(got[b, :len(kt)], path[b, kt], atol=2e-5)  # interpolates
        if len(kt) >= 4:  # interp1d(kind='cubic'), the reference's constructor, needs 4 knots
            np.testing.assert_allclose(got[b], interp1d(kt, path[b, kt], kind="cubic",
                                                        axis=0)(x[b]), atol=2e-5)


def test_three_knots_is_the_quadratic_fallback_and_two_knots_the_line(fitted):
    path, x, got = fitted
    kt = knot_frames(30)  # sample 1: knots 0, 16, 29
    quadratic = interp1d(kt, path[1, kt], kind="quadratic", axis=0)
    np.testing.assert_allclose(got[1], quadratic(x[1]), atol=2e-5)
    # sample 0: knots 0 and 11 only, a straight line between the end frames
    w = (x[0] / 11.0)[:, None]
    np.testing.assert_allclose(got[0], (1 - w) * path[0, 0] + w * path[0, 11], atol=2e-5)


def test_final_knot_takes_the_last_frame_not_the_second_to_last(fitted):
    path, x, got = fitted
    for b, n in enumerate(SPLINE_LENGTHS):
        np.testing.assert_allclose(got[b, 6], path[b, n - 1], atol=1e-5)  # x = n-1 (padded slot)


# ---------------------------------------------------------------------------------------------
# window_curves (jit and no jit)
# ---------------------------------------------------------------------------------------------


# Every window test uses one batch shape so that jit (and eager op) compilations are shared.
B, N, T = 2, 161, 40
window_curves_jit = jax.jit(curves.window_curves, static_argnames=("T", "interval"))


def batch_paths(*seeds):
    return np.stack([wiggly_path(N, s) for s in seeds]).astype(np.float32)


class WindowCurvesTest(parameterized.TestCase):
    @chex.variants(with_jit=True, without_jit=True)
    def test_equal_arc_length_on_a_curvy_path(self):
        lengths = np.array([161, 120])
        path = batch_paths(1, 2)
        fn = self.variant(curves.window_curves, static_argnames=("T", "interval"))
        out = np.asarray(fn(path, lengths, T=T, interval=I, noise=0.0, key=jax.random.key(0)))
        chex.assert_shape(out, (B, T, 2))
        chex.assert_tree_all_finite(out)
        for b, n in enumerate(lengths):
            ref, total, cs = scipy_equal_arclength(path[b].astype(np.float64), n, T)
            d = np.linalg.norm(np.diff(out[b], axis=0), axis=1)
            assert d.max() / d.min() < 1.01, (d.min(), d.max())
            speed = lambda t: np.linalg.norm(cs(t, 1))  # noqa: E731
            kt = knot_frames(n)
            arc = sum(quad(speed, a, c)[0] for a, c in zip(kt[:-1], kt[1:]))
            np.testing.assert_allclose(total, arc, rtol=1e-6)  # the reference itself is right
            np.testing.assert_allclose(d.sum(), arc, rtol=2e-3)  # chords of a curve: a bit less
            np.testing.assert_allclose(out[b], ref, atol=1e-4)
            np.testing.assert_array_equal(out[b, 0], path[b, 0])
            np.testing.assert_allclose(out[b, -1], path[b, n - 1], atol=1e-5)

    @chex.variants(with_jit=True, without_jit=True)
    def test_noise_is_keyed_and_zero_noise_is_noise_free(self):
        path = batch_paths(0, 0)
        lengths = np.array([161, 64])
        fn = self.variant(curves.window_curves, static_argnames=("T", "interval"))
        k1, k2 = jax.random.key(1), jax.random.key(2)
        a = np.asarray(fn(path, lengths, T=T, interval=I, noise=0.02, key=k1))
        b = np.asarray(fn(path, lengths, T=T, interval=I, noise=0.02, key=k1))
        c = np.asarray(fn(path, lengths, T=T, interval=I, noise=0.02, key=k2))
        clean = np.asarray(fn(path, lengths, T=T, interval=I, noise=0.0, key=k1))
        np.testing.assert_array_equal(a, b)
        assert np.abs(a - c).max() > 1e-4
        assert np.abs(a - clean).max() > 1e-4
        np.testing.assert_array_equal(a[:, 0], clean[:, 0])  # the start stays exact
        np.testing.assert_array_equal(
            clean, np.asarray(fn(path, lengths, T=T, interval=I, noise=0.0, key=k2)))
        # no key at all (eager): the same curve up to float32 rounding of a different program
        np.testing.assert_allclose(clean, curves.window_curves(path, lengths, T, I), atol=1e-6)


def test_straight_line_with_changing_speed_is_spaced_exactly():
    s = np.linspace(0, 1, N) ** 2 * 4.0  # accelerating along the line
    direction = np.array([0.6, 0.8])
    path = (np.array([1.0, 2.0]) + s[:, None] * direction)[None].repeat(B, 0).astype(np.float32)
    out = np.asarray(window_curves_jit(path, np.array([N, N]), T=T, interval=I, noise=0.0,
                                       key=jax.random.key(0)))
    expect = np.array([1.0, 2.0]) + np.linspace(0, 4.0, T)[:, None] * direction
    np.testing.assert_allclose(out[0], expect, atol=2e-5)


def test_standing_still_gives_copies_of_the_start():
    path = np.zeros((B, N, 2), np.float32) + np.array([1.5, -0.5], np.float32)
    for noise in (0.0, 0.05):
        out = np.asarray(window_curves_jit(path, np.array([N, 1]), T=T, interval=I, noise=noise,
                                           key=jax.random.key(3)))
        chex.assert_tree_all_finite(out)
        np.testing.assert_array_equal(out, np.broadcast_to(path[:, :1], out.shape))


def test_noise_statistics():
    Bs, noise = 48, 0.1
    path = np.zeros((Bs, N, 2), np.float32)
    path[..., 0] = np.arange(N) * 0.01  # straight along x at constant speed
    length = np.full(Bs, N)
    out = np.asarray(window_curves_jit(path, length, T=T, interval=I, noise=noise,
                                       key=jax.random.key(0)))
    clean = np.asarray(window_curves_jit(path, length, T=T, interval=I, noise=0.0,
                                         key=jax.random.key(0)))
    delta = 0.01 * (N - 1) / (T - 1)
    err = out - clean
    # Across the line only the spatial jitter acts; along it timing (~ step * speed) adds its
    # own, clipped at the end, so leave the last point out there.
    np.testing.assert_allclose(err[:, 1:, 1].std(), noise * delta, rtol=0.06)
    along = noise * math.hypot(delta, 0.01 * N / T)
    np.testing.assert_allclose(err[:, 1:-1, 0].std(), along, rtol=0.06)
    assert abs(err[:, 1:, 1].mean()) < 0.1 * noise * delta


def test_rotating_the_path_rotates_the_curve():
    path = batch_paths(4, 5)
    lengths = np.array([161, 77])
    theta = np.array([0.7, -2.1], np.float32)
    kw = dict(T=T, interval=I, noise=0.0, key=jax.random.key(0))
    out = window_curves_jit(path, lengths, **kw)
    out_rot = window_curves_jit(trajectory.rotate_y(path, theta), lengths, **kw)
    np.testing.assert_allclose(out_rot, trajectory.rotate_y(out, theta), atol=5e-5)


def test_window_curves_rejects_noise_without_key():
    with pytest.raises(ValueError, match="key"):
        curves.window_curves(np.zeros((1, 10, 2)), [10], 4, I, noise=0.02)


def test_spline_curve_matches_the_independent_reference():
    path = wiggly_path(300, 7)
    out = curves.spline_curve(path, 50, 64)
    chex.assert_shape(out, (50, 2))
    assert out.dtype == np.float64
    ref, _, _ = scipy_equal_arclength(path, 300, 50, interval=64)
    np.testing.assert_allclose(out, ref, atol=1e-4)


# ---------------------------------------------------------------------------------------------
# velocity, integrate, rotation
# ---------------------------------------------------------------------------------------------


def test_velocity_by_hand_and_reflected_first_element():
    x = jnp.array([[0.0], [1.0], [3.0], [6.0]])
    # differences 1, 2, 3; the first element reflects to the second difference (numpy 'reflect')
    np.testing.assert_array_equal(trajectory.velocity(x), [[2.0], [1.0], [2.0], [3.0]])
    d = np.diff(np.asarray(x), axis=0)
    np.testing.assert_array_equal(trajectory.velocity(x), np.pad(d, ((1, 0), (0, 0)), mode="reflect"))
    np.testing.assert_array_equal(trajectory.integrate(jnp.array([0.0]), jnp.array(
        [[99.0], [1.0], [2.0], [3.0]])), x)  # v[0] is ignored


@pytest.mark.parametrize("shape", [(7, 3), (4, 7, 3), (2, 3, 7, 2)])
def test_velocity_integrate_round_trip(shape):
    x = jax.random.normal(jax.random.key(0), shape)
    v = trajectory.velocity(x)
    chex.assert_shape(v, shape)
    np.testing.assert_array_equal(v[..., 0, :], v[..., 2, :])
    np.testing.assert_allclose(trajectory.integrate(x[..., 0, :], v), x, atol=1e-5)


def test_rotate_y_is_the_reference_matrix_on_row_vectors():
    theta = 0.9
    c, s = math.cos(theta), math.sin(theta)
    R = np.array([[c, 0, -s], [0, 1, 0], [s, 0, c]])
    assert np.isclose(np.linalg.det(R), 1.0)
    x = np.asarray(jax.random.normal(jax.random.key(1), (5, 4, 3)))
    np.testing.assert_allclose(trajectory.rotate_y(x, theta), x @ R, atol=1e-6)
    # quarter turn by hand: +x goes to -z, +z to +x
    np.testing.assert_allclose(trajectory.rotate_y(jnp.array([[1.0, 2.0, 0.0], [0.0, 0.0, 1.0]]),
                                               math.pi / 2), [[0, 2, -1], [1, 0, 0]], atol=1e-6)
    # per-sample angles: (B,) and (B, 1) agree; the 2-D (x, z) form agrees with the 3-D one
    th = np.array([0.1, 0.5, 1.0, 2.0, 3.0])
    np.testing.assert_allclose(trajectory.rotate_y(x, th), trajectory.rotate_y(x, th[:, None]))
    np.testing.assert_allclose(trajectory.rotate_y(x[..., 0::2], th), trajectory.rotate_y(x, th)[..., 0::2],
                               atol=1e-6)
    np.testing.assert_allclose(trajectory.rotate_y(x, th)[1], x[1] @ np.array(
        [[math.cos(0.5), 0, -math.sin(0.5)], [0, 1, 0], [math.sin(0.5), 0, math.cos(0.5)]]),
        atol=1e-6)


def test_rotate_rows_y_turns_every_joint_triple_by_its_samples_angle():
    pose_BxTxR = np.asarray(jax.random.normal(jax.random.key(2), (2, 3, 12)), np.float64)  # 4 joints
    th_BxT = np.array([[0.0, 0.4, 1.1], [2.0, -0.7, 3.0]])
    got = np.asarray(trajectory.rotate_rows_y(pose_BxTxR, th_BxT))
    for b in range(2):
        for t in range(3):
            c, s = math.cos(th_BxT[b, t]), math.sin(th_BxT[b, t])
            R = np.array([[c, 0, -s], [0, 1, 0], [s, 0, c]])  # the reference's row-vector matrix
            np.testing.assert_allclose(got[b, t], (pose_BxTxR[b, t].reshape(4, 3) @ R).reshape(12), atol=1e-6)
    # one angle per window (B,) turns all its samples alike
    np.testing.assert_allclose(trajectory.rotate_rows_y(pose_BxTxR, th_BxT[:, 1]),
                               trajectory.rotate_rows_y(pose_BxTxR, np.repeat(th_BxT[:, 1:2], 3, 1)), atol=1e-6)


# ---------------------------------------------------------------------------------------------
# shapes, user curves, files, degenerate curves
# ---------------------------------------------------------------------------------------------


def polyline_length(p):
    return float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum())


def test_heading_is_the_angle_rotate_y_turns_plus_z_into():
    v = jnp.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 5.0, -2.0], [-3.0, 0.0, 0.0]])
    np.testing.assert_allclose(trajectory.heading(v), [0.0, np.pi / 2, np.pi, -np.pi / 2], atol=1e-6)
    th = jnp.linspace(-3.0, 3.0, 13)
    np.testing.assert_allclose(trajectory.heading(trajectory.rotate_y(jnp.array([0.0, 0.0, 0.3]), th)), th, atol=1e-6)


def test_smooth_heading_by_hand_and_against_numpy():
    # a constant direction is kept exactly, whatever the speed
    v = jnp.array([[[0.2, 0.0, 0.2], [1.0, 0.0, 1.0], [0.5, 0.0, 0.5], [3.0, 0.0, 3.0]]])
    np.testing.assert_allclose(trajectory.smooth_heading(v), np.full((1, 4), np.pi / 4), atol=1e-6)
    # a 90-degree corner: the middle sample averages 3 unit vectors along +z and 2 along +x,
    # weights 1+4+6 = 11 and 4+1 = 5, so its heading is atan2(5, 11)
    corner = jnp.array([[0, 0, 1]] * 4 + [[1, 0, 0]] * 4, jnp.float32)
    got = np.asarray(trajectory.smooth_heading(corner))
    assert got[3] == pytest.approx(np.arctan2(5, 11), abs=1e-6)
    assert got[0] == pytest.approx(0.0, abs=1e-6) and got[-1] == pytest.approx(np.pi / 2, abs=1e-6)
    assert np.all(np.diff(got) >= -1e-7)  # turns monotonically through the corner
    # independent numpy version (edge-replicated weighted mean of unit vectors) on random walks
    rng = np.random.default_rng(0)
    w = rng.normal(size=(3, 20, 3)) + np.array([0.0, 0.0, 2.0])
    u = w[..., 0::2] / np.linalg.norm(w[..., 0::2], axis=-1, keepdims=True)
    pad = np.concatenate([u[:, :1], u[:, :1], u, u[:, -1:], u[:, -1:]], axis=1)
    k = np.array([1, 4, 6, 4, 1]) / 16
    avg = sum(k[i] * pad[:, i:i + 20] for i in range(5))
    np.testing.assert_allclose(trajectory.smooth_heading(jnp.asarray(w, jnp.float32)),
                               np.arctan2(avg[..., 0], avg[..., 1]), atol=1e-5)


@pytest.mark.parametrize("name", curves.SHAPES)
def test_shapes_start_at_origin_equally_spaced(name):
    p = curves.shape_curve(name, length=7.0, scale=1.5, num_points=300)
    chex.assert_shape(p, (300, 2))
    np.testing.assert_array_equal(p[0], [0, 0])
    np.testing.assert_allclose(polyline_length(p), 7.0, rtol=2e-3)


def test_circle_closes_with_its_radius_and_length():
    r = 1.25
    p = curves.shape_curve("circle", scale=r, num_points=400)
    np.testing.assert_allclose(p[-1], p[0], atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(p - [0, r], axis=1), r, atol=1e-9)
    np.testing.assert_allclose(polyline_length(p), 2 * math.pi * r, rtol=1e-4)
    laps = curves.shape_curve("circle", scale=r, length=4 * math.pi * r, num_points=401)
    np.testing.assert_allclose(laps[[200, 400]], [[0, 0], [0, 0]], atol=1e-9)  # two laps
    f8 = curves.shape_curve("figure8", scale=r, num_points=401)
    np.testing.assert_allclose(f8[-1], [0, 0], atol=1e-9)
    np.testing.assert_allclose(f8[200], [0, 0], atol=1e-9)  # the crossing, half way


def test_corner_turns_ninety_degrees_and_line_length():
    p = curves.shape_curve("corner", scale=2.0, num_points=401)  # 4 m, corner at point 200
    np.testing.assert_allclose(p[200], [2.0, 0.0], atol=1e-9)
    d_in, d_out = p[100] - p[0], p[-1] - p[300]
    cosang = d_in @ d_out / np.linalg.norm(d_in) / np.linalg.norm(d_out)
    np.testing.assert_allclose(cosang, 0.0, atol=1e-12)
    np.testing.assert_allclose(p[-1], [2.0, 2.0], atol=1e-9)
    line = curves.shape_curve("line", scale=3.0, num_points=11)
    np.testing.assert_allclose(line, np.stack([np.linspace(0, 3, 11), np.zeros(11)], -1))


def test_unknown_shape_lists_valid_names():
    with pytest.raises(ValueError, match="circle.*figure8"):
        curves.shape_curve("spiral")


def test_resample_polyline_count_spacing_and_smoothing():
    pts = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 0.0], [3.0, 0.0]])  # a duplicate point too
    out = curves.resample_polyline(pts, num_points=7)
    np.testing.assert_allclose(out, np.stack([np.linspace(0, 3, 7), np.zeros(7)], -1))
    out = curves.resample_polyline(pts, spacing=0.4)  # 3 m: 8 points, 0.2 m left over
    np.testing.assert_allclose(out[:, 0], np.arange(8) * 0.4)
    assert len(curves.resample_polyline(pts)) == len(pts)
    # an L-shaped polyline: equal spacing along the path (distance 1 + 1 = 2 m, 5 points)
    out = curves.resample_polyline([[0, 0], [1, 0], [1, 1]], num_points=5)
    np.testing.assert_allclose(out, [[0, 0], [0.5, 0], [1, 0], [1, 0.5], [1, 1]])
    # a 12-gon around a circle: the polyline cuts the corners, the spline through the vertices
    # (point index as parameter) follows the circle
    poly = curves.shape_curve("circle", scale=2.0, num_points=13)
    radius = lambda p: np.linalg.norm(p - [0, 2], axis=1)  # noqa: E731
    assert radius(curves.resample_polyline(poly, num_points=100)).min() < 1.95
    sm = curves.resample_polyline(poly, num_points=100, smooth_interval=1)
    chex.assert_shape(sm, (100, 2))
    np.testing.assert_allclose(radius(sm), 2.0, atol=5e-3)
    # with knots every 3rd point it is the scipy spline through those points
    sm3 = curves.resample_polyline(poly, num_points=50, smooth_interval=3)
    dense = CubicSpline(knot_frames(13, 3), poly[knot_frames(13, 3)])(np.linspace(0, 12, 120001))
    dist = [np.linalg.norm(dense - p, axis=1).min() for p in sm3]  # dense: 0.1 mm apart
    assert max(dist) < 1e-4
    np.testing.assert_allclose(sm3[[0, -1]], poly[[0, -1]], atol=1e-6)
    with pytest.raises(ValueError, match="not both"):
        curves.resample_polyline(pts, num_points=3, spacing=0.1)
    with pytest.raises(curves.DegenerateCurveError, match="shorter than one spacing"):
        curves.resample_polyline(pts, spacing=5.0)


@pytest.mark.parametrize("points, match", [
    ([[1.0, 2.0]], "at least 2 points"),
    ([[1.0, 2.0], [1.0, 2.0], [1.0, 2.0]], "zero length"),
    ([[0.0, 0.0], [np.nan, 1.0]], "point 1 is not finite"),
    ([[0.0, 0.0], [1.0, np.inf]], "not finite"),
    ([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]], r"\(P, 2\)"),
    ([], r"\(P, 2\)"),
])
def test_degenerate_curves(points, match):
    with pytest.raises(curves.DegenerateCurveError, match=match):
        curves.check_curve(points, "my curve")
    with pytest.raises(curves.DegenerateCurveError, match="curve"):
        curves.resample_polyline(points, num_points=4)


def test_loaders(tmp_path):
    (tmp_path / "a.csv").write_text("x,z\n0,0\n1.5, 0\n\n# comment\n1.5,2e0\n")
    np.testing.assert_array_equal(curves.load_curve_file(tmp_path / "a.csv"),
                                  [[0, 0], [1.5, 0], [1.5, 2]])
    (tmp_path / "b.txt").write_text("0 0\n1 1\n")
    np.testing.assert_array_equal(curves.load_curve_file(tmp_path / "b.txt"), [[0, 0], [1, 1]])
    (tmp_path / "c.json").write_text(json.dumps([[0, 0], [1, 2.5]]))
    np.testing.assert_array_equal(curves.load_curve_file(tmp_path / "c.json"), [[0, 0], [1, 2.5]])
    (tmp_path / "d.json").write_text(json.dumps({"points": [[0, 0], [0, 3]]}))
    np.testing.assert_array_equal(curves.load_curve_file(tmp_path / "d.json"), [[0, 0], [0, 3]])


@pytest.mark.parametrize("name, text, err, match", [
    ("bad.csv", "x,z\n0,0\n1,oops\n", curves.CurveFileError, "line 3"),
    ("cols.csv", "0,0,0\n1,1,1\n", curves.CurveFileError, "2 columns"),
    ("empty.csv", "x,z\n", curves.CurveFileError, "no x,z rows"),
    ("nan.csv", "0,0\nnan,1\n", curves.DegenerateCurveError, "not finite"),
    ("one.csv", "0,0\n", curves.DegenerateCurveError, "at least 2"),
    ("bad.json", "[[0, 0], [1, 1]", curves.CurveFileError, "invalid JSON"),
    ("key.json", '{"pts": []}', curves.CurveFileError, "no 'points' key"),
    ("pair.json", "[[0, 0], [1]]", curves.CurveFileError, "point 1"),
    ("same.json", "[[1, 1], [1, 1]]", curves.DegenerateCurveError, "zero length"),
    ("curve.npy", "", curves.CurveFileError, "unsupported"),
])
def test_malformed_files_name_the_file(tmp_path, name, text, err, match):
    f = tmp_path / name
    f.write_text(text)
    with pytest.raises(err, match=match) as info:
        curves.load_curve_file(f)
    assert name in str(info.value)


def test_missing_file_and_root_positions(tmp_path):
    with pytest.raises(curves.CurveFileError, match="nope.csv"):
        curves.load_curve_file(tmp_path / "nope.csv")
    root = np.array([[0.0, 0.9, 0.0], [0.1, 0.95, 0.2], [0.3, 0.9, 0.1]])
    np.testing.assert_array_equal(trajectory.floor_path(root), root[:, [0, 2]])
    np.testing.assert_array_equal(curves.curve_from_root_positions(root), root[:, [0, 2]])
    with pytest.raises(curves.DegenerateCurveError, match="zero length"):
        curves.curve_from_root_positions(np.zeros((5, 3)))


def test_window_frame_turns_the_travel_to_plus_z_and_ignores_the_first_velocity():
    """By hand: travel along +x (heading pi/2) is turned to +z, and a pose row along +x with it;
    v[0] (a copy of v[1] in `velocity`) does not enter the heading; a still window is unturned."""
    from motiongan_jax.motion.trajectory import window_frame

    T = 8
    v_x = jnp.zeros((1, T, 3)).at[..., 0].set(0.1).at[0, 0].set(jnp.array([0.0, 0.0, -5.0]))
    v_c, p_c = window_frame(v_x, jnp.tile(jnp.array([1.0, 2.0, 0.0]), (1, T, 1)))
    chex.assert_shape((v_c, p_c), (1, T, 3))
    np.testing.assert_allclose(np.asarray(v_c[0, 3]), [0, 0, 0.1], atol=1e-6)
    np.testing.assert_allclose(np.asarray(p_c[0, 3]), [0, 2, 1], atol=1e-6)
    still_v, still_p = window_frame(jnp.zeros((1, T, 3)), jnp.ones((1, T, 3)))
    np.testing.assert_array_equal(np.asarray(still_p), np.ones((1, T, 3)))
