"""The curve a user gives (a built-in shape, a CSV/JSON file, a BVH root path) and G's input from it.

Curve -> G input. The curve (metres, floor x-z) is resampled at equal arc length with spacing
speed / sample_rate, sample_rate = meta fps / data.frame_step (15 Hz for the shipped configs);
speed defaults to DEFAULT_SPEED_M_PER_S (1.2 m/s, an ordinary adult walk; the embedded styles
range from 0.54 to 1.65 m/s, mean 1.08; checkpoints store no data statistics), and for a BVH
curve to that clip's own mean speed. The whole curve is walked: G needs T a multiple of 8 (and
>= MIN_T), so generate_motion extends the curve straight past its end to the next such T, runs
G, and crops the motion back to the curve's own samples.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from pathlib import Path
from typing import Callable

import numpy as np

from motiongan_jax.data import curves
from motiongan_jax.generate import limits, walk
from motiongan_jax.motion import trajectory

DEFAULT_SPEED_M_PER_S = 1.2
SHAPE_POINTS_PER_M = 100  # built-in shapes are drawn at 1 cm before resampling (at most MAX_CURVE_POINTS)


@dataclasses.dataclass(frozen=True)
class Curve:
    """A user curve before resampling: (P, 2) floor points (x, z) in metres, and for a BVH curve
    its own mean speed and the spline interval (in points) that smooths its gait sway."""

    points: np.ndarray
    description: str
    speed_m_per_s: float | None = None
    smooth_interval: int | None = None


def _positive(value) -> bool:
    """Whether `value` is a finite positive real number (an int beyond float range is not)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        return False
    try:
        return math.isfinite(float(value)) and value > 0
    except OverflowError:
        return False


def check_shape_size(name: str, length, scale) -> None:
    """GenerateError unless a shape's length (None: its natural one) and scale are finite positive
    metres (the command line checks them before loading the model)."""
    for what, value in (("length", length), ("scale", scale)):
        if value is not None and not _positive(value):
            raise limits.GenerateError(f"curve {name!r}: {what} must be a positive number of metres, "
                                       f"got {value!r}"[:200])


def load_curve(text: str, *, length: float | None = None, scale: float = 2.0,
               control_seconds: float | None = None) -> Curve:
    """A shape name (curves.SHAPES, with length/scale in metres), or a .csv/.txt/.json file of
    x,z points in metres, or a .bvh file (its pelvis path, units guessed from the leg length,
    smoothed by a spline with a knot every `control_seconds` as in training).
    Raises GenerateError (also for a curve beyond the module's limits, before it is built or
    read), curves.CurveFileError or curves.DegenerateCurveError."""
    text = str(text).strip()
    if text in curves.SHAPES:
        check_shape_size(text, length, scale)
        try:
            natural = None if length is None else float(length)
            total = natural
            if total is None:
                total = curves.natural_length(text, scale)
            if math.isfinite(total) and total > limits.MAX_CURVE_LENGTH_M:
                raise limits.GenerateError(limits.too_long_message(f"curve {text!r}", total))
            num = int(min(max(total * SHAPE_POINTS_PER_M, 256), limits.MAX_CURVE_POINTS))
            pts = curves.shape_curve(text, length=natural, scale=scale, num_points=num)
        except (ValueError, TypeError) as e:
            if isinstance(e, (curves.DegenerateCurveError, limits.GenerateError)):
                raise
            raise limits.GenerateError(f"curve {text!r}: {e}") from None
        return Curve(pts, f"{text} (scale {scale:g} m, length {limits.polyline_length(pts):.3g} m)")
    path = Path(text)
    if not path.is_file():
        raise limits.GenerateError(f"curve {text!r}: not a shape name ({', '.join(curves.SHAPES)}) and "
                                   f"no such file")
    size = path.stat().st_size
    if size > limits.MAX_CURVE_FILE_BYTES:
        raise limits.GenerateError(f"curve file {path}: {size / 2**20:.0f} MiB is larger than the limit of "
                                   f"{limits.MAX_CURVE_FILE_BYTES / 2**20:.0f} MiB "
                                   f"(generate.limits.MAX_CURVE_FILE_BYTES)")
    if path.suffix.lower() == ".bvh":
        from motiongan_jax.motion import bvh

        motion = bvh.read_bvh(path)
        limits.check_point_count(motion.num_frames, f"curve {path.name}")
        pts = curves.curve_from_bvh(motion)
        limits.check_curve_limits(pts, f"curve {path.name}")
        frames = len(pts)
        seconds = (frames - 1) * motion.frame_time
        interval = None
        if control_seconds is not None:
            interval = max(2, int(round(control_seconds / motion.frame_time)))
        smoothed = pts if interval is None else curves.resample_polyline(pts, num_points=frames,
                                                                          smooth_interval=interval)
        speed = limits.polyline_length(smoothed) / seconds if seconds > 0 else None
        return Curve(pts, f"{path.name} (root path, {frames} frames, {seconds:.3g} s)",
                     speed if speed and speed > 0 else None, interval)
    pts = curves.load_curve_file(path)
    limits.check_curve_limits(pts, f"curve {path.name}")
    return Curve(pts, f"{path.name}")


def prepare_curve(curve: Curve | np.ndarray, sample_rate: float, speed: float | None = None,
                  log: Callable[[str], None] | None = None) -> np.ndarray:
    """G's input curve: (M, 3) float32 (x, 0, z) metres, equal spacing speed / sample_rate, every
    sample of the curve (M >= 2; generate_motion pads it for G and crops back, module doc).
    speed defaults to the curve's own (a BVH) or DEFAULT_SPEED_M_PER_S. GenerateError when the
    curve exceeds the limits (module doc), before it is resampled."""
    if not isinstance(curve, Curve):
        curve = Curve(curves.check_curve(curve, "curve"), "curve")
    limits.check_curve_limits(curve.points, f"curve {curve.description}")
    if speed is None:
        speed = float(curve.speed_m_per_s or DEFAULT_SPEED_M_PER_S)
        if not (math.isfinite(speed) and speed > 0):
            raise limits.GenerateError(f"speed must be a positive number of m/s, got {speed}")
    else:
        speed = limits.check_speed(speed)
    if not (math.isfinite(sample_rate) and sample_rate > 0):
        raise limits.GenerateError(f"sample rate must be positive, got {sample_rate}")
    spacing = speed / sample_rate
    # the samples resampling would give (smoothing only shortens a curve): refuse before allocating
    expected = limits.polyline_length(curve.points) / spacing + 1
    if expected > limits.MAX_CURVE_SAMPLES:
        raise limits.GenerateError(
            f"curve {curve.description}: {expected:,.0f} samples at {spacing:.3g} m ({speed:.3g} m/s at "
            f"{sample_rate:g} Hz) are more than the limit of {limits.MAX_CURVE_SAMPLES:,} "
            f"({limits.MAX_CURVE_SAMPLES / sample_rate / 60:.0f} minutes at this rate; "
            f"generate.limits.MAX_CURVE_SAMPLES): "
            f"shorten the curve or walk it faster")
    xz = curves.resample_polyline(curve.points, spacing=spacing, smooth_interval=curve.smooth_interval)
    M = len(xz)
    note = f"curve {curve.description}: {M} samples at {spacing:.3g} m ({speed:.3g} m/s at {sample_rate:g} Hz)"
    if walk.padded_length(M) > M:
        note += (f"; walked in full: G takes a multiple of 8 samples (at least {walk.MIN_T}), so it walks on "
                 f"straight past the curve's end and the motion is cropped back to its {M} samples")
    if M > walk.CHUNK_T:
        note += f"; in overlapping chunks of {walk.CHUNK_T} samples"
    if log is not None:
        log(note)
    return trajectory.on_floor(xz).astype(np.float32)
