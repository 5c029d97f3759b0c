"""Clips: one BVH file preprocessed into root trajectory and root-relative rows (metres), cached by
content hash; a dataset is every clip of a data directory, labelled and split.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import sys
from pathlib import Path

import numpy as np

from motiongan_jax import atomic
from motiongan_jax.cache import cache_root
from motiongan_jax.config import DataConfig
from motiongan_jax.data import synthetic
from motiongan_jax.data.file_labels import DataError, FileLabel, discover, split_by_trial
from motiongan_jax.motion import bvh, kinematics
from motiongan_jax.motion.representation import UNITS_TO_M, RowLayout, layout_from_skeleton, to_rows

# Bump when preprocessing changes what it computes: part of every cache key.
CACHE_VERSION = "1"


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
    layout, root, pose = motion_rows(motion, units_to_m, start_offset)
    if use_cache:
        cache_file.parent.mkdir(parents=True, exist_ok=True)
        sk = motion.skeleton
        with atomic.atomic_path(cache_file) as tmp, open(tmp, "wb") as fh:
            np.savez(fh, root=root, pose=pose, fps=motion.fps, names=np.array(sk.names),
                     parents=np.array(sk.parents), offsets=sk.offsets,
                     channels=np.array(json.dumps([list(c) for c in sk.channels])))
    return Clip(str(path), label, motion.fps, root, pose, layout)


def motion_rows(motion: bvh.Motion, units_to_m: float, start_offset: int) -> tuple[RowLayout, np.ndarray, np.ndarray]:
    """(layout, root_Fx3, pose_FxR) of a parsed BVH motion as training reads it: its kept joints,
    world positions in metres from frame `start_offset` on, float32."""
    layout = layout_from_skeleton(motion.skeleton, units_to_m)
    world_m = kinematics.world_positions(motion) * units_to_m
    root, pose = to_rows(world_m[start_offset:], layout)
    return layout, root.astype(np.float32), pose.astype(np.float32)


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

