"""What one generation may ask for, and the error that says which limit a request passes.

Limits (module constants, checked by load_curve, prepare_curve and generate_motion before
anything large is allocated; beyond them GenerateError says which limit and by how much):
MAX_CURVE_LENGTH_M of walk, MAX_CURVE_SAMPLES samples of G input (40 minutes at 15 Hz),
MAX_CURVE_POINTS input points, MAX_CURVE_FILE_BYTES per curve file, MAX_TOTAL_SAMPLES motions x
samples per call, MAX_GIF_FRAMES frames x panels per GIF (Pillow holds every frame in memory).
"""

from __future__ import annotations

import numpy as np

# What one generation may ask for (module doc, README "Generating walks")
MAX_CURVE_LENGTH_M = 10_000.0
MAX_CURVE_SAMPLES = 36_000
MAX_CURVE_POINTS = 250_000
MAX_CURVE_FILE_BYTES = 128 * 2**20
MAX_TOTAL_SAMPLES = 300_000
MAX_GIF_FRAMES = 3_000


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


def check_point_count(n: int, what: str) -> None:
    if n > MAX_CURVE_POINTS:
        raise GenerateError(f"{what}: {n:,} points are more than the limit of {MAX_CURVE_POINTS:,} "
                            f"(generate.limits.MAX_CURVE_POINTS); resample it more coarsely")
