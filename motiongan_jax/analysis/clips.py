"""A motion clip cut into the model's windows, the targets of style search: its T, its frame step,
the noise-free curve of each window, aligned with the motion exactly as in training.
"""

from __future__ import annotations

import dataclasses
import functools
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from motiongan_jax.analysis.style_space import AnalysisError
from motiongan_jax.data import curves
from motiongan_jax.motion import trajectory
from motiongan_jax.motion.representation import RowLayout, to_rows


@dataclasses.dataclass(frozen=True)
class MotionWindows:
    """A motion cut into the model's windows, float32 metres. Window n covers source frames
    start_frames[n] + frame_step · t, t < T; its curve is the noise-free training curve of exactly
    those frames (point 0 = the root's floor position at the first frame)."""
    root_NxTx3: jax.Array
    pose_NxTxR: jax.Array
    curve_NxTx3: jax.Array
    start_frames: np.ndarray
    frame_step: int
    source: str = ""

    @property
    def spacing_m(self) -> float:
        """Mean curve length per network sample (the motion's speed per sample)."""
        d = jnp.linalg.norm(jnp.diff(self.curve_NxTx3, axis=1), axis=-1)
        return float(jnp.mean(d))


_clean_curves = jax.jit(functools.partial(curves.window_curves, noise=0.0, key=None),
                        static_argnames=("T", "interval"))


def windows_from_rows(root_Fx3, pose_FxR, *, T: int, frame_step: int, interval: int,
                      max_windows: int | None = None, source: str = "") -> MotionWindows:
    """Non-overlapping windows (each T samples, frame_step apart; the next starts T·frame_step
    frames later) with their noise-free curves (`curves.window_curves`, as in training)."""
    root = np.asarray(root_Fx3, np.float32)
    pose = np.asarray(pose_FxR, np.float32)
    F = len(root)
    span = (T - 1) * frame_step + 1
    frames = curves.window_indices(F, T, frame_step, max_windows=max_windows)
    if len(frames) == 0:
        raise AnalysisError(f"{source or 'motion'}: {F} frames is shorter than one window "
                            f"({T} samples x step {frame_step} = {span} frames)")
    starts, count = frames[:, 0], len(frames)
    path_frames = starts[:, None] + np.arange(span)[None, :]
    xz = _clean_curves(root[path_frames][..., [0, 2]], np.full(count, span, np.int32), T=int(T),
                       interval=int(interval))
    curve = trajectory.on_floor(xz)
    return MotionWindows(jnp.asarray(root[frames]), jnp.asarray(pose[frames]), curve.astype(jnp.float32),
                         starts, int(frame_step), source)


def load_motion(path, meta: dict, cfg, layout: RowLayout, *, units_to_m: float | None = None,
                clip: int = 0) -> tuple[np.ndarray, np.ndarray, float]:
    """(root_Fx3, pose_FxR, fps) in metres of a BVH file or an .npz of world positions.

    BVH: preprocessed as in training (clip_cache.preprocess_clip with the run's units and start
    offset; no cache). Its kept joints must be the model's. npz: `positions` (F x J x 3, metres),
    either the model's kept joints in order or a full skeleton with `joint_names` (e.g. the
    output of bin/prepare_data.py; `clip_start`/`clip_length` select clip `clip`); `fps`
    defaults to the run's.
    """
    from motiongan_jax.data import clip_cache, file_labels
    path = Path(path)
    if not path.is_file():
        raise AnalysisError(f"{path}: no such file")
    names = tuple(layout.joint_names)
    if path.suffix.lower() == ".bvh":
        units = clip_cache.units_for(cfg.data) if units_to_m is None else float(units_to_m)
        c = clip_cache.preprocess_clip(path, file_labels.FileLabel(style="?", trial=0), units, cfg.data.start_offset,
                                 use_cache=False)
        if tuple(c.layout.joint_names) != names:
            raise AnalysisError(f"{path}: its skeleton keeps joints {c.layout.joint_names}, the model "
                                f"needs {names}")
        return np.asarray(c.root_Fx3, np.float64), np.asarray(c.pose_FxR, np.float64), float(c.fps)
    if path.suffix.lower() != ".npz":
        raise AnalysisError(f"{path}: expected a .bvh or an .npz of world positions")
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except (OSError, ValueError) as err:
        raise AnalysisError(f"{path}: cannot read ({err})") from None
    if "positions" not in arrays:
        raise AnalysisError(f"{path}: no 'positions' array (has {sorted(arrays)})")
    pos = np.asarray(arrays["positions"], np.float64)
    if "clip_start" in arrays and "clip_length" in arrays:
        starts, lengths = arrays["clip_start"], arrays["clip_length"]
        if not 0 <= clip < len(starts):
            raise AnalysisError(f"{path}: clip {clip} out of range (0..{len(starts) - 1})")
        pos = pos[int(starts[clip]): int(starts[clip]) + int(lengths[clip])]
    if pos.ndim != 3 or pos.shape[2] != 3:
        raise AnalysisError(f"{path}: positions must be (frames, joints, 3), got {pos.shape}")
    if "joint_names" in arrays:
        file_names = [str(s) for s in arrays["joint_names"]]
        missing = [n for n in names if n not in file_names]
        if missing:
            raise AnalysisError(f"{path}: joints {missing} of the model are not in its joint_names")
        pos = pos[:, [file_names.index(n) for n in names]]
    elif pos.shape[1] != len(names):
        raise AnalysisError(f"{path}: {pos.shape[1]} joints without joint_names; the model has "
                            f"{len(names)} ({', '.join(names)})")
    if not np.isfinite(pos).all():
        raise AnalysisError(f"{path}: positions contain NaN or inf")
    kept = dataclasses.replace(layout, source_index=tuple(range(len(names))))
    root, pose = to_rows(pos, kept)
    fps = float(arrays["fps"]) if "fps" in arrays else float(meta.get("fps", 0) or 0)
    if not fps > 0:
        raise AnalysisError(f"{path}: no fps in the file and none in the run's metadata")
    return root, pose, fps


def motion_windows(path, meta: dict, cfg, layout: RowLayout, *, max_windows: int | None = 8,
                   units_to_m: float | None = None, clip: int = 0, T: int | None = None) -> MotionWindows:
    """`load_motion` + `windows_from_rows` with the model's T (or `T`, a multiple of 8: G is
    convolutional in time), frame step and spline interval, the last two scaled by the clip's
    fps over the training fps (so a 120 fps clip is sampled at the training's rate too)."""
    T = cfg.data.window_T if T is None else int(T)
    if T < 16 or T % 8:
        raise AnalysisError(f"window length T must be a multiple of 8 and >= 16, got {T}")
    root, pose, fps = load_motion(path, meta, cfg, layout, units_to_m=units_to_m, clip=clip)
    ratio = fps / float(meta.get("fps") or fps)
    step = max(1, int(round(cfg.data.frame_step * ratio)))
    interval = max(2, int(round(cfg.data.control_point_interval * ratio)))
    return windows_from_rows(root, pose, T=T, frame_step=step, interval=interval,
                             max_windows=max_windows, source=str(path))
