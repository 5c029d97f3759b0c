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
from motiongan_jax.motion.representation import RowLayout, foot_joints, from_rows, to_rows


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
    # the gait phase of every sample (radians, data.gait_stats.gait_phase of the whole motion) and
    # where it is measured; None when not asked for (`windows_from_rows(phase=False)`)
    phase_NxT: np.ndarray | None = None
    phase_valid_NxT: np.ndarray | None = None

    @property
    def spacing_m(self) -> float:
        """Mean curve length per network sample (the motion's speed per sample)."""
        d = jnp.linalg.norm(jnp.diff(self.curve_NxTx3, axis=1), axis=-1)
        return float(jnp.mean(d))


_clean_curves = jax.jit(functools.partial(curves.window_curves, noise=0.0, key=None),
                        static_argnames=("T", "interval"))


def windows_from_rows(root_Fx3, pose_FxR, *, T: int, frame_step: int, interval: int,
                      max_windows: int | None = None, spread: int | None = None, layout: RowLayout | None = None,
                      fps: float | None = None, source: str = "") -> MotionWindows:
    """Windows of T samples, frame_step apart, with their noise-free curves (`curves.window_curves`,
    as in training): back to back from the first frame (at most `max_windows`), or, with `spread`,
    exactly that many spread evenly from the first frame to the last (overlapping when the motion
    is short). With `layout` and `fps` the gait phase of every sample is measured on the whole
    motion (`gait_stats.gait_phase`) and kept with the windows."""
    root = np.asarray(root_Fx3, np.float32)
    pose = np.asarray(pose_FxR, np.float32)
    F = len(root)
    span = (T - 1) * frame_step + 1
    if spread is not None and F >= span:
        starts = np.round(np.linspace(0, F - span, int(spread))).astype(np.int64)
        frames = starts[:, None] + frame_step * np.arange(T)[None, :]
    else:
        frames = curves.window_indices(F, T, frame_step, max_windows=max_windows)
    if len(frames) == 0:
        raise AnalysisError(f"{source or 'motion'}: {F} frames is shorter than one window "
                            f"({T} samples x step {frame_step} = {span} frames"
                            + (f", {span / fps:.1f} s)" if fps else ")"))
    starts, count = frames[:, 0], len(frames)
    path_frames = starts[:, None] + np.arange(span)[None, :]
    xz = _clean_curves(root[path_frames][..., [0, 2]], np.full(count, span, np.int32), T=int(T),
                       interval=int(interval))
    curve = trajectory.on_floor(xz)
    phase = valid = None
    if layout is not None and fps is not None:
        from motiongan_jax.data import gait_stats

        phase_F, valid_F = gait_stats.gait_phase(root, pose, layout, foot_joints(layout), fps)
        phase, valid = phase_F[frames], valid_F[frames]
    return MotionWindows(jnp.asarray(root[frames]), jnp.asarray(pose[frames]), curve.astype(jnp.float32),
                         starts, int(frame_step), source, phase, valid)


def model_rate_windows(root_Fx3, pose_FxR, fps: float, meta: dict, cfg, layout: RowLayout, *,
                       T: int | None = None, max_windows: int | None = None, spread: int | None = None,
                       phase: bool = False, source: str = "") -> MotionWindows:
    """`windows_from_rows` at the model's sample rate: the run's frame step and spline interval
    scaled by the motion's fps over the training fps (a 120 fps clip is sampled at the training's
    rate too); T defaults to the model's."""
    T = cfg.data.window_T if T is None else int(T)
    ratio = float(fps) / float(meta.get("fps") or fps)
    step = max(1, int(round(cfg.data.frame_step * ratio)))
    interval = max(2, int(round(cfg.data.control_point_interval * ratio)))
    return windows_from_rows(root_Fx3, pose_FxR, T=T, frame_step=step, interval=interval, max_windows=max_windows,
                             spread=spread, layout=layout if phase else None, fps=fps if phase else None,
                             source=source)


# What one clip may be (a file given to --search / --style-from, or the demo's upload): bounds
# checked before the frames are read
MAX_CLIP_BYTES = 8 * 2**20
MAX_CLIP_FRAMES = 36_000  # 5 minutes at 120 fps
MAX_CLIP_JOINTS = 256  # End Sites included


MIN_SPEED_M_PER_S = 0.1  # a motion whose root moves slower on average does not walk: it has no walking style


def bvh_rows(data: bytes, source: str, cfg, layout: RowLayout, *, units_to_m: float | None = None
             ) -> tuple[np.ndarray, np.ndarray, float]:
    """(root_Fx3, pose_FxR, fps) in metres of a BVH file's bytes: read by the strict reader
    (`bvh.parse_bvh`, bounded by MAX_CLIP_BYTES, MAX_CLIP_FRAMES and MAX_CLIP_JOINTS), then
    `motion_rows`; nothing is written. BVHError for a malformed file, AnalysisError for one the
    model cannot read."""
    from motiongan_jax.motion import bvh

    if len(data) > MAX_CLIP_BYTES:
        raise AnalysisError(f"{source}: {len(data) / 2**20:.1f} MiB; a clip file is at most "
                            f"{MAX_CLIP_BYTES // 2**20} MiB")
    motion = bvh.parse_bvh(bvh.decode(data), source, max_joints=MAX_CLIP_JOINTS, max_frames=MAX_CLIP_FRAMES)
    return motion_rows(motion, source, cfg, layout, units_to_m=units_to_m)


def motion_rows(motion, source: str, cfg, layout: RowLayout, *, units_to_m: float | None = None
                ) -> tuple[np.ndarray, np.ndarray, float]:
    """(root_Fx3, pose_FxR, fps) in metres of a parsed BVH motion, read as training reads its files
    (the run's units, unless `units_to_m`, and start offset). AnalysisError naming the problem when
    its kept joints are not the model's, the walker is not 0.5-3 m tall in those units, or it does
    not walk (`check_walks`)."""
    from motiongan_jax.data import clip_cache
    from motiongan_jax.data.positions_npz import PLAUSIBLE_HEIGHT_M

    units = clip_cache.units_for(cfg.data) if units_to_m is None else float(units_to_m)
    clip_layout, root, pose = clip_cache.motion_rows(motion, units, cfg.data.start_offset)
    names, got = tuple(layout.joint_names), tuple(clip_layout.joint_names)
    if got != names:
        missing = [n for n in names if n not in got]
        extra = [n for n in got if n not in names]
        why = "; ".join(([f"lacks {_names(missing)}"] if missing else [])
                        + ([f"has {_names(extra)} besides"] if extra else [])) or "keeps them in another order"
        other = (f"{source}: not the model's skeleton: of the {len(names)} joints the model moves "
                 f"({_names(names)}) it {why}")
        root, pose, units = retargeted_rows(motion, other, cfg, layout, units_to_m)
        clip_layout = dataclasses.replace(layout, source_index=tuple(range(len(names))))
    if len(root) < 2:
        raise AnalysisError(f"{source}: {len(root)} frame after the first {cfg.data.start_offset}; a walk needs more")
    height = float(np.median(np.ptp(np.asarray(from_rows(root, pose, clip_layout))[..., 1], axis=1)))
    lo, hi = PLAUSIBLE_HEIGHT_M
    if not lo <= height <= hi:
        raise AnalysisError(f"{source}: the walker is {height:.3g} m tall at {units:g} m per file unit, not "
                            f"{lo:g}-{hi:g} m: the file is in another unit than the model's data")
    check_walks(root, motion.fps, source)
    return np.asarray(root, np.float64), np.asarray(pose, np.float64), float(motion.fps)


def retargeted_rows(motion, other: str, cfg, layout: RowLayout, units_to_m: float | None = None
                    ) -> tuple[np.ndarray, np.ndarray, float]:
    """(root_Fx3, pose_FxR, units_to_m) of a motion on another skeleton, retargeted onto the model's
    (motion.retarget, the export's retargeting run the other way: the model's skeleton as the rig,
    the file's as the source; its units guessed from its legs unless given). AnalysisError `other`
    (why it is not the model's skeleton) and why it cannot be retargeted, when it cannot."""
    from motiongan_jax.motion import kinematics, retarget, rigs
    from motiongan_jax.motion.representation import guess_units_to_m

    sk = motion.skeleton
    try:
        units = guess_units_to_m(sk) if units_to_m is None else float(units_to_m)
        rigs.resolve_roles(sk, None, "its skeleton")
        if layout.rest_offsets_m is None:
            raise rigs.RigError("the model keeps no rest pose to retarget onto")
        model_rig = rigs.make_rig(retarget.layout_skeleton(layout.joint_names, layout.parents, layout.rest_offsets_m),
                                  "the model's skeleton", units_to_m=1.0)
        start = min(cfg.data.start_offset, max(motion.num_frames - 2, 0))
        world_m = kinematics.world_positions(motion)[start:] * units
        out = retarget.retarget(world_m, sk.names, sk.parents, np.asarray(sk.offsets, np.float64) * units, model_rig,
                                motion.fps)
    except (rigs.RigError, ValueError) as err:
        raise AnalysisError(f"{other}, and it cannot be retargeted onto it: {err}") from None
    kept = dataclasses.replace(layout, source_index=tuple(range(len(layout.joint_names))))
    root, pose = to_rows(out.positions_m, kept)
    return root, pose, units


def check_walks(root_Fx3, fps: float, source: str) -> None:
    """AnalysisError unless the root travels at least MIN_SPEED_M_PER_S on average over the floor."""
    xz = np.asarray(root_Fx3, np.float64)[:, [0, 2]]
    speed = float(np.sum(np.linalg.norm(np.diff(xz, axis=0), axis=1))) * fps / max(len(xz) - 1, 1)
    if not speed >= MIN_SPEED_M_PER_S:
        raise AnalysisError(f"{source}: the root moves {speed:.2g} m/s on average: not a walk (at least "
                            f"{MIN_SPEED_M_PER_S:g} m/s), so it has no walking style to recover")


def _names(names, at_most: int = 8) -> str:
    shown = ", ".join(names[:at_most])
    return shown + (f" and {len(names) - at_most} more" if len(names) > at_most else "")


def load_motion(path, meta: dict, cfg, layout: RowLayout, *, units_to_m: float | None = None,
                clip: int = 0) -> tuple[np.ndarray, np.ndarray, float]:
    """(root_Fx3, pose_FxR, fps) in metres of a BVH file or an .npz of world positions.

    BVH: preprocessed as in training (clip_cache.preprocess_clip with the run's units and start
    offset; no cache). Its kept joints must be the model's. npz: `positions` (F x J x 3, metres),
    either the model's kept joints in order or a full skeleton with `joint_names` (e.g. the
    output of bin/prepare_data.py; `clip_start`/`clip_length` select clip `clip`); `fps`
    defaults to the run's.
    """
    path = Path(path)
    if not path.is_file():
        raise AnalysisError(f"{path}: no such file")
    names = tuple(layout.joint_names)
    if path.suffix.lower() == ".bvh":
        size = path.stat().st_size
        if size > MAX_CLIP_BYTES:
            raise AnalysisError(f"{path}: {size / 2**20:.1f} MiB; a clip file is at most {MAX_CLIP_BYTES // 2**20} MiB")
        return bvh_rows(path.read_bytes(), str(path), cfg, layout, units_to_m=units_to_m)
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
    check_walks(root, fps, str(path))
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
    return model_rate_windows(root, pose, fps, meta, cfg, layout, T=T, max_windows=max_windows, source=str(path))
