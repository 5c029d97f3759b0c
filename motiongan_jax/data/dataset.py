"""Datasets: discovery, style labels, splits, the preprocessing cache, and batched windows.

Files -> (per clip) root trajectory and root-relative rows in metres, cached by content hash ->
one `ClipArrays` -> `sample_batch(arrays, key, step)`: a jitted, batched function of an explicit
key that cuts training windows with FPS and rotation augmentation and noisy input curves.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import re
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from scipy.ndimage import gaussian_filter1d, uniform_filter1d
from scipy.signal import hilbert

from motiongan_jax import atomic
from motiongan_jax.config import DataConfig
from motiongan_jax.data import curves
from motiongan_jax.evaluation import metrics
from motiongan_jax.motion import bvh, kinematics
from motiongan_jax.motion.representation import (
    UNITS_TO_M,
    RowLayout,
    foot_joints,
    from_rows,
    layout_from_skeleton,
    to_rows,
)

# Bump when preprocessing changes what it computes: part of every cache key.
CACHE_VERSION = "1"

# CMU styled-walk trials (subjects 137 and 142) -> style, as the CMU database describes them.
CMU_TRIAL_STYLES: dict[str, str] = {
    "137_04": "Cat", "137_08": "Chicken", "137_12": "Dinosaur", "137_16": "Drunk",
    "137_20": "GanglyTeen", "137_24": "GracefulLady", "137_29": "Normal", "137_33": "OldMan",
    "137_38": "SexyLady", "137_42": "StrongMan",
    "142_01": "Childish", "142_02": "Clumsy", "142_03": "Clumsy", "142_04": "Cool",
    "142_05": "Depressed", "142_06": "Elated", "142_07": "Elderlyman", "142_08": "Happy",
    "142_09": "Joy", "142_10": "Lavish", "142_11": "Marching", "142_12": "Painfulleftknee",
    "142_13": "Relaxed", "142_14": "Rushed", "142_15": "Sad", "142_16": "Scared",
    "142_17": "Scared", "142_18": "Sexy", "142_19": "Shy", "142_20": "Singingintherainjump",
    "142_21": "Singingintherainjump", "142_22": "Sneaky",
}

# The paper's 28 classes, in the order that fixes label indices 0..27 (docs/DESIGN.md §2.1).
PAPER_STYLES = (
    "Cat", "Chicken", "Dinosaur", "Drunk", "GanglyTeen", "GracefulLady", "Normal", "OldMan",
    "SexyLady", "StrongMan", "Childish", "Clumsy", "Cool", "Depressed", "Elated", "Elderlyman",
    "Happy", "Joy", "Lavish", "Marching", "Painfulleftknee", "Relaxed", "Rushed", "Sad", "Scared",
    "Sexy", "Shy", "Sneaky",
)


class DataError(ValueError):
    """A dataset problem (no files, unknown label, mismatched skeletons); the message says which."""


# ----------------------------------------------------------------------------------------------
# Discovery and labels
# ----------------------------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class FileLabel:
    style: str
    trial: int  # drives the train/validation split
    content: str = "walk"


_BANDAI = re.compile(r"^dataset-(\d+)_([A-Za-z-]+)_([A-Za-z-]+)_(\d+)$")
_CMU = re.compile(r"^(\d+)_(\d+)$")


def label_from_filename(path: str | Path, rule: str) -> FileLabel | None:
    """The style label (and trial number) a file's name gives under `rule`; None if it gives none."""
    stem = Path(path).stem
    if rule in ("paper", "synthetic"):
        if "_" not in stem:
            return None
        style, rest = stem.split("_", 1)
        digits = re.findall(r"\d+", rest)
        return FileLabel(style=style, trial=int(digits[-1]) if digits else 0)
    if rule in ("bandai", "bandai_session"):
        m = _BANDAI.match(stem)
        if not m:
            return None
        # bandai_session keeps the recording sessions apart ("d1_active" and "d2_active" are two
        # styles), like the paper's two actors
        style = m.group(3) if rule == "bandai" else f"d{int(m.group(1))}_{m.group(3)}"
        return FileLabel(style=style, trial=int(m.group(4)), content=m.group(2))
    if rule == "cmu":
        m = _CMU.match(stem)
        if not m:
            return None
        key = f"{int(m.group(1)):03d}_{int(m.group(2)):02d}"
        style = CMU_TRIAL_STYLES.get(key)
        return None if style is None else FileLabel(style=style, trial=int(m.group(2)))
    raise DataError(f"unknown label rule {rule!r}")


def discover(data_dir: str | Path, rule: str) -> list[tuple[Path, FileLabel]]:
    """Every *.bvh under data_dir (recursive, sorted) with its label. Unlabelled files are errors."""
    root = Path(data_dir)
    if not root.is_dir():
        raise DataError(f"data directory not found: {root}")
    files = sorted(root.rglob("*.bvh"))
    if not files:
        raise DataError(f"no .bvh files under {root}")
    out, unlabelled = [], []
    for f in files:
        label = label_from_filename(f, rule)
        (unlabelled if label is None else out).append(f if label is None else (f, label))
    if unlabelled:
        names = ", ".join(p.name for p in unlabelled[:5])
        raise DataError(
            f"{len(unlabelled)} file(s) under {root} have no style label under rule {rule!r} "
            f"(e.g. {names}); choose another data.label_rule or remove them")
    return out


def split_by_trial(entries, modulus: int, remainder: int):
    """Deterministic train/validation split: trial % modulus == remainder goes to validation."""
    if modulus == 0:
        return list(entries), []
    train = [e for e in entries if e[1].trial % modulus != remainder]
    val = [e for e in entries if e[1].trial % modulus == remainder]
    return train, val


def write_file_lists(out_dir: str | Path, train, val, root: str | Path | None = None) -> None:
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    for name, entries in (("train_files.txt", train), ("val_files.txt", val)):
        lines = [str(Path(p).relative_to(root)) if root else str(p) for p, _ in entries]
        atomic.write_text(out_dir / name, "".join(line + "\n" for line in lines))


# ----------------------------------------------------------------------------------------------
# Preprocessing and its cache
# ----------------------------------------------------------------------------------------------

def cache_root() -> Path:
    """Where preprocessed clips and the generated embedded dataset live: $MOTIONGAN_CACHE,
    default ~/.cache/motiongan_jax."""
    return Path(os.environ.get("MOTIONGAN_CACHE", Path.home() / ".cache" / "motiongan_jax"))


def units_for(cfg: DataConfig) -> float:
    return cfg.units_to_m if cfg.units_to_m is not None else UNITS_TO_M[cfg.label_rule]


@dataclasses.dataclass(frozen=True, eq=False)
class Clip:
    source: str
    label: FileLabel
    fps: float
    root_Fx3: np.ndarray  # metres, float32
    pose_FxR: np.ndarray  # metres, float32
    layout: RowLayout


def _clip_cache_key(file_bytes: bytes, units_to_m: float, start_offset: int) -> str:
    h = hashlib.sha256()
    h.update(f"motiongan_jax-clip-v{CACHE_VERSION}|units={units_to_m!r}|offset={start_offset}|".encode())
    h.update(file_bytes)
    return h.hexdigest()


def preprocess_clip(path: Path, label: FileLabel, units_to_m: float, start_offset: int,
                    use_cache: bool = True) -> Clip:
    """One BVH file -> Clip. The cache key covers the file's bytes and every setting used, so a
    stale entry cannot be read: any change gives another key."""
    raw = Path(path).read_bytes()
    key = _clip_cache_key(raw, units_to_m, start_offset)
    cache_file = cache_root() / "clips" / f"{key}.npz"
    if use_cache and cache_file.is_file():
        with np.load(cache_file, allow_pickle=False) as z:
            skeleton = bvh.Skeleton(
                names=tuple(str(s) for s in z["names"]),
                parents=tuple(int(p) for p in z["parents"]),
                offsets=z["offsets"],
                channels=tuple(tuple(c) for c in json.loads(str(z["channels"]))),
            )
            layout = layout_from_skeleton(skeleton, units_to_m)
            return Clip(str(path), label, float(z["fps"]), z["root"], z["pose"], layout)
    motion = bvh.parse_bvh(raw.decode("utf-8", errors="strict"), source=str(path))
    layout = layout_from_skeleton(motion.skeleton, units_to_m)
    world_m = kinematics.world_positions(motion) * units_to_m
    root, pose = to_rows(world_m[start_offset:], layout)
    root, pose = root.astype(np.float32), pose.astype(np.float32)
    if use_cache:
        cache_file.parent.mkdir(parents=True, exist_ok=True)
        sk = motion.skeleton
        with atomic.atomic_path(cache_file) as tmp, open(tmp, "wb") as fh:
            np.savez(fh, root=root, pose=pose, fps=motion.fps, names=np.array(sk.names),
                     parents=np.array(sk.parents), offsets=sk.offsets,
                     channels=np.array(json.dumps([list(c) for c in sk.channels])))
    return Clip(str(path), label, motion.fps, root, pose, layout)


# ----------------------------------------------------------------------------------------------
# The dataset as flat arrays
# ----------------------------------------------------------------------------------------------

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


@dataclasses.dataclass(frozen=True, eq=False)
class Dataset:
    style_names: tuple[str, ...]
    layout: RowLayout
    fps: float
    train: list[Clip]
    val: list[Clip]
    data_dir: str  # where the files came from

    @property
    def num_styles(self) -> int:
        return len(self.style_names)


def _check_layouts(clips: list[Clip]) -> RowLayout:
    first = clips[0]
    for c in clips[1:]:
        if c.layout.signature() != first.layout.signature():
            raise DataError(
                f"skeletons differ: {c.source} has joints {c.layout.joint_names} but "
                f"{first.source} has {first.layout.joint_names}")
    # Bone targets come from the skeletons' offsets (not from one augmented sample, as the
    # reference did); with several subjects, their mean.
    lengths = np.mean([c.layout.bone_lengths_m for c in clips], axis=0)
    rest = np.mean([c.layout.rest_offsets_m for c in clips], axis=0)
    return dataclasses.replace(first.layout, bone_lengths_m=lengths, rest_offsets_m=rest)


def resolve_data_dir(cfg: DataConfig) -> Path:
    if cfg.data_dir is not None:
        return Path(cfg.data_dir)
    from motiongan_jax.data import synthetic

    return synthetic.default_dataset_dir(cfg.synthetic_seed)


def load_dataset(cfg: DataConfig, *, use_cache: bool = True, log=None) -> Dataset:
    """Discover, label, split and preprocess (through the cache) every clip under the data dir."""
    data_dir = resolve_data_dir(cfg)
    entries = discover(data_dir, cfg.label_rule)
    if cfg.styles:
        unknown = sorted({lab.style for _, lab in entries} - set(cfg.styles))
        if unknown:
            skipped = [p.name for p, lab in entries if lab.style in unknown]
            msg = (f"skipping {len(skipped)} file(s) whose style is not in data.styles: "
                   f"{', '.join(unknown)}")
            (log or (lambda s: print(s, file=sys.stderr)))(msg)
        entries = [(p, lab) for p, lab in entries if lab.style in cfg.styles]
        missing = [s for s in cfg.styles if s not in {lab.style for _, lab in entries}]
        if missing:
            raise DataError(f"data.styles lists styles with no files under {data_dir}: {', '.join(missing)}")
        style_names = tuple(cfg.styles)
    else:
        style_names = tuple(sorted({lab.style for _, lab in entries}))
    units = units_for(cfg)
    train_e, val_e = split_by_trial(entries, cfg.val_modulus, cfg.val_remainder)
    train = [preprocess_clip(p, lab, units, cfg.start_offset, use_cache) for p, lab in train_e]
    val = [preprocess_clip(p, lab, units, cfg.start_offset, use_cache) for p, lab in val_e]
    if not train:
        raise DataError(f"no training clips under {data_dir} after the validation split")
    # A clip no longer than one window gives no training window and no evaluation window; such
    # clips are dropped before the skeletons are compared (two 20-31-frame Bandai dataset-1 clips
    # also carry a different End Site layout).
    short = [c for c in train + val if len(c.root_Fx3) <= cfg.frame_nums]
    if short:
        names = ", ".join(Path(c.source).name for c in short[:5])
        (log or (lambda m: print(m, file=sys.stderr)))(
            f"skipping {len(short)} clip(s) no longer than data.frame_nums = {cfg.frame_nums} frames: {names}")
        longest = max(len(c.root_Fx3) for c in train)
        train = [c for c in train if len(c.root_Fx3) > cfg.frame_nums]
        val = [c for c in val if len(c.root_Fx3) > cfg.frame_nums]
        if not train:
            raise DataError(f"no training clip is longer than data.frame_nums = {cfg.frame_nums} frames "
                            f"(longest: {longest}); lower frame_nums or frame_step")
    layout = _check_layouts(train + val)
    fps_set = {round(c.fps, 3) for c in train + val}
    if len(fps_set) != 1:
        raise DataError(f"clips have different frame rates {sorted(fps_set)}; resample them first")
    return Dataset(style_names, layout, float(train[0].fps), train, val, str(data_dir))


# ----------------------------------------------------------------------------------------------
# Gait statistics of real clips (what the gait terms of training aim at)
# ----------------------------------------------------------------------------------------------

CONTACT_PERCENTILE = 10.0  # contact height: this percentile of real toe heights above the floor ...
CONTACT_MARGIN_M = 0.02  # ... plus this
SPEED_SMOOTHING_S = 0.5  # the pelvis path is smoothed over this (Gaussian sigma) to drop its sway


@dataclasses.dataclass(frozen=True)
class GaitTargets:
    stride_m_C: tuple[float, ...]  # each style's median stride length (one left and one right step)
    contact_height_m: float  # a toe this close to the floor counts as planted
    toe_joints: tuple[int, int]  # kept-joint indices of the left and right toe


def clip_toe_heights(clip: Clip, layout: RowLayout, toes: tuple[int, int]) -> np.ndarray:
    """Heights (F, 2) of the two toes above the clip's floor (metrics.toe_heights)."""
    return metrics.toe_heights(np.asarray(from_rows(clip.root_Fx3, clip.pose_FxR, layout))[:, list(toes)])


def clip_stride_m(clip: Clip, layout: RowLayout, toes: tuple[int, int]) -> float:
    """Stride length of a clip: its walking speed (the smoothed pelvis path's length over the
    clip's duration) over its step frequency (metrics.step_frequency_hz); nan without steps."""
    freq = metrics.step_frequency_hz(clip_toe_heights(clip, layout, toes), clip.fps)
    xz = gaussian_filter1d(np.asarray(clip.root_Fx3, np.float64)[:, [0, 2]], SPEED_SMOOTHING_S * clip.fps,
                           axis=0, mode="nearest")
    speed = np.sum(np.linalg.norm(np.diff(xz, axis=0), axis=1)) * clip.fps / (len(xz) - 1)
    return float(speed / freq) if np.isfinite(freq) and freq > 0 else float("nan")


PHASE_DETREND_S = 2.0  # the toe-height difference minus its moving average over this ...
PHASE_SMOOTHING_S = 0.04  # ... smoothed over this (Gaussian sigma), before its Hilbert phase
PHASE_MIN_AMPLITUDE = 0.3  # frames whose step amplitude is below this share of the clip's median have no phase


def clip_gait_phase(clip: Clip, layout: RowLayout, toes: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """(phase_F radians, valid_F bool): the gait phase of every frame, measured without annotation:
    the unwrapped angle of the analytic signal (Hilbert transform) of left − right toe height,
    detrended and smoothed. It rises 2π per gait cycle and is 0 where the left toe is highest above
    the right. Frames where the steps fade (standing, a start or a stop) are not `valid`: their
    angle is noise."""
    h = clip_toe_heights(clip, layout, toes)
    d = h[:, 0] - h[:, 1]
    d = d - uniform_filter1d(d, max(int(round(PHASE_DETREND_S * clip.fps)), 1), mode="nearest")
    d = gaussian_filter1d(d, PHASE_SMOOTHING_S * clip.fps, mode="nearest")
    analytic = hilbert(d)
    amplitude = np.abs(analytic)
    valid = amplitude > PHASE_MIN_AMPLITUDE * max(float(np.median(amplitude)), 1e-9)
    return np.unwrap(np.angle(analytic)).astype(np.float32), valid


def contact_height(clips: list[Clip], layout: RowLayout, toes: tuple[int, int]) -> float:
    """The contact height (metres) calibrated on real clips: CONTACT_PERCENTILE of their toe
    heights above each clip's floor, pooled, plus CONTACT_MARGIN_M."""
    heights = np.concatenate([clip_toe_heights(c, layout, toes).ravel() for c in clips])
    return metrics.contact_height_threshold(heights, CONTACT_PERCENTILE) + CONTACT_MARGIN_M


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


def make_sample_batch(cfg: DataConfig, batch_size: int):
    """Returns sample_batch(arrays, key, step) -> Batch (see docs/CONTRACTS.md). jit it."""
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
        curve = curves.on_floor(curve_xz)
        if cfg.rotate:
            theta_B = jax.random.uniform(k_rot, (batch_size,), maxval=2 * jnp.pi)
            root = curves.rotate_y(root, theta_B[:, None])
            curve = curves.rotate_y(curve, theta_B[:, None])
            pose = curves.rotate_rows_y(pose, theta_B[:, None])
        return {
            "root_BxTx3": root.astype(jnp.float32),
            "pose_BxTxR": pose.astype(jnp.float32),
            "curve_BxTx3": curve.astype(jnp.float32),
            "label_B": arrays.clip_label_C[clip_B],
            "phase_BxT": arrays.phase_N[frame_BxT],
            "phase_valid_BxT": arrays.phase_valid_N[frame_BxT],
        }

    return sample_batch
