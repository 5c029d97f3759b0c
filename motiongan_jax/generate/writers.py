"""Writing generated motion: Outputs (by suffix; several motions -> .bvh/.npz get one file each, `name_<i>.ext`;
.gif/.mp4/.png show them side by side). Every file is written atomically: on an error nothing
(not even a partial file) is left at the output path.
- .bvh: ik.positions_to_motion on the layout's skeleton (see ik.py for the twist rule), by
  default in the training skeleton's own hierarchy (the bones leaving a joint with several
  children are best fits; the error goes to `log`), or with hierarchy "exact" with zero-length
  branch joints and every bone direction exact; bone lengths the skeleton's; metres by default
  (Blender's BVH importer maps one file unit to one Blender unit = 1 m at its default scale
  1.0, and converts Y-up to its Z-up with its default axes), or centimetres with units="cm"
  (import those with scale 0.01).
- .npz: positions (T, J, 3) float64 metres, Y up (the generated joints, after the floor shift);
  positions_skeleton (T, J, 3): the same pose on the skeleton's bone lengths (= FK of the .bvh,
  in the same hierarchy); joint_names, parents, fps (samples per second), style, w, z, curve
  (T, 3), floor_shift_m.
- .glb / .gltf: one file holding every motion as an animation of one skinned character
  (motion.gltf): the .bvh's skeleton and rotations (same hierarchy option) with the project's
  body (motion.body_mesh), metres, Y up, +Z forward; .gltf is JSON with its buffer inside.
- with a rig (motion.rigs.Rig, `--rig`): .bvh and .glb/.gltf hold the walk retargeted onto the rig's
  skeleton (motion.retarget), the .bvh in the rig's own units; `log` gets the matched joints and
  the foot skate and floor penetration beside the model's skeleton's.
- .gif (Pillow) / .mp4 (ffmpeg or imageio-ffmpeg): a chase-camera animation (viz.animate_motions) of
  the skinned body (a coarse one, body_mesh.PREVIEW), filling most of the frame, the camera behind
  the walker's side, the floor's grid and the path around it; `body=False`: stick figures.
- .png: stroboscopic strips (viz.pose_strips), the form of the paper's Figs. 4, 6 and 7.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from motiongan_jax import atomic
from motiongan_jax.generate import limits
from motiongan_jax.generate.walk import Generated
from motiongan_jax.motion import body_mesh, bvh, gltf, ik, kinematics, representation, retarget, rigs

OUTPUT_SUFFIXES = (".bvh", ".glb", ".gltf", ".npz", ".gif", ".mp4", ".png")
ONE_FILE = (".glb", ".gltf", ".gif", ".mp4", ".png")  # every motion in one file
RIG_SUFFIXES = (".bvh", ".glb", ".gltf")  # what a retargeted walk can be written as
BVH_UNITS = {"m": 1.0, "cm": 100.0}


def check_output_path(out, *, count: int = 1, rig: bool = False) -> list[Path]:
    """The file(s) an output will be written to; GenerateError for an unsupported suffix (or one
    a retargeted walk cannot be written as, with `rig`), a missing or unwritable directory, or a
    directory in the way. Nothing is created."""
    out = Path(out)
    suffix = out.suffix.lower()
    if suffix not in OUTPUT_SUFFIXES:
        raise limits.GenerateError(f"output {out}: unsupported format {out.suffix or '(none)'!r}; use one of "
                                   f"{', '.join(OUTPUT_SUFFIXES)}")
    if rig and suffix not in RIG_SUFFIXES:
        raise limits.GenerateError(f"output {out}: a walk retargeted onto a rig is written as "
                                   f"{', '.join(RIG_SUFFIXES)}, not {out.suffix}")
    parent = out.parent
    if parent.exists() and not parent.is_dir():
        raise limits.GenerateError(f"cannot write {out}: {parent} is not a directory")
    if not parent.is_dir():
        raise limits.GenerateError(f"cannot write {out}: directory {parent} does not exist")
    try:  # a real probe: os.access says yes to root even where writing fails (/proc, read-only mounts)
        fd, probe = tempfile.mkstemp(dir=parent, prefix=f".{out.name}.", suffix=".probe")
        os.close(fd)
        os.unlink(probe)
    except OSError as e:
        raise limits.GenerateError(f"cannot write {out}: directory {parent} is not writable "
                                   f"({e.strerror})") from None
    paths = [out] if count == 1 or suffix in ONE_FILE else \
        [out.with_name(f"{out.stem}_{i}{out.suffix}") for i in range(count)]
    for p in paths:
        if p.is_dir():
            raise limits.GenerateError(f"cannot write {p}: it is a directory")
        if p.exists() and not os.access(p, os.W_OK):
            raise limits.GenerateError(f"cannot write {p}: the existing file is read-only")
    if suffix == ".mp4":
        from motiongan_jax import viz

        try:
            viz.video_writer(out, 15.0)
        except RuntimeError as e:
            raise limits.GenerateError(str(e)) from None
    return paths


def check_output_size(out, frames: int, count: int = 1) -> None:
    """GenerateError when a .gif of `count` panels x `frames` frames exceeds MAX_GIF_FRAMES
    (Pillow keeps every frame in memory until the file is written; .mp4 streams to ffmpeg)."""
    if Path(out).suffix.lower() == ".gif" and frames * count > limits.MAX_GIF_FRAMES:
        raise limits.GenerateError(f"output {out}: a GIF of {count} panel(s) x {frames:,} frames is more than "
                                   f"the limit of {limits.MAX_GIF_FRAMES:,} frames x panels "
                                   f"(generate.limits.MAX_GIF_FRAMES; GIF frames are held in memory): "
                                   f"write .mp4, .bvh or .npz, or a shorter curve")


def rest_offsets(layout) -> np.ndarray:
    """The export skeleton's rest offsets: the layout's (every checkpoint stores them)."""
    if layout.rest_offsets_m is None:
        raise limits.GenerateError("this layout has no rest offsets: a BVH export needs the skeleton's rest pose")
    return np.asarray(layout.rest_offsets_m, np.float64)


def to_bvh_motion(positions_TxJx3, layout, fps: float, units: str = "m", log=None,
                  hierarchy: str = "source"):
    """(bvh.Motion, ExportSkeleton) of one generated clip on the `hierarchy` of ik.HIERARCHIES
    (see ik.py). For "source", `log` gets how far the best-fit bones are off the generated
    directions."""
    if units not in BVH_UNITS:
        raise limits.GenerateError(f"BVH units must be one of {', '.join(BVH_UNITS)}, got {units!r}")
    if hierarchy not in ik.HIERARCHIES:
        raise limits.GenerateError(f"BVH hierarchy must be one of {', '.join(ik.HIERARCHIES)}, got {hierarchy!r}")
    rest = rest_offsets(layout)
    scale = BVH_UNITS[units]
    motion = ik.positions_to_motion(positions_TxJx3, layout.joint_names, layout.parents, rest,
                                    1.0 / fps, units_per_m=scale, hierarchy=hierarchy)
    ex = ik.export_skeleton(layout.joint_names, layout.parents, rest, scale, hierarchy)
    if log is not None and hierarchy == "source":
        err = ik.bone_errors(positions_TxJx3, ik.layout_positions(motion, ex), layout.parents)
        kids = np.bincount(np.asarray(layout.parents[1:]), minlength=layout.num_joints)
        fitted = [b for b in range(layout.num_joints - 1)
                  if kids[layout.parents[b + 1]] > 1 and ex.helper_index[b + 1] < 0]
        if fitted:
            names = sorted({layout.joint_names[layout.parents[b + 1]] for b in fitted})
            deg = np.degrees(err[:, fitted])
            # how far the joint at the bone's end moves: a chord of the bone's length
            cm = 200 * np.asarray(layout.bone_lengths_m)[fitted] * np.sin(err[:, fitted] / 2)
            log(f"BVH, source hierarchy: the {len(fitted)} bones leaving {', '.join(names)} are best fits, "
                f"{deg.mean():.2g} deg mean and {deg.max():.2g} deg max off the generated directions "
                f"({cm.mean():.2g} cm mean, {cm.max():.2g} cm max at the joints they lead to; every other bone "
                f"direction exact); --bvh-hierarchy exact makes them exact with a zero-length joint per bone")
    return motion, ex


def save_bvh(path, positions_TxJx3, layout, fps: float, units: str = "m", log=None,
             hierarchy: str = "source") -> Path:
    motion, _ = to_bvh_motion(positions_TxJx3, layout, fps, units, log, hierarchy)
    bvh.write_bvh(path, motion, precision=6 if units == "cm" else 7)
    return Path(path)


def save_npz(path, gen: Generated, index: int, layout, fps: float, style: str, z=None,
             log=None, hierarchy: str = "source") -> Path:
    pos = gen.positions[index]
    motion, ex = to_bvh_motion(pos, layout, fps, "m", log, hierarchy)
    skel = ik.layout_positions(motion, ex)
    arrays = dict(positions=pos, positions_skeleton=skel,
                  joint_names=np.array(layout.joint_names), parents=np.array(layout.parents, np.int32),
                  fps=np.float64(fps), style=np.array(style), w=gen.w[index],
                  curve=gen.curve, floor_shift_m=np.float64(gen.floor_shift_m[index]))
    if z is not None:
        arrays["z"] = np.asarray(z, np.float32)
    path = Path(path)
    with atomic.atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            np.savez(fh, **arrays)
    return path


def retargeted(gen: Generated, layout, fps: float, rig, log=None) -> list:
    """Every motion of `gen` on `rig` (retarget.Retargeted each); `log` gets what was matched and
    the feet of each beside the model's skeleton's."""
    out = []
    for pos in gen.positions:
        r = retarget.retarget(pos, layout.joint_names, layout.parents, rest_offsets(layout), rig, fps)
        if log is not None:
            log(retarget.describe(r.report, rig))
        out.append(r)
    return out


def save_gltf(path, gen: Generated, titles: Sequence[str], layout, fps: float, *, rig=None,
              hierarchy: str = "source", log=None) -> Path:
    """Every motion of `gen` as one animation each of a skinned character (motion.gltf): on the
    model's skeleton (the .bvh's, in `hierarchy`) or, with `rig`, retargeted onto it."""
    if rig is None:
        motions = [to_bvh_motion(p, layout, fps, "m", log if i == 0 else None, hierarchy)[0]
                   for i, p in enumerate(gen.positions)]
        units = 1.0
    else:
        motions = [r.motion for r in retargeted(gen, layout, fps, rig, log)]
        units = rig.units_to_m
    skeleton = motions[0].skeleton
    return gltf.write_gltf(path, skeleton, units, motions, titles, gltf.body_for(skeleton, units))


def preview_body(positions_TxJx3, layout, fps: float):
    """(triangles, face colours, frame -> vertices) of the body walking `positions` for
    viz.animate_motions: the coarse body (body_mesh.PREVIEW) on the exact hierarchy (every bone
    where G put it), skinned one frame at a time; limbs tinted by side like the bones."""
    from motiongan_jax import viz

    motion, _ = to_bvh_motion(positions_TxJx3, layout, fps, "m", None, "exact")
    body = gltf.body_for(motion.skeleton, 1.0, **body_mesh.PREVIEW)
    rest = rigs.rest_world(motion.skeleton)
    R, P = kinematics.world_transforms(motion)
    side = [representation.joint_side(n) for n in motion.skeleton.names]
    tint = {"left": matplotlib_rgb(viz.LEFT_COLOR), "right": matplotlib_rgb(viz.RIGHT_COLOR)}
    skin_rgb = np.array(gltf.BODY_COLOR[:3])
    owner = body.joints[body.triangles[:, 0], 0]
    base = np.array([0.7 * skin_rgb + 0.3 * tint[side[j]] if side[j] in tint else skin_rgb for j in owner])

    def vertices_at(t: int):
        return body_mesh.skin(body, rest, R[t:t + 1], P[t:t + 1])[0]

    return body.triangles, base, vertices_at


def matplotlib_rgb(color) -> np.ndarray:
    from matplotlib.colors import to_rgb

    return np.array(to_rgb(color))


def write_outputs(out, gen: Generated, titles: Sequence[str], layout, fps: float, *,
                  bvh_units: str = "m", bvh_hierarchy: str = "source", z_per_motion=None,
                  log: Callable[[str], None] | None = None, rig=None, body: bool = True) -> list[Path]:
    """Writes every motion of `gen` to `out` by its suffix (module doc); returns the paths.
    `bvh_hierarchy` (ik.HIERARCHIES) is the skeleton of .bvh and glTF files and of .npz's
    positions_skeleton; `rig` (motion.rigs.Rig) retargets .bvh and glTF output onto another
    skeleton."""
    from motiongan_jax import viz

    out = Path(out)
    B = gen.positions.shape[0]
    paths = check_output_path(out, count=B, rig=rig is not None)
    check_output_size(out, gen.positions.shape[1], B)
    suffix = out.suffix.lower()
    parents = list(layout.parents)
    try:
        if suffix == ".bvh" and rig is not None:
            for p, r in zip(paths, retargeted(gen, layout, fps, rig, log)):
                bvh.write_bvh(p, r.motion, precision=6)
        elif suffix in gltf.SUFFIXES:
            save_gltf(out, gen, titles, layout, fps, rig=rig, hierarchy=bvh_hierarchy, log=log)
        elif suffix == ".bvh":
            for i, p in enumerate(paths):
                save_bvh(p, gen.positions[i], layout, fps, bvh_units, log, bvh_hierarchy)
        elif suffix == ".npz":
            for i, p in enumerate(paths):
                save_npz(p, gen, i, layout, fps, titles[i],
                         None if z_per_motion is None else z_per_motion[i], log, bvh_hierarchy)
        elif suffix in (".gif", ".mp4"):
            viz.animate_motions(list(gen.positions), parents, list(titles), out, fps=fps,
                                curves=[gen.curve] * B, joint_names=layout.joint_names,
                                bodies=[preview_body(p, layout, fps) for p in gen.positions] if body else None)
        else:
            viz.pose_strips(list(gen.positions), parents, list(titles), out, curves=[gen.curve] * B)
    except RuntimeError as e:  # e.g. ffmpeg vanished between the check and the write
        raise limits.GenerateError(str(e)) from None
    except OSError as e:  # the temporary file is gone with the error (atomic writes)
        raise limits.GenerateError(f"cannot write {out}: {e.strerror or e}") from None
    return paths
