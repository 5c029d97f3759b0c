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
# Real walkers lengthen their stride as they walk faster: log stride rises with log speed at a
# slope between 0 (a fixed stride: cadence follows speed) and 1 (a fixed cadence). The fitted
# slope is held to this range, so that a handful of clips cannot make a faster walk step slower.
STRIDE_SPEED_SLOPE_RANGE = (0.0, 1.0)


@dataclasses.dataclass(frozen=True)
class GaitTargets:
    stride_m_C: tuple[float, ...]  # each style's stride (one left and one right step) at its speed below
    speed_mps_C: tuple[float, ...]  # each style's median travel speed (m/s)
    step_height_m_C: tuple[float, ...]  # each style's median step height (gait.step_amplitude_m) over its clips
    # d log stride / d log speed within styles, pooled over the styles (STRIDE_SPEED_SLOPE_RANGE)
    stride_speed_slope: float
    sample_hz: float  # network samples per second (source fps / data.frame_step): m/s = m/sample x this
    contact_height_m: float  # a toe this close to the floor counts as planted
    toe_joints: tuple[int, int]  # kept-joint indices of the left and right toe


def toe_heights(root_Fx3, pose_FxR, layout: RowLayout, toes: tuple[int, int]) -> np.ndarray:
    """Heights (F, 2) of the two toes of a motion's rows above its floor (gait.toe_heights)."""
    return gait.toe_heights(np.asarray(from_rows(root_Fx3, pose_FxR, layout))[:, list(toes)])


def clip_toe_heights(clip: Clip, layout: RowLayout, toes: tuple[int, int]) -> np.ndarray:
    """Heights (F, 2) of the two toes above the clip's floor (`toe_heights`)."""
    return toe_heights(clip.root_Fx3, clip.pose_FxR, layout, toes)


def speed_and_stride(root_Fx3, heights_Fx2: np.ndarray, fps: float) -> tuple[float, float]:
    """(travel speed m/s, stride length m) of a motion with toe heights `heights_Fx2`: the root path
    averaged over one gait cycle (gait.travel_speed_mps: no sway, no slowing at the ends), and that
    speed over the step frequency (gait.step_frequency_hz); nan without steps."""
    freq = gait.step_frequency_hz(heights_Fx2, fps)
    speed = gait.travel_speed_mps(root_Fx3, fps, freq)
    return (speed, speed / freq) if np.isfinite(speed) and speed > 0 else (float("nan"), float("nan"))


def clip_speed_and_stride(clip: Clip, layout: RowLayout, toes: tuple[int, int]) -> tuple[float, float]:
    """(travel speed m/s, stride length m) of a clip (`speed_and_stride`)."""
    return speed_and_stride(clip.root_Fx3, clip_toe_heights(clip, layout, toes), clip.fps)


def clip_stride_m(clip: Clip, layout: RowLayout, toes: tuple[int, int]) -> float:
    """Stride length of a clip (`clip_speed_and_stride`); nan without steps."""
    return clip_speed_and_stride(clip, layout, toes)[1]


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
    h = toe_heights(root_Fx3, pose_FxR, layout, toes)
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
    return contact_height_of([clip_toe_heights(c, layout, toes) for c in clips])


def contact_height_of(heights_by_clip: list[np.ndarray]) -> float:
    """`contact_height` from each clip's toe heights (F, 2)."""
    heights = np.concatenate([h.ravel() for h in heights_by_clip])
    return gait.contact_height_threshold(heights, CONTACT_PERCENTILE) + CONTACT_MARGIN_M


def stride_speed_slope(log_speed_by_style: list[np.ndarray], log_stride_by_style: list[np.ndarray]) -> float:
    """The slope of log stride on log speed within styles, pooled over them (each style's clips
    about their own means, one least-squares line), held to STRIDE_SPEED_SLOPE_RANGE; 0 when no
    style's clips differ in speed."""
    sxy = sxx = 0.0
    for x, y in zip(log_speed_by_style, log_stride_by_style):
        if len(x) >= 2:
            sxy += float(np.sum((x - x.mean()) * (y - y.mean())))
            sxx += float(np.sum(np.square(x - x.mean())))
    slope = sxy / sxx if sxx > 1e-12 else 0.0
    return float(np.clip(slope, *STRIDE_SPEED_SLOPE_RANGE))


def gait_targets(clips: list[Clip], style_names: tuple[str, ...], layout: RowLayout,
                 sample_hz: float) -> GaitTargets:
    """Each style's median speed and its stride there, its median step height, the stride–speed
    slope within styles (`stride_speed_slope`) and the contact height, measured on real clips without annotation;
    `sample_hz` is the network's samples per second. A style none of whose clips shows a step
    frequency is an error."""
    toes = foot_joints(layout)
    by_style: dict[str, list[tuple[float, float]]] = {s: [] for s in style_names}
    heights_by_style: dict[str, list[float]] = {s: [] for s in style_names}
    heights_by_clip = [clip_toe_heights(clip, layout, toes) for clip in clips]  # one FK pass per clip
    for clip, h in zip(clips, heights_by_clip):
        by_style[clip.label.style].append(speed_and_stride(clip.root_Fx3, h, clip.fps))
        heights_by_style[clip.label.style].append(gait.step_amplitude_m(h))
    log_speeds, log_strides = [], []
    for style in style_names:
        vals = np.array([v for v in by_style[style] if np.all(np.isfinite(v))], np.float64).reshape(-1, 2)
        if not len(vals):
            raise DataError(f"style {style!r}: no clip with a measurable step frequency (no stride length)")
        log_speeds.append(np.log(vals[:, 0]))
        log_strides.append(np.log(vals[:, 1]))
    slope = stride_speed_slope(log_speeds, log_strides)
    speeds, strides = [], []
    for x, y in zip(log_speeds, log_strides):
        centre = float(np.median(x))
        speeds.append(float(np.exp(centre)))
        strides.append(float(np.exp(np.median(y - slope * (x - centre)))))  # at the median speed
    step_heights = tuple(float(np.median(heights_by_style[style])) for style in style_names)
    return GaitTargets(tuple(strides), tuple(speeds), step_heights, slope, float(sample_hz),
                       contact_height_of(heights_by_clip), toes)
