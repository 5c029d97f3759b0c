"""The protocol's curves: held-out clips' paths, curve files, built-in shapes and a long line.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Sequence

import numpy as np

from motiongan_jax.analysis import clips as clips_lib
from motiongan_jax.data import curves
from motiongan_jax.generate import user_curves

TURNING_DEG = 45.0  # a held-out path whose heading changes more than this is "turning"


@dataclasses.dataclass(frozen=True)
class EvalCurve:
    name: str
    kind: str  # heldout_straight, heldout_turning, cmu, synthetic
    curve_Lx3: np.ndarray  # metres, y = 0, starts at the origin
    source: str


def from_origin(curve_Lx3: np.ndarray) -> np.ndarray:
    """The curve moved on the floor so that it starts at the origin (its dtype kept)."""
    return curve_Lx3 - curve_Lx3[0] * np.array([1.0, 0.0, 1.0], curve_Lx3.dtype)


def _whole_windows(curve_Lx3: np.ndarray, L: int, T: int) -> np.ndarray | None:
    """The curve's first min(L, a multiple of T) samples, None when it is shorter than T."""
    n = min(L, len(curve_Lx3) // T * T)
    return curve_Lx3[:n] if n >= T else None


def _heading_change_deg(curve_Lx3) -> float:
    d = np.diff(curve_Lx3[:, [0, 2]], axis=0)
    d = d[np.linalg.norm(d, axis=1) > 1e-9]
    if len(d) < 2:
        return 0.0
    ang = np.unwrap(np.arctan2(d[:, 0], d[:, 1]))
    return float(np.degrees(ang.max() - ang.min()))


def heldout_curves(val_clips, cfg, L: int, max_curves: int) -> list[EvalCurve]:
    """The noise-free training curve of each held-out clip's first L-sample stretch (fewer
    samples, a multiple of T, if the clip is shorter), round-robin over styles."""
    T, step = cfg.data.window_T, cfg.data.frame_step
    by_style: dict[str, list] = {}
    for clip in val_clips:
        by_style.setdefault(clip.label.style, []).append(clip)
    order = []
    while any(by_style.values()):
        for s in sorted(by_style):
            if by_style[s]:
                order.append(by_style[s].pop(0))
    out = []
    for clip in order:
        F = len(clip.root_Fx3)
        n = min(L, ((F - 1) // step + 1) // T * T)
        if n < T:
            continue
        mw = clips_lib.windows_from_rows(clip.root_Fx3, clip.pose_FxR, T=n, frame_step=step,
                                        interval=cfg.data.control_point_interval, max_windows=1)
        c = from_origin(np.asarray(mw.curve_NxTx3[0], np.float64))
        kind = "heldout_turning" if _heading_change_deg(c) > TURNING_DEG else "heldout_straight"
        out.append(EvalCurve(Path(clip.source).stem, kind, c.astype(np.float32), clip.source))
        if len(out) >= max_curves:
            break
    return out


def file_curves(paths: Sequence[Path], sample_rate: float, L: int, T: int, control_seconds: float,
                log=None) -> list[EvalCurve]:
    """Root paths of BVH files from another session or lab (their own speed), trimmed to L."""
    out = []
    for p in paths:
        try:
            c = user_curves.load_curve(str(p), control_seconds=control_seconds)
            arr = user_curves.prepare_curve(c, sample_rate)
        except (ValueError, OSError) as err:
            if log:
                log(f"skipping curve {p}: {err}")
            continue
        arr = _whole_windows(arr, L, T)
        if arr is None:
            continue
        out.append(EvalCurve(Path(p).stem, "cmu", from_origin(arr).astype(np.float32), str(p)))
    return out


def shape_curves(sample_rate: float, speed: float, L: int, T: int,
                 shapes: Sequence[str] = curves.SHAPES) -> list[EvalCurve]:
    """The synthetic shapes (line, circle, S-curve, figure-8, 90° corner) walked at `speed`."""
    out = []
    length = L * speed / sample_rate
    for name in shapes:
        kw = {"length": length} if name in ("line", "corner") else {"scale": max(length / (2 * math.pi), 1.0)}
        if name == "figure8":
            kw = {"scale": max(length / (4 * math.pi), 1.0)}
        arr = user_curves.prepare_curve(user_curves.load_curve(name, **kw), sample_rate, speed)
        arr = _whole_windows(arr, L, T)
        if arr is None:
            continue
        out.append(EvalCurve(name, "synthetic", from_origin(arr).astype(np.float32), f"shape:{name}"))
    return out


def long_line(sample_rate: float, speed: float, length_m: float) -> EvalCurve:
    """A straight line of `length_m` metres walked at `speed`: the drift test's curve."""
    arr = user_curves.prepare_curve(user_curves.load_curve("line", length=length_m), sample_rate, speed)
    return EvalCurve(f"line_{length_m:g}m", "long", from_origin(arr).astype(np.float32), f"shape:line:{length_m:g}m")


def median_speed(clips, fps: float) -> float:
    """Median walking speed (m/s) of clips: floor path length over duration."""
    s = []
    for c in clips:
        xz = np.asarray(c.root_Fx3)[:, [0, 2]]
        if len(xz) > 1:
            s.append(np.sum(np.linalg.norm(np.diff(xz, axis=0), axis=1)) / ((len(xz) - 1) / fps))
    return float(np.median(s)) if s else user_curves.DEFAULT_SPEED_M_PER_S
