"""Streaming generation: a walker steered as it goes, one piece of path at a time.

A `Walker` holds a model, a style code w, the path walked so far and the gait state. `feed_steps`
(a floor direction and a speed per sample) or `feed_points` (floor points, one per sample) append
the path ahead, `revise_ahead` replaces the part not yet walked (the caller's prediction
of the path from its current input); `advance(n)` returns the next n motion samples, continuous with the ones before.

How. Every advance runs G once on a window of `window` samples of the path (one compiled shape
per walker configuration): `history` samples already walked, the n new ones, and the path ahead,
known for at least `lookahead` samples and extended straight on (walk.extend_straight) past what
is known. The window starts on G's downsampling grid (a multiple of 8 of the walk's sample index,
as walk.chunk_starts), so a window sees the samples the one-pass walk sees where they overlap.
 * Gait phase: the window starts at the phase the walk had at its first sample (kept in the ring),
   and G walks it on its own clock (model.apply.walked_phase): one clock for the whole walk, never
   restarted, whatever the window.
 * Root: G's root velocity is integrated from the last emitted root position (float64), so the
   path cannot jump between advances.
 * Pose and root velocity: a new window's outputs differ a little from the previous window's
   prediction for the same samples (its instance norms see other samples, its path ahead is
   newer). The difference at the first new sample is carried over and faded out over BLEND
   samples (inertialisation, as game character controllers do), so values continue exactly and
   the new window takes over smoothly.
 * Floor: whole-path generation lifts a clip by the 5th percentile of its lowest joint
   (walk.floor_shift), which needs the whole clip; a stream estimates the same over its ring of
   recent samples and moves its shift towards it by at most FLOOR_SLEW_M metres per sample.
 * Style: `set_style(w, blend_s)` moves w linearly to the new code over blend_s seconds of walk
   (each window runs with the code at its first new sample); the gait phase keeps running.

Lookahead costs latency: a sample is emitted only once the path `lookahead` samples beyond it is
known, i.e. lookahead / rate seconds after its input arrives (a caller that steers and predicts the
path ahead from the current input can feed that prediction and pay nothing but the prediction's
error). It costs quality below G's receptive radius (about 100 samples, walk.CHUNK_MARGIN): G's
output at a sample depends on the path that far ahead, which the stream replaces by a straight
extension; tests/test_stream.py states the difference to whole-path generation.

State is bounded: the ring keeps the last RING samples of path, phase and floor heights, and the
path ahead is capped at MAX_AHEAD samples beyond the next one to emit (StreamError beyond).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from motiongan_jax.generate import limits, walk
from motiongan_jax.model import apply as model_apply
from motiongan_jax.motion import trajectory
from motiongan_jax.motion.representation import from_rows

HISTORY = 128  # samples already walked that each window sees (>= G's receptive radius)
LOOKAHEAD = 32  # samples of path ahead that must be known before a sample is emitted
MAX_STEP = 16  # samples one advance emits at most
BLEND = 8  # samples over which a new window's difference to the previous one fades out
FLOOR_SLEW_M = 0.002  # metres per sample the floor shift moves at most
MAX_AHEAD = 1024  # samples of path known beyond the next one to emit, at most
MAX_SPEED_M_PER_S = 10.0  # a step's speed, at most


class StreamError(limits.GenerateError):
    """Input a walker refuses (non-finite, over a limit, out of order); the message says which."""


@dataclasses.dataclass(frozen=True, eq=False)
class Samples:
    """The next n samples of a walk (index0 is the walk's sample index of the first)."""
    index0: int
    positions: np.ndarray  # (n, J, 3) float64 metres, Y up, after the stream's floor shift
    root_velocity: np.ndarray  # (n, 3) G's root velocity (m per sample), after blending
    pose: np.ndarray  # (n, R) G's root-relative rows, after blending
    curve: np.ndarray  # (n, 3) the input path at these samples (x, 0, z)
    phase: np.ndarray | None  # (n,) gait phase (radians, unwrapped) or None (G without a clock)
    floor_shift_m: np.ndarray  # (n,) the shift added to each sample's heights


def window_length(history: int, lookahead: int, max_step: int = MAX_STEP) -> int:
    """G's input length for a walker: history (plus up to 7 for the grid), a step, lookahead;
    a multiple of 8."""
    return walk.padded_length(history + 7 + max_step + lookahead)


class Walker:
    """A walk generated as its path arrives (module doc). Not thread-safe: one caller at a time."""

    def __init__(self, model, layout, w_D, rate: float, *, start_xz=(0.0, 0.0), heading_xz=(1.0, 0.0),
                 speed_m_per_s: float = 1.0, phase0: float = 0.0, history: int = HISTORY,
                 lookahead: int = LOOKAHEAD, max_step: int = MAX_STEP, blend: int = BLEND):
        if history < 8 or history % 8:
            raise StreamError(f"history must be a positive multiple of 8 samples, got {history}")
        if not 0 <= lookahead <= MAX_AHEAD // 2:
            raise StreamError(f"lookahead must be 0 to {MAX_AHEAD // 2} samples, got {lookahead}")
        if not 1 <= max_step <= 256:
            raise StreamError(f"max_step must be 1 to 256 samples, got {max_step}")
        self.model = model_apply.generator_state(model)
        self.layout = layout
        self.rate = float(rate)
        self.history, self.lookahead = int(history), int(lookahead)
        self.max_step, self.blend = int(max_step), int(blend)
        self.window = window_length(self.history, self.lookahead, self.max_step)
        self.ring = self.window + 8
        self.gait = model_apply.has_gait_phase(self.model)
        w = self._check_w(w_D)
        self._w_from = self._w_to = w
        self._w_change, self._w_blend = -1, 1  # no blend under way: every sample has w
        # the path: points[k] is sample base + k; samples < emitted are walked
        start = self._check_xz(start_xz, "start")
        self._points = np.array([[start[0], 0.0, start[1]]], np.float64)
        self._base = 0
        self.emitted = 0  # the walk's next sample index to emit
        self._phase = np.array([float(phase0)])  # phase of samples base.. (emitted ones, and the next)
        self._lowest = np.zeros(0)  # each emitted sample's lowest joint height before the shift (ring)
        self._root = None  # the last emitted root position (3,)
        self._shift = None
        self._pending = None  # (root_vel, pose) the last window predicted for samples emitted..
        heading = self._check_xz(heading_xz, "heading")
        if np.linalg.norm(heading) < 1e-9:
            raise StreamError("heading must be a non-zero floor direction")
        self._last_dir = heading / np.linalg.norm(heading)
        self._last_speed = self._check_speed(speed_m_per_s)

    # ---- input -------------------------------------------------------------------------------

    def _check_w(self, w_D) -> np.ndarray:
        w = np.asarray(w_D, np.float32).reshape(-1)
        if not np.isfinite(w).all():
            raise StreamError("style code has non-finite values")
        return w

    @staticmethod
    def _check_xz(v, what: str) -> np.ndarray:
        a = np.asarray(v, np.float64)
        if a.shape != (2,) or not np.isfinite(a).all():
            raise StreamError(f"{what} must be two finite numbers (x, z metres), got {np.asarray(v).tolist()!r}"[:200])
        return a

    @staticmethod
    def _check_speed(s) -> float:
        s = float(s)
        if not np.isfinite(s) or not 0.0 <= s <= MAX_SPEED_M_PER_S:
            raise StreamError(f"speed must be 0 to {MAX_SPEED_M_PER_S:g} m/s, got {s!r}")
        return s

    @property
    def known(self) -> int:
        """The walk's sample count whose path is known (feed_* extends it)."""
        return self._base + len(self._points)

    def ready(self) -> int:
        """How many samples advance() can emit now (the path known `lookahead` beyond them)."""
        return max(0, self.known - self.lookahead - self.emitted)

    def feed_points(self, points_Nx2) -> None:
        """Appends floor points (x, z metres), one per sample, to the path ahead."""
        pts = np.asarray(points_Nx2, np.float64)
        if pts.ndim != 2 or pts.shape[1] != 2:
            raise StreamError(f"points must be (N, 2) floor points (x, z), got shape {pts.shape}")
        if not np.isfinite(pts).all():
            raise StreamError("points have non-finite values")
        if self.known + len(pts) - self.emitted > MAX_AHEAD:
            raise StreamError(f"the path ahead would be {self.known + len(pts) - self.emitted} samples; "
                              f"a walker takes at most {MAX_AHEAD} (generate.stream.MAX_AHEAD): feed less at once")
        step = np.linalg.norm(np.diff(np.concatenate([self._points[-1:, [0, 2]], pts]), axis=0), axis=1)
        if len(step) and step.max() > MAX_SPEED_M_PER_S / self.rate:
            raise StreamError(f"a step of {step.max():.3g} m between samples is faster than "
                              f"{MAX_SPEED_M_PER_S:g} m/s at {self.rate:g} samples/s")
        if len(pts):
            d = pts[-1] - (pts[-2] if len(pts) > 1 else self._points[-1, [0, 2]])
            if np.linalg.norm(d) > 1e-9:
                self._last_dir = d / np.linalg.norm(d)
                self._last_speed = float(np.linalg.norm(d)) * self.rate
        self._points = np.concatenate([self._points, trajectory.on_floor(pts)])

    def revise_ahead(self, points_Nx2) -> None:
        """Replaces the path not yet walked (from the next sample to emit) by these floor points,
        one per sample: a caller that steers feeds the path it predicts from the current input and
        revises it when the input changes, so a turn reaches G at the next advance instead of
        `lookahead` samples later. The walked samples, root and phase are kept."""
        keep = max(self.emitted, 1) - self._base
        old = self._points
        self._points = old[:keep]
        try:
            self.feed_points(points_Nx2)
        except StreamError:
            self._points = old
            raise

    def feed_steps(self, directions_Nx2, speeds_N) -> None:
        """Appends one sample per (direction (x, z), speed m/s): the path moves speed / rate
        metres along the direction (normalised) at each."""
        d = np.asarray(directions_Nx2, np.float64)
        s = np.asarray(speeds_N, np.float64).reshape(-1)
        if d.ndim != 2 or d.shape[1] != 2 or len(s) != len(d):
            raise StreamError(f"directions must be (N, 2) and speeds (N,), got shapes {d.shape} and {s.shape}")
        if not (np.isfinite(d).all() and np.isfinite(s).all()):
            raise StreamError("directions and speeds must be finite")
        if s.size and (s.min() < 0 or s.max() > MAX_SPEED_M_PER_S):
            raise StreamError(f"speeds must be 0 to {MAX_SPEED_M_PER_S:g} m/s, got {s.min():.3g} to {s.max():.3g}")
        n = np.linalg.norm(d, axis=1, keepdims=True)
        if (n < 1e-9).any():
            raise StreamError("a direction is zero: give a floor direction (x, z) for every step")
        steps = d / n * (s[:, None] / self.rate)
        self.feed_points(self._points[-1, [0, 2]] + np.cumsum(steps, axis=0))

    def set_style(self, w_D, blend_s: float = 1.0) -> None:
        """Moves the style code to w over blend_s seconds of walk from the next sample."""
        w = self._check_w(w_D)
        if w.shape != self._w_to.shape:
            raise StreamError(f"style code must have {self._w_to.size} values, got {w.size}")
        blend_s = float(blend_s)
        if not np.isfinite(blend_s) or not 0 <= blend_s <= 60:
            raise StreamError(f"blend_s must be 0 to 60 seconds, got {blend_s!r}")
        self._w_from, self._w_to = self.style_at(self.emitted), w
        self._w_change, self._w_blend = self.emitted, max(1, round(blend_s * self.rate))

    def style_progress(self, t: int) -> float:
        """How far sample t is into the last set_style's blend: 0 (the previous code) to 1 (the new one)."""
        return float(np.clip((t - self._w_change) / self._w_blend, 0.0, 1.0))

    def style_at(self, t: int) -> np.ndarray:
        a = self.style_progress(t)
        return ((1 - a) * self._w_from + a * self._w_to).astype(np.float32)

    def path_point(self, t: int) -> np.ndarray:
        """The path's floor point (x, z) at sample t, for t in the ring or the known path ahead."""
        k = int(t) - self._base
        if not 0 <= k < len(self._points):
            raise StreamError(f"sample {t} is not held (the walker holds samples {self._base} to {self.known - 1})")
        return self._points[k, [0, 2]].copy()

    # ---- output ------------------------------------------------------------------------------

    def advance(self, n: int | None = None, *, flush: bool = False) -> Samples:
        """The next min(n, ready(), max_step) samples (n None: as many as are ready, up to
        max_step). `flush`: the path is complete; emit up to its end without waiting for
        lookahead (it is extended straight on, as whole-path generation does)."""
        avail = (self.known - self.emitted) if flush else self.ready()
        n = min(self.max_step, avail if n is None else int(n), avail)
        if n < 0:
            raise StreamError(f"n must be >= 0, got {n}")
        e = self.emitted
        if n == 0:
            return self._empty(e)
        s0 = max(0, (e - self.history) // 8 * 8)
        W = self.window
        # the window's path: known samples, then straight on
        pts = self._points[s0 - self._base:]
        if len(pts) < 2:
            pts = np.concatenate([pts, pts[-1:] + np.r_[self._last_dir[0], 0, self._last_dir[1]]
                                  * (self._last_speed / self.rate)])
        pts = pts[:W] if len(pts) >= W else walk.extend_straight(pts, W - len(pts))
        w = self.style_at(e)[None]
        vel, ph = model_apply.curve_clock(self.model, pts.astype(np.float32)[None], w)  # (1, W, 3), (1, W)
        i0 = e - s0
        phase0 = None
        if self.gait:
            # the window's clock set so that sample e keeps the phase it was given (a style blend
            # changes the stride, never the phase already walked)
            ph = ph[0].astype(np.float64)
            at_e = self._phase[e - self._base]
            phase0 = np.array([np.mod(at_e - ph[i0], 2 * np.pi)], np.float32)
            ph = at_e + (ph - ph[i0])
        r, p = model_apply.apply_code(self.model, vel, w, phase0)
        r = np.asarray(r, np.float64)[0, i0:]
        p = np.asarray(p, np.float64)[0, i0:]
        if self._pending is not None:
            # inertialisation: carry the previous prediction's difference at sample e, fade it out
            decay = np.clip(1.0 - np.arange(len(r)) / max(self.blend, 1), 0.0, 1.0)[:, None]
            r = r + (self._pending[0][0] - r[0]) * decay
            p = p + (self._pending[1][0] - p[0]) * decay
        root_vel, pose = r[:n], p[:n]
        self._pending = (r[n:], p[n:])
        # root: integrated from the last emitted position (trajectory.integrate's convention)
        if self._root is None:
            start = self._points[0] * np.array([1.0, 0.0, 1.0])
            root = start + np.concatenate([np.zeros((1, 3)), np.cumsum(root_vel[1:], axis=0)])
        else:
            root = self._root + np.cumsum(root_vel, axis=0)
        self._root = root[-1]
        joints = np.asarray(from_rows(root, pose, self.layout), np.float64)
        if not np.isfinite(joints).all():
            raise limits.GenerateError("the generator produced non-finite positions (a broken checkpoint?)")
        lowest = joints[..., 1].min(axis=-1)
        self._lowest = np.concatenate([self._lowest, lowest])[-self.ring:]
        target = -np.percentile(self._lowest, walk.FLOOR_PERCENTILE)
        shifts = np.empty(n)
        for k in range(n):
            if self._shift is None:
                self._shift = target
            self._shift += np.clip(target - self._shift, -FLOOR_SLEW_M, FLOOR_SLEW_M)
            shifts[k] = self._shift
        joints[..., 1] += shifts[:, None]
        phase = None
        if self.gait:
            phase = ph[i0:i0 + n]
            # the phase of samples e+1..e+n (e+n: the next one to emit)
            self._phase = np.concatenate([self._phase, ph[i0 + 1:i0 + n + 1]])
        curve = self._points[e - self._base:e - self._base + n].copy()
        if len(curve) < n:
            curve = pts[i0:i0 + n].astype(np.float64)
        self.emitted = e + n
        self._trim()
        return Samples(e, joints, root_vel, pose, curve, phase, shifts)

    def _empty(self, e: int) -> Samples:
        J = self.layout.num_rel_joints + 1
        return Samples(e, np.zeros((0, J, 3)), np.zeros((0, 3)), np.zeros((0, 3 * (J - 1))), np.zeros((0, 3)),
                       np.zeros(0) if self.gait else None, np.zeros(0))

    def _trim(self) -> None:
        """Keeps the ring: samples from `ring` before the next one to emit (a window's start)."""
        keep_from = max(0, self.emitted - self.ring)
        cut = keep_from - self._base
        if cut > 0:
            self._points = self._points[cut:]
            self._phase = self._phase[cut:]
            self._base = keep_from

    def state_size(self) -> int:
        """Numbers held (path, phase, floor heights, pending prediction): bounded by the ring and MAX_AHEAD."""
        pend = 0 if self._pending is None else self._pending[0].size + self._pending[1].size
        return self._points.size + self._phase.size + self._lowest.size + pend
