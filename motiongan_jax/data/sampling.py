"""The dataset as flat arrays, and `sample_batch(arrays, key, step)`: a jitted, batched function of
an explicit key that cuts training windows with FPS and rotation augmentation and noisy input curves.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from motiongan_jax.config import DataConfig
from motiongan_jax.data import curves
from motiongan_jax.data.clip_cache import Clip
from motiongan_jax.data.file_labels import DataError
from motiongan_jax.data.gait_stats import clip_gait_phase
from motiongan_jax.motion import trajectory
from motiongan_jax.motion.representation import foot_joints


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class ClipArrays:
    """All clips of a split concatenated along frames, plus the window table; a pytree of arrays."""
    root_Nx3: jax.Array
    pose_NxR: jax.Array
    clip_start_C: jax.Array  # first frame of each clip in the flat arrays
    clip_length_C: jax.Array
    clip_label_C: jax.Array
    window_clip_M: jax.Array  # clip index of every training window
    window_start_M: jax.Array  # start frame inside its clip
    phase_N: jax.Array  # gait phase of every frame, radians (clip_gait_phase)
    phase_valid_N: jax.Array  # whether that phase is measured (bool)


def max_step(cfg: DataConfig) -> int:
    return max(1, int(np.floor(cfg.frame_step * max(cfg.fps_factors))))


def _phase_or_none(clip: Clip) -> tuple[np.ndarray, np.ndarray]:
    """The clip's gait phase, or an all-invalid one for a skeleton without two feet (it has no gait;
    the gait options refuse such data in gait_targets, so nothing trains on these zeros)."""
    try:
        toes = foot_joints(clip.layout)
    except ValueError:
        n = clip.root_Fx3.shape[0]
        return np.zeros(n, np.float32), np.zeros(n, bool)
    return clip_gait_phase(clip, clip.layout, toes)


def build_arrays(clips: list[Clip], style_names: tuple[str, ...], cfg: DataConfig) -> ClipArrays:
    """Concatenate clips and list every window start (DESIGN.md §2.4: clips longer than frame_nums,
    starts every window_stride frames)."""
    index = {s: i for i, s in enumerate(style_names)}
    starts, lengths, labels, w_clip, w_start = [], [], [], [], []
    offset = 0
    for c, clip in enumerate(clips):
        n = clip.root_Fx3.shape[0]
        starts.append(offset)
        lengths.append(n)
        labels.append(index[clip.label.style])
        offset += n
        if n > cfg.frame_nums:
            count = (n - cfg.frame_nums) // cfg.window_stride
            count = max(count, 1)
            w_clip.extend([c] * count)
            w_start.extend(range(0, count * cfg.window_stride, cfg.window_stride))
    if not w_clip:
        longest = max(c.root_Fx3.shape[0] for c in clips)
        raise DataError(
            f"no clip is longer than data.frame_nums = {cfg.frame_nums} frames (longest: {longest}); "
            "lower frame_nums or frame_step")
    phases = [_phase_or_none(c) for c in clips]
    return ClipArrays(
        root_Nx3=jnp.asarray(np.concatenate([c.root_Fx3 for c in clips])),
        pose_NxR=jnp.asarray(np.concatenate([c.pose_FxR for c in clips])),
        clip_start_C=jnp.asarray(starts, jnp.int32),
        clip_length_C=jnp.asarray(lengths, jnp.int32),
        clip_label_C=jnp.asarray(labels, jnp.int32),
        window_clip_M=jnp.asarray(w_clip, jnp.int32),
        window_start_M=jnp.asarray(w_start, jnp.int32),
        phase_N=jnp.asarray(np.concatenate([p for p, _ in phases])),
        phase_valid_N=jnp.asarray(np.concatenate([v for _, v in phases])),
    )


def epoch_indices(key: jax.Array, step, num_windows: int, batch_size: int) -> jax.Array:
    """Window indices of batch `step`: epochs are permutations drawn from fold_in(key, epoch), the
    last partial batch dropped. A pure function of (key, step), so resuming needs no state."""
    per_epoch = max(num_windows // batch_size, 1)
    epoch = step // per_epoch
    perm = jax.random.permutation(jax.random.fold_in(key, epoch), num_windows)
    if num_windows < batch_size:  # tiny datasets: draw with replacement
        return jax.random.choice(jax.random.fold_in(key, step), num_windows, (batch_size,))
    return jax.lax.dynamic_slice(perm, ((step % per_epoch) * batch_size,), (batch_size,))


def make_sample_batch(cfg: DataConfig, batch_size: int, rec_rows: int = 0):
    """Returns sample_batch(arrays, key, step) -> Batch (see docs/CONTRACTS.md). jit it.
    `rec_rows`: the batch's `rec_B` marks its first rec_rows windows as the ones G reconstructs
    (train.objectives.reconstructed_rows); no `rec_B` when 0."""
    T = cfg.window_T
    factors = jnp.asarray(cfg.fps_factors, jnp.float32)
    n_max = (T - 1) * max_step(cfg) + 1

    def sample_batch(arrays: ClipArrays, key: jax.Array, step) -> dict:
        k_idx, k_fps, k_rot, k_curve = jax.random.split(jax.random.fold_in(key, step), 4)
        idx_B = epoch_indices(k_idx, step, arrays.window_clip_M.shape[0], batch_size)
        clip_B = arrays.window_clip_M[idx_B]
        s_B = arrays.window_start_M[idx_B]
        n_B = arrays.clip_length_C[clip_B]
        base_B = arrays.clip_start_C[clip_B]
        # FPS augmentation (DESIGN.md §2.4): factor a, capped so the window fits in the clip.
        a_B = factors[jax.random.randint(k_fps, (batch_size,), 0, factors.shape[0])]
        fps_B = jnp.minimum(a_B, (n_B - s_B - 1).astype(jnp.float32) / cfg.frame_nums)
        step_B = jnp.maximum(jnp.floor(cfg.frame_step * fps_B).astype(jnp.int32), 1)
        # Motion samples at s, s+step', ...; the curve spans exactly those frames (the reference's
        # curve ran ~0.7% past the last sample, DESIGN.md §6).
        t_T = jnp.arange(T, dtype=jnp.int32)
        frame_BxT = base_B[:, None] + s_B[:, None] + step_B[:, None] * t_T
        root = arrays.root_Nx3[frame_BxT]
        pose = arrays.pose_NxR[frame_BxT]
        length_B = (T - 1) * step_B + 1
        i_N = jnp.arange(n_max, dtype=jnp.int32)
        path_frames = base_B[:, None] + s_B[:, None] + jnp.minimum(i_N, length_B[:, None] - 1)
        path_xz = arrays.root_Nx3[path_frames][..., jnp.array([0, 2])]
        curve_xz = curves.window_curves(path_xz, length_B, T, cfg.control_point_interval,
                                        cfg.curve_noise, k_curve)
        curve = trajectory.on_floor(curve_xz)
        if cfg.rotate:
            theta_B = jax.random.uniform(k_rot, (batch_size,), maxval=2 * jnp.pi)
            root = trajectory.rotate_y(root, theta_B[:, None])
            curve = trajectory.rotate_y(curve, theta_B[:, None])
            pose = trajectory.rotate_rows_y(pose, theta_B[:, None])
        rec = {"rec_B": jnp.arange(batch_size) < rec_rows} if rec_rows else {}
        return {
            **rec,
            "root_BxTx3": root.astype(jnp.float32),
            "pose_BxTxR": pose.astype(jnp.float32),
            "curve_BxTx3": curve.astype(jnp.float32),
            "label_B": arrays.clip_label_C[clip_B],
            "phase_BxT": arrays.phase_N[frame_BxT],
            "phase_valid_BxT": arrays.phase_valid_N[frame_BxT],
        }

    return sample_batch

