"""What one generation may ask for, and the error that says which limit a request passes.

Limits (module constants, checked by load_curve, prepare_curve and generate_motion before
anything large is allocated; beyond them GenerateError says which limit and by how much):
MAX_CURVE_LENGTH_M of walk, MAX_CURVE_SAMPLES samples of G input (40 minutes at 15 Hz),
MAX_CURVE_POINTS input points, MAX_CURVE_FILE_BYTES per curve file, MAX_TOTAL_SAMPLES motions x
samples per call, MAX_GIF_FRAMES frames x panels per GIF (Pillow holds every frame in memory);
and the seed (MAX_SEED) and an explicit walking speed (SPEED_RANGE_M_PER_S) every entry point takes.
"""

from __future__ import annotations

import math
import numbers

import numpy as np

# What one generation may ask for (module doc, README "Generating walks")
MAX_CURVE_LENGTH_M = 10_000.0
MAX_CURVE_SAMPLES = 36_000
MAX_CURVE_POINTS = 250_000
MAX_CURVE_FILE_BYTES = 128 * 2**20
MAX_TOTAL_SAMPLES = 300_000
MAX_GIF_FRAMES = 3_000
# a seed is a non-negative 31-bit integer everywhere (command line, API, page), so a seed that
# one entry point takes the others take too
MAX_SEED = 2**31 - 1
# an explicit walking speed: a slow stroll to a sprint (a tiny speed asks for astronomically many samples)
SPEED_RANGE_M_PER_S = (0.05, 15.0)


class GenerateError(ValueError):
    """Bad user input to generation (style, curve option, output path); the message says which."""


def polyline_length(pts) -> float:
    return float(np.sum(np.linalg.norm(np.diff(np.asarray(pts), axis=0), axis=1)))


def too_long_message(what: str, length_m: float) -> str:
    shown = f"{length_m:,.0f}" if length_m < 1e12 else f"{length_m:.3g}"
    return (f"{what}: {shown} m is longer than the limit of {MAX_CURVE_LENGTH_M:,.0f} m "
            f"(generate.limits.MAX_CURVE_LENGTH_M)")


def check_curve_limits(points_Px2, what: str = "curve") -> None:
    """GenerateError when a user curve has more than MAX_CURVE_POINTS points or is longer than
    MAX_CURVE_LENGTH_M (its polyline length)."""
    check_point_count(len(points_Px2), what)
    length = polyline_length(points_Px2)
    if length > MAX_CURVE_LENGTH_M:
        raise GenerateError(too_long_message(what, length))


def check_seed(seed) -> int:
    """The seed as an int; GenerateError unless it is an integer 0..MAX_SEED."""
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed <= MAX_SEED:
        raise GenerateError(f"seed must be an integer 0..{MAX_SEED}, got {seed!r}"[:200])
    return seed


def check_speed(speed: float) -> float:
    """An explicit walking speed as a float; GenerateError unless it is within SPEED_RANGE_M_PER_S."""
    lo, hi = SPEED_RANGE_M_PER_S
    if isinstance(speed, bool) or not isinstance(speed, numbers.Real):  # numpy's floats are Real too
        raise GenerateError(f"speed must be a number of m/s, got {speed!r}"[:200])
    try:
        speed = float(speed)
    except OverflowError:  # an int beyond float range
        speed = math.inf
    if not lo <= speed <= hi:  # NaN fails too
        raise GenerateError(f"speed must be {lo:g}..{hi:g} m/s (generate.limits.SPEED_RANGE_M_PER_S), got {speed:g}")
    return speed


def check_point_count(n: int, what: str) -> None:
    if n > MAX_CURVE_POINTS:
        raise GenerateError(f"{what}: {n:,} points are more than the limit of {MAX_CURVE_POINTS:,} "
                            f"(generate.limits.MAX_CURVE_POINTS); resample it more coarsely")
