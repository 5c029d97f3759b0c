"""A folder of BVH files as one .npz of world joint positions (every joint, metres, Y up) for users'
own code: what bin/prepare_data.py writes and analysis.clips.load_motion reads back."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from motiongan_jax import atomic
from motiongan_jax.data.file_labels import DataError, label_from_filename
from motiongan_jax.motion import bvh, kinematics
from motiongan_jax.motion.representation import UNITS_TO_M


def write_positions_npz(data_dir: str | Path, out: str | Path, labels: str = "paper",
                        units_to_m: float | None = None, skip_bad: bool = False, log=print) -> dict:
    """Read every BVH under data_dir and write one .npz (see bin/prepare_data.py --help).

    Nothing is written unless every file (or, with skip_bad, every good file) was read.
    """
    data_dir, out = Path(data_dir), Path(out)
    if not data_dir.is_dir():
        raise DataError(f"data directory not found: {data_dir}")
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
    out.parent.mkdir(parents=True, exist_ok=True)
    with atomic.atomic_path(out) as tmp, open(tmp, "wb") as fh:
        np.savez(fh, **arrays)
    return {"clips": len(motions), "frames": int(offset), "joints": len(first.names),
            "styles": style_names, "skipped": len(errors)}
