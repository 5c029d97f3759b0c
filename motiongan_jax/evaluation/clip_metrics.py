"""Per-clip motion metrics, for generated and real clips alike: the gait, the path, the body.
"""

from __future__ import annotations

import dataclasses

import jax
import numpy as np

from motiongan_jax.analysis import clips
from motiongan_jax.data import curves
from motiongan_jax.evaluation import metrics
from motiongan_jax.generate import styles, walk
from motiongan_jax.model import apply as model_apply
from motiongan_jax.motion import gait
from motiongan_jax.motion.representation import facing_joints, from_rows

PENETRATION_TOLERANCE_M = 0.02
GAIT_KEYS = ("support", "lower_foot_height_m", "alternation", "step_frequency_hz", "step_amplitude_m",
             "root_height_range_m")


def gait_metrics(joints_LxJx3, feet, fps: float, contact_height: float) -> dict:
    """Does it walk: support, lower-toe height, alternation, step frequency and amplitude (toe
    heights above the clip's own floor, gait.toe_heights) and the root's height range."""
    h = gait.toe_heights(joints_LxJx3[:, list(feet)])
    return {"support": gait.support(h, contact_height), "lower_foot_height_m": gait.lower_foot_height(h),
            "alternation": gait.alternation(h), "step_frequency_hz": gait.step_frequency_hz(h, fps),
            "step_amplitude_m": gait.step_amplitude_m(h),
            "root_height_range_m": gait.height_range_m(joints_LxJx3[:, 0])}


@dataclasses.dataclass(frozen=True)
class GaitTrace:
    style: str
    source: str  # the held-out clip whose path G walked
    real_heights_Tx2: np.ndarray  # that clip's toe heights above its floor (left, right), metres
    gen_heights_Tx2: np.ndarray  # G's, walking the clip's path in the clip's style


def gait_traces(state, cfg, layout, val_clips, style_names, feet, sample_rate: float, seconds: float = 6.0,
                seed: int = 0) -> list[GaitTrace]:
    """Per style, the first held-out clip of that style and G's walk of its path in its style (one
    noise draw z from `seed`, phase offset 0), as toe heights at the network's sample rate, over at
    most `seconds` (a multiple of 8 samples, at least 16)."""
    step = cfg.data.frame_step
    out = []
    for c, name in enumerate(style_names):
        clip = next((v for v in val_clips if v.label.style == name), None)
        if clip is None:
            continue
        n = min(int(seconds * sample_rate), (len(clip.root_Fx3) - 1) // step + 1) // 8 * 8
        if n < walk.MIN_T:
            continue
        mw = clips.windows_from_rows(clip.root_Fx3, clip.pose_FxR, T=n, frame_step=step,
                                        interval=cfg.data.control_point_interval, max_windows=1)
        curve = np.asarray(mw.curve_NxTx3[0], np.float32)
        z = jax.random.normal(jax.random.fold_in(jax.random.key(seed), c), (1, model_apply.z_dim(state)))
        gen = walk.generate_motion(state, layout, curve, np.asarray(styles.latent_codes(state, np.array([c]), z)))
        real = np.asarray(from_rows(clip.root_Fx3[: (n - 1) * step + 1: step],
                                    clip.pose_FxR[: (n - 1) * step + 1: step], layout), np.float64)
        out.append(GaitTrace(name, clip.source, gait.toe_heights(real[:, list(feet)]),
                             gait.toe_heights(gen.positions[0][:, list(feet)])))
    return out


def motion_metrics(joints_LxJx3, curve_Lx3, layout, feet, fps: float, contact_height: float) -> dict:
    """Trajectory (when a curve is given), skating, skeleton, facing, smoothness and gait of one
    clip. Contacts (skating ratio, support) are toes within `contact_height` of the clip's floor."""
    toes = joints_LxJx3[:, list(feet)]
    toes_on_floor = toes.copy()
    toes_on_floor[..., 1] = gait.toe_heights(toes)
    hips = facing_joints(layout)
    out = {
        "facing_error_deg": float("nan") if hips is None else metrics.facing_error_deg(joints_LxJx3, *hips),
        "foot_skate_original_m": metrics.foot_skate_original(toes),
        "skate_ratio": metrics.skate_ratio(toes_on_floor, fps, contact_height),
        "bone_length_error": metrics.bone_length_error(joints_LxJx3, np.asarray(layout.bone_pairs),
                                                       np.asarray(layout.bone_lengths_m)),
        "ground_penetration": metrics.ground_penetration(toes[..., 1], PENETRATION_TOLERANCE_M),
        "jerk_mps3": metrics.mean_jerk(joints_LxJx3, fps),
        **gait_metrics(joints_LxJx3, feet, fps, contact_height),
    }
    if curve_Lx3 is not None:
        root = joints_LxJx3[:, 0]
        out.update({
            "traj_error_original_m": metrics.trajectory_error_original(root, curve_Lx3),
            "traj_error_symmetric_m": metrics.trajectory_error_symmetric(root, curve_Lx3),
            "endpoint_error_m": metrics.endpoint_error(root, curve_Lx3),
            "path_length_ratio": metrics.path_length_ratio(root, curve_Lx3),
        })
    return out


def cut_windows(root_BxLx3, pose_BxLxR, T: int):
    """Back-to-back windows of T samples of every motion: (root (B·n) x T x 3, pose, n)."""
    B, L, _ = root_BxLx3.shape
    frames = curves.window_indices(L, T)
    n = len(frames)
    return root_BxLx3[:, frames].reshape(B * n, T, 3), pose_BxLxR[:, frames].reshape(B * n, T, -1), n
