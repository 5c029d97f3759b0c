"""The input curve: root path on the floor -> spline -> equal-arc-length points.

Units are metres, Y up, floor = X-Z plane; every 2-D curve here is (x, z).

Training hot path (pure jnp, jit-able, batched): `window_curves`. Whole clips and user curves
(numpy around the same spline core): `spline_curve`, `resample_polyline`, `load_curve_file`,
`curve_from_root_positions`, `shape_curve`, `check_curve`. Velocities, rotations and floor points
are motion geometry (`motion.trajectory`).

Spline (docs/DESIGN.md §2.3, with the reference's bugs fixed):
- knots at frames 0, I, 2I, ... < n-1 plus a final knot at frame n-1 holding r[n-1]. The
  reference gave the final knot the value r[n-2] (off by one) and crashed when n-1 was a
  multiple of I (duplicate knot); neither happens here.
- not-a-knot cubic through the knots (= scipy CubicSpline(bc_type='not-a-knot') =
  interp1d(kind='cubic')); 3 knots give the interpolating parabola (the reference's quadratic
  fallback gives the same curve), 2 knots the straight line.
- it is solved for the knot second derivatives ("moments") with one small dense system per
  sample, K = ceil((N-1)/I)+1 knots at most; unused knots get identity rows, so every shape is
  static and the batch never leaves the device.
"""

from __future__ import annotations

import functools
import json
import math
import pathlib
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from motiongan_jax.motion import trajectory

# Arc length is the chord sum of the spline sampled every 1/SUBSTEPS frame. With knots >= tens
# of frames apart the chord error is ~(kappa*h)^2/24 relative, far below 1e-6 at 4 sub-steps,
# while the table stays small (4 * 1535 entries for a 1536-frame window). The reference used
# 1 sub-step in training and 10 for its cache.
SUBSTEPS = 4
# The same for smoothed user curves, per input point: drawn points can be ~1 m apart on a tight
# turn, so use more (3000 points -> a 96k-entry table, still instant).
SMOOTH_SUBSTEPS = 32

SHAPES = ("line", "circle", "s_curve", "figure8", "corner")


class DegenerateCurveError(ValueError):
    """A curve that cannot drive the generator: too few distinct points, zero length, NaN/inf, or
    the wrong shape. The message names the curve (e.g. its file) and the problem."""


class CurveFileError(ValueError):
    """A curve file that cannot be read or parsed; the message names the file and the problem."""


# ---------------------------------------------------------------------------------------------
# Spline core (jnp, batched)
# ---------------------------------------------------------------------------------------------


class Spline(NamedTuple):
    """A batch of not-a-knot splines in knot units u = frame / interval (knot i at u = i, the
    last knot at u = (n-1)/interval). Values are relative to `origin_Bx2` for float32 accuracy."""

    y_BxKx2: jax.Array  # knot values minus origin (0 for unused knots)
    m_BxKx2: jax.Array  # second derivatives d2y/du2 at the knots (0 for unused knots)
    h_BxK: jax.Array  # knot spacing in u (1 except the last used segment, 1 for unused)
    num_knots_B: jax.Array  # int32, >= 2
    origin_Bx2: jax.Array  # path[0]


def max_knots(num_frames: int, interval: int) -> int:
    """K: the knot count of an N-frame path (the most any shorter path in the batch can need)."""
    return max(-(-(num_frames - 1) // interval), 1) + 1


def fit_spline(path_xz_BxNx2, length_B, interval: int) -> Spline:
    """Fits each sample's spline through its frames [0, length_b) (knots as in the module doc).

    length_b is clipped to [1, N]; a 1-frame path gives a constant spline. Frames at or past
    length_b are never read into the fit, so any padding (even NaN) is harmless.
    """
    path = jnp.asarray(path_xz_BxNx2)
    if not jnp.issubdtype(path.dtype, jnp.floating):
        path = path.astype(jnp.float32)
    B, N, _ = path.shape
    interval = int(interval)
    if interval < 1:
        raise ValueError(f"interval must be >= 1 frame, got {interval}")
    K = max_knots(N, interval)
    dtype = path.dtype
    length = jnp.clip(jnp.asarray(length_B, jnp.int32), 1, N)
    last = length - 1  # frame of the final knot
    # Knot count m = ceil((n-1)/I) + 1; at least 2 so a single-frame path is a (constant) line.
    m = jnp.maximum((last + interval - 1) // interval, 1) + 1
    k = jnp.arange(K, dtype=jnp.int32)
    used = k[None, :] < m[:, None]
    frame = jnp.where(k[None, :] < m[:, None] - 1, k[None, :] * interval, last[:, None])
    frame = jnp.clip(frame, 0, N - 1)
    origin = path[:, 0, :]
    y = jnp.take_along_axis(path, frame[..., None], axis=1) - origin[:, None, :]
    y = jnp.where(used[..., None], y, 0)
    # u of the final knot is max(n-1, 1)/I: a 1-frame path keeps a non-zero spacing (its two
    # knots hold the same value, and evaluation is clipped to frame 0 anyway).
    h_last = (jnp.maximum(last, 1).astype(dtype) / interval) - (m - 2).astype(dtype)
    h = jnp.where(k[None, :] == m[:, None] - 2, h_last[:, None], 1.0).astype(dtype)

    h_prev = jnp.concatenate([jnp.ones((B, 1), dtype), h[:, :-1]], axis=1)
    y_prev = jnp.concatenate([jnp.zeros((B, 1, 2), dtype), y[:, :-1]], axis=1)
    y_next = jnp.concatenate([y[:, 1:], jnp.zeros((B, 1, 2), dtype)], axis=1)
    kk, mm = k[None, :], m[:, None]
    interior = (kk >= 1) & (kk <= mm - 2)
    first, lastrow = kk == 0, kk == mm - 1
    m4, m3 = mm >= 4, mm == 3
    h0, h1 = h[:, :1], h[:, 1:2]  # K >= 2 always
    h_a = jnp.take_along_axis(h, jnp.maximum(m - 3, 0)[:, None], axis=1)  # h_{m-3}
    h_b = h_last[:, None]  # h_{m-2}
    one = jnp.ones_like(h)
    # Rows: interior continuity of the first derivative; not-a-knot (third derivative continuous
    # at knots 1 and m-2) for the end rows when m >= 4; M0 = M1 = M2 (parabola) when m == 3;
    # M0 = M1 = 0 (line) when m == 2; identity rows for unused knots.
    c0 = jnp.where(interior, 2 * (h_prev + h),
                   jnp.where(first & m4, h1, jnp.where(lastrow & m4, h_a, one)))
    c_m1 = jnp.where(interior, h_prev, jnp.where(lastrow & m4, -(h_a + h_b),
                                                 jnp.where(lastrow & m3, -one, 0)))
    c_m2 = jnp.where(lastrow & m4, h_b, 0)
    c_p1 = jnp.where(interior, h, jnp.where(first & m4, -(h0 + h1),
                                            jnp.where(first & m3, -one, 0)))
    c_p2 = jnp.where(first & m4, h0, 0)
    A = sum(c[..., None] * jnp.eye(K, k=d, dtype=dtype)
            for d, c in ((-2, c_m2), (-1, c_m1), (0, c0), (1, c_p1), (2, c_p2)))
    rhs = 6 * ((y_next - y) / h[..., None] - (y - y_prev) / h_prev[..., None])
    rhs = jnp.where(interior[..., None], rhs, 0)
    moments = jnp.linalg.solve(A, rhs)
    return Spline(y, moments, h, m, origin)


def eval_spline(spline: Spline, x_BxP, interval: int) -> jax.Array:
    """The splines at frame positions x_BxP (float frames; clip them to [0, n-1] beforehand)."""
    y, M, h, m = spline.y_BxKx2, spline.m_BxKx2, spline.h_BxK, spline.num_knots_B
    u = jnp.asarray(x_BxP, y.dtype) / interval
    j = jnp.clip(jnp.floor(u).astype(jnp.int32), 0, (m - 2)[:, None])
    hj = jnp.take_along_axis(h, j, axis=1)[..., None]

    def at(v, idx):
        return jnp.take_along_axis(v, idx[..., None], axis=1)

    yj, yj1, Mj, Mj1 = at(y, j), at(y, j + 1), at(M, j), at(M, j + 1)
    b = (u - j.astype(u.dtype))[..., None]
    a = hj - b
    out = ((Mj * a**3 + Mj1 * b**3) / (6 * hj)
           + (yj / hj - Mj * hj / 6) * a + (yj1 / hj - Mj1 * hj / 6) * b)
    return out + spline.origin_Bx2[:, None, :]


def _grid_frames(N: int, length_B, dtype) -> jax.Array:
    """Sub-step grid k / SUBSTEPS, k = 0 .. SUBSTEPS (N-1), clipped to each sample's last frame."""
    g = jnp.arange(SUBSTEPS * (N - 1) + 1, dtype=dtype) / SUBSTEPS
    last = (jnp.clip(jnp.asarray(length_B, jnp.int32), 1, N) - 1).astype(dtype)
    return jnp.minimum(g[None, :], last[:, None])


def window_indices(num_frames: int, T: int, frame_step: int = 1, stride: int | None = None,
                   max_windows: int | None = None) -> np.ndarray:
    """Frame indices (N, T) of the windows of a clip of `num_frames` frames: T samples `frame_step`
    frames apart, one starting every `stride` frames from frame 0 (default T·frame_step: back to
    back), every one that fits (N = 0 when none does), at most `max_windows`. The evaluation's and
    analysis's windows; training draws its own (data.make_sample_batch)."""
    span = (T - 1) * frame_step + 1
    starts = np.arange(0, max(int(num_frames) - span + 1, 0), T * frame_step if stride is None else stride)
    if max_windows is not None:
        starts = starts[: int(max_windows)]
    return starts[:, None] + frame_step * np.arange(T)[None, :]


def window_curves(path_xz_BxNx2, length_B, T: int, interval: int, noise=0.0, key=None):
    """Input curves of a batch of windows: T points of equal arc length along each window's spline.

    path_xz_BxNx2: floor paths (x, z) in metres; sample b uses frames [0, length_b), the rest is
      padding (never read). N, T and interval are static; length_B is a dynamic int32 vector.
    Returns curve_BxTx2. Point 0 is the spline at frame 0 (= the raw root point path[b, 0]);
    point T-1 is the spline at frame length_b - 1.

    Unlike the reference, which emitted points only on the frame grid (up to ~10% of a spacing
    off), the points are exactly equally spaced in arc length: the arc-length table (chord sums
    every 1/SUBSTEPS frame) is inverted by linear interpolation and the spline is evaluated at
    the resulting fractional frames.

    noise > 0 (needs `key`; the only randomness used) adds, to points 1..T-1 (point 0 stays the
    exact start, as in the reference): timing jitter N(0, (noise*step)^2) frames on the
    parameter, step = length_b / T, clipped to [0, length_b - 1]; then spatial jitter
    N(0, (noise*spacing)^2) on x and on z. noise = 0 is exactly the noise-free curve. A path
    that stands still gives T copies of its start point (no NaN).
    """
    path = jnp.asarray(path_xz_BxNx2)
    if not jnp.issubdtype(path.dtype, jnp.floating):
        path = path.astype(jnp.float32)
    B, N, D = path.shape
    if D != 2:
        raise ValueError(f"path must be (B, N, 2) floor (x, z) points, got shape {path.shape}")
    T = int(T)
    if T < 2:
        raise ValueError(f"T must be >= 2, got {T}")
    noise_free = isinstance(noise, (int, float, np.number)) and noise == 0
    if key is None and not noise_free:
        raise ValueError("window_curves: noise needs a PRNG key (pass key=..., or noise=0.0)")
    dtype = path.dtype
    length = jnp.clip(jnp.asarray(length_B, jnp.int32), 1, N)
    last = (length - 1).astype(dtype)
    spline = fit_spline(path, length, interval)

    grid = _grid_frames(N, length, dtype)  # (B, G)
    pts = eval_spline(spline, grid, interval)
    seg = jnp.sqrt(jnp.sum(jnp.square(pts[:, 1:] - pts[:, :-1]), axis=-1))
    cum = jnp.concatenate([jnp.zeros((B, 1), dtype), jnp.cumsum(seg, axis=1)], axis=1)
    total = cum[:, -1]
    frac_T = jnp.arange(T, dtype=dtype) / (T - 1)  # exact 0 and 1 at the ends
    target = total[:, None] * frac_T[None, :]
    # First table entry reaching each target; linear inversion inside that sub-step. Flat spots
    # (standing still, padding) resolve to their first entry and are guarded against 0/0.
    hi = jax.vmap(lambda c, t: jnp.searchsorted(c, t, side="left"))(cum, target)
    hi = jnp.clip(hi, 1, cum.shape[1] - 1)
    lo = hi - 1
    c_lo, c_hi = jnp.take_along_axis(cum, lo, 1), jnp.take_along_axis(cum, hi, 1)
    g_lo, g_hi = jnp.take_along_axis(grid, lo, 1), jnp.take_along_axis(grid, hi, 1)
    dc = c_hi - c_lo
    w = jnp.where(dc > 0, (target - c_lo) / jnp.where(dc > 0, dc, 1), 0)
    x = g_lo + jnp.clip(w, 0, 1) * (g_hi - g_lo)
    t_idx = jnp.arange(T)[None, :]
    x = jnp.where(t_idx == 0, 0, jnp.where(t_idx == T - 1, last[:, None], x))

    if not noise_free:
        k_time, k_space = jax.random.split(key)
        step = length.astype(dtype) / T
        spacing = total / (T - 1)
        jitter_t = jax.random.normal(k_time, (B, T), dtype) * (noise * step)[:, None]
        x = jnp.where(t_idx == 0, x, jnp.clip(x + jitter_t, 0, last[:, None]))
        curve = eval_spline(spline, x, interval)
        jitter_xz = jax.random.normal(k_space, (B, T, 2), dtype) * (noise * spacing)[:, None, None]
        return curve + jnp.where(t_idx[..., None] == 0, 0, jitter_xz)
    return eval_spline(spline, x, interval)


_clean_curves_jit = jax.jit(functools.partial(window_curves, noise=0.0, key=None),
                            static_argnames=("T", "interval"))
_fit_spline_jit = jax.jit(fit_spline, static_argnames="interval")
_eval_spline_jit = jax.jit(eval_spline, static_argnames="interval")


# ---------------------------------------------------------------------------------------------
# Whole clips and user curves (numpy, float64 out)
# ---------------------------------------------------------------------------------------------


def check_curve(points, what: str = "curve") -> np.ndarray:
    """Validates a user curve and returns it as a (P, 2) float64 array.

    Raises DegenerateCurveError (naming `what`) for a wrong shape, NaN/inf, fewer than 2 points,
    or zero length (all points identical).
    """
    try:
        pts = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise DegenerateCurveError(f"{what}: not an array of numbers ({e})") from None
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise DegenerateCurveError(f"{what}: expected (P, 2) floor points (x, z), got shape "
                                   f"{pts.shape}")
    bad = ~np.isfinite(pts).all(axis=1)
    if bad.any():
        raise DegenerateCurveError(f"{what}: point {int(np.argmax(bad))} is not finite "
                                   f"({pts[bad][0].tolist()}); {int(bad.sum())} bad point(s)")
    if len(pts) < 2:
        raise DegenerateCurveError(f"{what}: needs at least 2 points, got {len(pts)}")
    length = float(np.sum(np.linalg.norm(np.diff(pts, axis=0), axis=1)))
    if not length > 0:
        raise DegenerateCurveError(f"{what}: zero length (all {len(pts)} points are identical, "
                                   f"fewer than 2 distinct points)")
    return pts


def spline_curve(path_xz_Nx2, T: int, interval: int) -> np.ndarray:
    """Noise-free input curve of a whole clip: T equal-arc-length points, (T, 2) float64.

    Runs `window_curves` with B = 1 (float32 unless jax x64 is on; values are fitted relative
    to the start point). The path is padded to a multiple of 512 frames so clips of similar
    length share one compilation.
    """
    path = np.asarray(path_xz_Nx2, dtype=np.float64)
    if path.ndim != 2 or path.shape[1] != 2 or len(path) < 1:
        raise ValueError(f"spline_curve: expected an (N, 2) path, got shape {path.shape}")
    n = len(path)
    n_pad = -(-n // 512) * 512
    padded = np.concatenate([path, np.repeat(path[-1:], n_pad - n, axis=0)])[None]
    out = _clean_curves_jit(padded, np.array([n], np.int32), T=int(T), interval=int(interval))
    return np.asarray(out[0], dtype=np.float64)


def resample_polyline(points_Px2, num_points: int | None = None, spacing: float | None = None,
                      smooth_interval: int | None = None) -> np.ndarray:
    """Equal-arc-length resampling of a user curve (e.g. drawn, loaded or a built-in shape).

    points_Px2: (x, z) points in metres along the curve (consecutive duplicates are fine).
    num_points: M points from start to end, equally spaced (default: as many as the input).
    spacing: metres between consecutive points, i.e. distance per network sample (the speed
      control); gives floor(length / spacing) + 1 points from the start, the remainder shorter
      than one spacing at the end is dropped. Give num_points or spacing, not both.
    smooth_interval: follow the not-a-knot spline through every smooth_interval-th point (and
      the last) instead of the polyline, with the point index as parameter, like frames in
      window_curves. Output points then lie on the spline, found as in window_curves by
      inverting its arc-length table (SMOOTH_SUBSTEPS chords per input point).
    Returns (M, 2) float64. Raises DegenerateCurveError for a degenerate curve or one shorter
    than a single spacing.
    """
    pts = check_curve(points_Px2, "curve")
    if num_points is not None and spacing is not None:
        raise ValueError("resample_polyline: give num_points or spacing, not both")
    P = len(pts)
    if smooth_interval is not None:
        interval = int(smooth_interval)
        if interval < 1:
            raise ValueError(f"smooth_interval must be >= 1, got {smooth_interval}")
        spline = _fit_spline_jit(pts[None], np.array([P], np.int32), interval=interval)
        param = np.arange((P - 1) * SMOOTH_SUBSTEPS + 1, dtype=np.float64) / SMOOTH_SUBSTEPS
        table = np.asarray(_eval_spline_jit(spline, param[None], interval=interval)[0],
                           dtype=np.float64)
    else:
        param, table = np.arange(P, dtype=np.float64), pts
    seg = np.linalg.norm(np.diff(table, axis=0), axis=1)
    keep = np.concatenate([[True], seg > 0])  # np.interp needs strictly increasing lengths
    cum = np.concatenate([[0.0], np.cumsum(seg)])[keep]
    param, table = param[keep], table[keep]
    total = cum[-1]
    if total <= 0:
        raise DegenerateCurveError("curve: the smoothed curve has zero length")
    if spacing is not None:
        spacing = float(spacing)
        if not (math.isfinite(spacing) and spacing > 0):
            raise ValueError(f"spacing must be a positive number of metres, got {spacing}")
        count = int(math.floor(total / spacing * (1 + 1e-12))) + 1
        if count < 2:
            raise DegenerateCurveError(f"curve: length {total:.4g} m is shorter than one "
                                       f"spacing ({spacing:.4g} m)")
        target = np.arange(count) * spacing
    else:
        count = P if num_points is None else int(num_points)
        if count < 2:
            raise ValueError(f"num_points must be >= 2, got {count}")
        target = np.linspace(0.0, total, count)
    if smooth_interval is None:
        return np.stack([np.interp(target, cum, table[:, 0]), np.interp(target, cum, table[:, 1])],
                        -1)
    x = np.interp(target, cum, param)
    return np.asarray(_eval_spline_jit(spline, x[None], interval=interval)[0], dtype=np.float64)


def curve_from_bvh(path_or_motion, units_to_m: float | None = None) -> np.ndarray:
    """The floor path (metres) of a BVH file's root (the representation root: the pelvis), from
    its path or an already read `bvh.Motion`. Units default to a guess from the skeleton's leg
    length (CMU units, cm, inches or m)."""
    from motiongan_jax.motion import bvh, kinematics, representation

    motion = path_or_motion if isinstance(path_or_motion, bvh.Motion) else bvh.read_bvh(path_or_motion)
    units = representation.guess_units_to_m(motion.skeleton) if units_to_m is None else units_to_m
    root = representation.representation_root(motion.skeleton)
    return curve_from_root_positions(kinematics.world_positions(motion)[:, root] * units)


def curve_from_root_positions(root_Fx3) -> np.ndarray:
    """A user curve from another motion's root positions (F, 3): its floor path, validated."""
    root = np.asarray(root_Fx3, dtype=np.float64)
    if root.ndim != 2 or root.shape[1] != 3:
        raise DegenerateCurveError(f"root positions: expected (F, 3), got shape {root.shape}")
    return check_curve(trajectory.floor_path(root), "root positions")


def _parse_csv(text: str, where: str) -> list[list[float]]:
    rows: list[list[float]] = []
    seen_first = False
    for lineno, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        cells = [c.strip() for c in (line.split(",") if "," in line else line.split())]
        try:
            values = [float(c) for c in cells]
        except ValueError:
            if not seen_first:  # one header line is allowed
                seen_first = True
                continue
            raise CurveFileError(f"{where}: line {lineno}: expected two numbers x,z, got "
                                 f"{raw.strip()!r}") from None
        seen_first = True
        if len(values) != 2:
            raise CurveFileError(f"{where}: line {lineno}: expected 2 columns (x,z), got "
                                 f"{len(values)}")
        rows.append(values)
    if not rows:
        raise CurveFileError(f"{where}: no x,z rows found")
    return rows


def _parse_json(text: str, where: str) -> list[list[float]]:
    try:
        data = json.loads(text)
    except json.JSONDecodeError as e:
        raise CurveFileError(f"{where}: invalid JSON at line {e.lineno} column {e.colno}: "
                             f"{e.msg}") from None
    if isinstance(data, dict):
        if "points" not in data:
            raise CurveFileError(f"{where}: JSON object has no 'points' key (keys: "
                                 f"{sorted(data)})")
        data = data["points"]
    if not isinstance(data, list):
        raise CurveFileError(f"{where}: expected a list of [x, z] pairs or {{\"points\": [...]}}, "
                             f"got {type(data).__name__}")
    rows = []
    for i, p in enumerate(data):
        ok = (isinstance(p, list) and len(p) == 2
              and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in p))
        if not ok:
            raise CurveFileError(f"{where}: point {i} is not an [x, z] pair of numbers: {p!r}")
        rows.append([float(p[0]), float(p[1])])
    return rows


def load_curve_file(path) -> np.ndarray:
    """A user curve from a file: (P, 2) float64 (x, z) metres.

    .csv/.txt: two columns x,z per line (comma or whitespace separated), an optional header
    line, blank lines and '#' comments skipped. .json: a list of [x, z] pairs, or an object
    {"points": [...]}. Raises CurveFileError (unreadable/malformed) or DegenerateCurveError,
    both naming the file.
    """
    p = pathlib.Path(path)
    try:
        text = p.read_text()
    except (OSError, UnicodeDecodeError) as e:
        raise CurveFileError(f"{p}: cannot read curve file ({e})") from None
    suffix = p.suffix.lower()
    if suffix == ".json":
        rows = _parse_json(text, str(p))
    elif suffix in (".csv", ".txt"):
        rows = _parse_csv(text, str(p))
    else:
        raise CurveFileError(f"{p}: unsupported curve file type {suffix!r} (use .csv or .json)")
    return check_curve(rows, str(p))


# Shapes as curvature profiles: (segment length, curvature, heading turn before the segment),
# integrated exactly (straight lines and circular arcs), so points are equally spaced by
# construction. Heading psi: direction (cos psi, sin psi) in (x, z); every shape starts at the
# origin heading +x, and positive curvature turns towards +z.
def _shape_segments(name: str, r: float, length: float) -> list[tuple[float, float, float]]:
    two_pi = 2 * math.pi
    if name == "line":
        return [(length, 0.0, 0.0)]
    if name == "corner":
        return [(r, 0.0, 0.0), (max(length - r, 0.0), 0.0, math.pi / 2)]
    period = {"circle": [(two_pi * r, 1 / r)],
              "s_curve": [(math.pi * r, 1 / r), (math.pi * r, -1 / r)],
              "figure8": [(two_pi * r, 1 / r), (two_pi * r, -1 / r)]}[name]
    segs, acc = [], 0.0
    while acc < length:
        for seg_len, kappa in period:
            segs.append((seg_len, kappa, 0.0))
            acc += seg_len
    return segs


# one natural period of each shape per metre of its scale (shape_curve's doc)
_PERIOD_PER_SCALE = {"line": 1.0, "circle": 2 * math.pi, "s_curve": 2 * math.pi, "figure8": 4 * math.pi,
                     "corner": 2.0}


def natural_length(name: str, scale: float) -> float:
    """The arc length of one period of shape `name` at `scale` metres (shape_curve's doc)."""
    return _PERIOD_PER_SCALE[name] * scale


def scale_for_length(name: str, length: float) -> float:
    """The scale at which `length` metres is exactly one period of the shape: a circle whose
    circumference is the length, a figure-8 of two lobes, one S, a corner at half way."""
    return length / _PERIOD_PER_SCALE[name]


def shape_curve(name: str, length: float | None = None, scale: float = 2.0,
                num_points: int = 256) -> np.ndarray:
    """A built-in curve in metres, starting at the origin heading +x: (num_points, 2) float64,
    equally spaced in arc length.

    scale (m): line - its length; circle - radius (turning towards +z); s_curve - radius of its
    two half-circle turns (+z, then back); figure8 - radius of each of its two circles; corner -
    the length of the first leg before a sharp 90 degree turn towards +z.
    length (m): arc length travelled; None is one natural period (line: scale; circle: 2 pi r,
    closed; s_curve: 2 pi r; figure8: 4 pi r, closed; corner: 2 * scale). Longer lengths go
    round again (circle, figure8), keep weaving (s_curve) or extend the last leg (line, corner).
    """
    if name not in SHAPES:
        raise ValueError(f"unknown shape {name!r}; valid shapes: {', '.join(SHAPES)}")
    scale = float(scale)
    if not (math.isfinite(scale) and scale > 0):
        raise ValueError(f"scale must be a positive number of metres, got {scale}")
    length = natural_length(name, scale) if length is None else float(length)
    if not (math.isfinite(length) and length > 0):
        raise ValueError(f"length must be a positive number of metres, got {length}")
    if int(num_points) < 2:
        raise ValueError(f"num_points must be >= 2, got {num_points}")
    s = np.linspace(0.0, length, int(num_points))
    out = np.zeros((len(s), 2))
    pos, psi, s0 = np.zeros(2), 0.0, 0.0
    segs = _shape_segments(name, scale, length)
    for i, (seg_len, kappa, turn) in enumerate(segs):
        psi += turn
        end = s0 + seg_len
        sel = (s >= s0) & ((s < end) | (i == len(segs) - 1))
        ds = s[sel] - s0
        out[sel] = pos + _arc(psi, kappa, ds)
        pos = pos + _arc(psi, kappa, np.array([seg_len]))[0]
        psi += kappa * seg_len
        s0 = end
    return check_curve(out, f"shape {name!r}")


def _arc(psi: float, kappa: float, ds: np.ndarray) -> np.ndarray:
    """Displacement after travelling ds along a circle of curvature kappa from heading psi."""
    if kappa == 0:
        return ds[:, None] * np.array([math.cos(psi), math.sin(psi)])
    end = psi + kappa * ds
    return np.stack([(np.sin(end) - math.sin(psi)) / kappa,
                     (math.cos(psi) - np.cos(end)) / kappa], axis=-1)
