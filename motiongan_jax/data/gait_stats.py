"""Gait statistics of real clips, measured without annotation: what the gait terms of training aim
at (stride per style, contact height) and each frame's gait phase (for reconstruction).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.ndimage import gaussian_filter1d, uniform_filter1d
from scipy.signal import hilbert

from motiongan_jax.data.clip_cache import Clip
from motiongan_jax.data.file_labels import DataError
from motiongan_jax.motion import gait
from motiongan_jax.motion.representation import RowLayout, foot_joints, from_rows

CONTACT_PERCENTILE = 10.0  # contact height: this percentile of real toe heights above the floor ...
CONTACT_MARGIN_M = 0.02  # ... plus this
SPEED_SMOOTHING_S = 0.5  # the pelvis path is smoothed over this (Gaussian sigma) to drop its sway


@dataclasses.dataclass(frozen=True)
class GaitTargets:
    stride_m_C: tuple[float, ...]  # each style's median stride length (one left and one right step)
    contact_height_m: float  # a toe this close to the floor counts as planted
    toe_joints: tuple[int, int]  # kept-joint indices of the left and right toe


def clip_toe_heights(clip: Clip, layout: RowLayout, toes: tuple[int, int]) -> np.ndarray:
    """Heights (F, 2) of the two toes above the clip's floor (gait.toe_heights)."""
    return gait.toe_heights(np.asarray(from_rows(clip.root_Fx3, clip.pose_FxR, layout))[:, list(toes)])


def clip_stride_m(clip: Clip, layout: RowLayout, toes: tuple[int, int]) -> float:
    """Stride length of a clip: its walking speed (the smoothed pelvis path's length over the
    clip's duration) over its step frequency (gait.step_frequency_hz); nan without steps."""
    freq = gait.step_frequency_hz(clip_toe_heights(clip, layout, toes), clip.fps)
    xz = gaussian_filter1d(np.asarray(clip.root_Fx3, np.float64)[:, [0, 2]], SPEED_SMOOTHING_S * clip.fps,
                           axis=0, mode="nearest")
    speed = np.sum(np.linalg.norm(np.diff(xz, axis=0), axis=1)) * clip.fps / (len(xz) - 1)
    return float(speed / freq) if np.isfinite(freq) and freq > 0 else float("nan")


PHASE_DETREND_S = 2.0  # the toe-height difference minus its moving average over this ...
PHASE_SMOOTHING_S = 0.04  # ... smoothed over this (Gaussian sigma), before its Hilbert phase
PHASE_MIN_AMPLITUDE = 0.3  # frames whose step amplitude is below this share of the clip's median have no phase


def clip_gait_phase(clip: Clip, layout: RowLayout, toes: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """(phase_F radians, valid_F bool) of a clip's frames: `gait_phase` of its rows."""
    return gait_phase(clip.root_Fx3, clip.pose_FxR, layout, toes, clip.fps)


def gait_phase(root_Fx3, pose_FxR, layout: RowLayout, toes: tuple[int, int], fps: float
               ) -> tuple[np.ndarray, np.ndarray]:
    """(phase_F radians, valid_F bool): the gait phase of every frame, measured without annotation:
    the unwrapped angle of the analytic signal (Hilbert transform) of left − right toe height,
    detrended and smoothed. It rises 2π per gait cycle and is 0 where the left toe is highest above
    the right. Frames where the steps fade (standing, a start or a stop) are not `valid`: their
    angle is noise."""
    h = gait.toe_heights(np.asarray(from_rows(root_Fx3, pose_FxR, layout))[:, list(toes)])
    d = h[:, 0] - h[:, 1]
    d = d - uniform_filter1d(d, max(int(round(PHASE_DETREND_S * fps)), 1), mode="nearest")
    d = gaussian_filter1d(d, PHASE_SMOOTHING_S * fps, mode="nearest")
    analytic = hilbert(d)
    amplitude = np.abs(analytic)
    valid = amplitude > PHASE_MIN_AMPLITUDE * max(float(np.median(amplitude)), 1e-9)
    return np.unwrap(np.angle(analytic)).astype(np.float32), valid


def contact_height(clips: list[Clip], layout: RowLayout, toes: tuple[int, int]) -> float:
    """The contact height (metres) calibrated on real clips: CONTACT_PERCENTILE of their toe
    heights above each clip's floor, pooled, plus CONTACT_MARGIN_M."""
    heights = np.concatenate([clip_toe_heights(c, layout, toes).ravel() for c in clips])
    return gait.contact_height_threshold(heights, CONTACT_PERCENTILE) + CONTACT_MARGIN_M


def gait_targets(clips: list[Clip], style_names: tuple[str, ...], layout: RowLayout) -> GaitTargets:
    """Stride lengths per style (median over its clips) and the contact height, measured on real
    clips without annotation. A style none of whose clips shows a step frequency is an error."""
    toes = foot_joints(layout)
    by_style: dict[str, list[float]] = {s: [] for s in style_names}
    for clip in clips:
        by_style[clip.label.style].append(clip_stride_m(clip, layout, toes))
    strides = []
    for style in style_names:
        vals = [v for v in by_style[style] if np.isfinite(v)]
        if not vals:
            raise DataError(f"style {style!r}: no clip with a measurable step frequency (no stride length)")
        strides.append(float(np.median(vals)))
    return GaitTargets(tuple(strides), contact_height(clips, layout, toes), toes)

