"""A folder of BVH files as one .npz of world joint positions (every joint, metres, Y up) for users'
own code: what bin/prepare_data.py writes and analysis.clips.load_motion reads back."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from motiongan_jax import atomic
from motiongan_jax.data.file_labels import DataError, label_from_filename
from motiongan_jax.motion import bvh, kinematics
from motiongan_jax.motion.representation import UNITS_TO_M

# How tall a person stands (the span of the joints' heights, metres): outside it the file's unit
# is not the one assumed (Bandai's centimetres read as CMU units make an 8 m tall walker)
PLAUSIBLE_HEIGHT_M = (0.5, 3.0)


def write_positions_npz(data_dir: str | Path, out: str | Path, labels: str = "paper",
                        units_to_m: float | None = None, skip_bad: bool = False, log=print) -> dict:
    """Read every BVH under data_dir and write one .npz (see bin/prepare_data.py --help).

    Nothing is written unless every file (or, with skip_bad, every good file) was read.
    """
    data_dir, out = Path(data_dir), Path(out)
    if not data_dir.is_dir():
        raise DataError(f"data directory not found: {data_dir}")
    _check_writable(out)  # before the files are read: that can take minutes
    motions, errors = bvh.read_bvh_dir(data_dir, skip_bad=skip_bad)
    for err in errors:
        log(f"skipped: {err}")
    if not motions:
        raise DataError(f"no readable .bvh files under {data_dir}")
    units = units_to_m if units_to_m is not None else UNITS_TO_M[labels]
    first = motions[0].skeleton
    positions, starts, lengths, styles, sources = [], [], [], [], []
    offset = 0
    for m in motions:
        if m.skeleton.names != first.names or m.skeleton.parents != first.parents:
            raise DataError(f"{m.source}: skeleton differs from {motions[0].source}")
        if abs(m.fps - motions[0].fps) > 1e-3:
            raise DataError(f"{m.source}: {m.fps:.3f} fps differs from {motions[0].fps:.3f} fps")
        label = label_from_filename(m.source, labels)
        if label is None:
            raise DataError(f"{m.source}: file name gives no style label under --labels {labels}")
        pos = kinematics.world_positions(m) * units
        if not positions:
            _check_height(pos, m.source, labels, units, explicit=units_to_m is not None, log=log)
        positions.append(pos.astype(np.float32))
        starts.append(offset)
        lengths.append(len(pos))
        styles.append(label.style)
        sources.append(str(Path(m.source).relative_to(data_dir)))
        offset += len(pos)
    style_names = sorted(set(styles))
    arrays = dict(
        positions=np.concatenate(positions),
        joint_names=np.array(first.names),
        parents=np.array(first.parents, np.int32),
        clip_start=np.array(starts, np.int64),
        clip_length=np.array(lengths, np.int64),
        clip_style=np.array([style_names.index(s) for s in styles], np.int32),
        style_names=np.array(style_names),
        fps=np.float64(motions[0].fps),
        source_files=np.array(sources),
    )
    try:
        with atomic.atomic_path(out) as tmp, open(tmp, "wb") as fh:
            np.savez(fh, **arrays)
    except OSError as e:
        raise DataError(f"cannot write {out}: {e.strerror or e}") from None
    return {"clips": len(motions), "frames": int(offset), "joints": len(first.names),
            "styles": style_names, "skipped": len(errors)}


def _check_writable(out: Path) -> None:
    """DataError unless `out` can be written (its folder made if need be)."""
    if out.is_dir():
        raise DataError(f"cannot write {out}: it is a directory")
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise DataError(f"cannot write {out}: cannot make its folder {out.parent} ({e.strerror or e})") from None
    if not os.access(out.parent, os.W_OK):
        raise DataError(f"cannot write {out}: folder {out.parent} is not writable")


def _check_height(pos, source, labels: str, units: float, explicit: bool, log) -> None:
    """DataError (a warning when the unit was given with --units-to-m) when the first clip's
    walker is not PLAUSIBLE_HEIGHT_M tall in the unit assumed."""
    height = float(np.median(pos[..., 1].max(axis=1) - pos[..., 1].min(axis=1)))
    lo, hi = PLAUSIBLE_HEIGHT_M
    if lo <= height <= hi:
        return
    msg = (f"{source}: the skeleton is {height:.3g} m tall at {units:g} m per file unit, not {lo:g}-{hi:g} m: "
           f"the files are in another unit")
    if explicit:
        log(f"warning: {msg} than --units-to-m {units:g}")
        return
    raise DataError(f"{msg} than --labels {labels} assumes; Bandai files are in centimetres (--labels bandai), "
                    f"or give the unit with --units-to-m")
