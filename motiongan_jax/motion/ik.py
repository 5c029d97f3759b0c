"""Joint positions -> BVH joint rotations ("inverse kinematics" by aligning bone directions).

The generator outputs joint *positions*; a BVH file needs a fixed skeleton (OFFSETs) and per-frame
joint rotations. `positions_to_motion` finds rotations whose forward kinematics put the bones
along the generated bone directions, with the skeleton's own bone lengths: a generated pose whose
bones are slightly too long or short is "made rigid" along each bone direction, outward from the
root; the root position is the generated one.

Two export skeletons (`HIERARCHIES`, `export_skeleton`); OFFSETs are the layout's rest offsets
(the rest pose of the training skeleton; identity rotations there) in both:

- "source" (default): the hierarchy of the skeleton the model was trained on, joint for joint
  (the layout's kept joints under their own parents; see "Leaves" for the End Sites). One
  rotation cannot point several child bones along arbitrary directions (a generated pose is not
  a rigid copy of the rest pose), so at a joint with several children (pelvis, chest, hands)
  the bones to its children are best fits, not exact (`bone_errors` measures them; README,
  "Generating walks", gives a trained model's figures); every other bone direction is exact.
- "exact": every child of a joint with several children hangs from its own zero-length *branch
  joint* (OFFSET 0 0 0, three rotation channels), like CMU's zero-length LHipJoint, LowerBack,
  LeftShoulder, ..., so every bone direction is exact (to float64 rounding, ~1e-12 rad before
  the text is written) at the price of extra joints the training skeleton does not have (named
  "<child>_branch"). Reading the file back and applying representation.layout_from_skeleton
  drops the zero-length joints again and recovers the layout's joints in the same order.

Leaves. A layout leaf named "<P>_EndSite" whose export parent is P is written as P's End Site
(bvh.read_bvh calls an End Site "<parent>_EndSite", so it reads back under its own name). One
named "<X>_EndSite" under another parent (CMU's thumbs: the source's zero-length LThumb was
dropped) gets the zero-length joint X back, the source's own, with the End Site under it; one
with another name (Bandai's Head, whose End Site has zero length) is written as a joint of that
name with a zero-length End Site, as in its source file. Both read back to the layout.

How the free rotation (twist) is chosen:
- a joint with one child: its local rotation is the *minimal* (swing-only) rotation taking the
  rest bone direction to the posed bone direction expressed in the parent's frame, i.e. zero
  twist about the bone relative to its parent (so forearm twist is inherited from the upper
  arm; nothing spins). If the posed direction is opposite to the rest one (a 180 degree swing,
  whose axis is undefined) a fixed axis perpendicular to the bone is used.
- a joint with several children: its world rotation is the best-fit rotation (Kabsch/SVD, unit
  directions) of the rest child directions onto the posed ones, so the twist follows the plane
  of the children (hips, shoulders); then a zero-length joint between it and a child (a branch
  joint, or a leaf's restored joint) adds the minimal rotation that makes that child's direction
  exact. For a pose that is a rigid rotation of the rest pose (e.g. FK of this skeleton) the
  best fit is exact and those rotations are the identity. If the rest child directions are
  collinear (no plane) the joint falls back to the single-child rule on its first child.
- a bone of (near) zero posed length has no direction: it keeps its rest direction relative to
  the parent (identity local rotation).

Euler angles (`matrix_to_euler`): intrinsic Tait-Bryan angles in the file's channel order,
R = R_c0(a0) R_c1(a1) R_c2(a2) (kinematics.euler_to_matrix's convention), computed with atan2
(exact at gimbal lock, where the first angle takes the whole rotation and the last is 0), then
unwrapped over time so that curves in an animation editor have no 360 degree jumps. The root
uses "YXZ" (heading first, so any heading is far from gimbal lock); other joints put the axis
most parallel to their bone (the twist axis, ~0 for a swing) in the middle of the order, which
keeps swings of up to 90 degrees away from gimbal lock.

Units and axes: positions in metres, Y up; `units_per_m` scales OFFSETs and the root position
(1 -> metres, what Blender's importer expects at its default scale 1.0; 100 -> centimetres).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from motiongan_jax.motion import bvh

ROOT_CHANNELS = ("Xposition", "Yposition", "Zposition")
ROOT_ORDER = "YXZ"
# order by the axis that goes in the middle (the bone's twist axis)
_ORDER_BY_MIDDLE = {0: "ZXY", 1: "ZYX", 2: "YZX"}
_EPS_LEN = 1e-9  # metres: a posed bone shorter than this has no direction
_ANTIPODAL = 1e-6  # 1 + cos(angle) below this: a 180 degree swing, handled separately
_COLLINEAR = 1e-3  # second singular value of the rest child directions below this: no plane


class IKError(ValueError):
    """Positions or a skeleton that cannot be exported; the message says why."""


# ---------------------------------------------------------------------------------------------
# Rotation helpers (numpy, float64, any leading shape)
# ---------------------------------------------------------------------------------------------


def _unit(v, eps=_EPS_LEN):
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.maximum(n, eps), n[..., 0]


def _perpendicular(a):
    """A unit vector perpendicular to each unit vector a (..., 3)."""
    # cross with the world axis least parallel to a
    axis = np.eye(3)[np.argmin(np.abs(a), axis=-1)]
    return _unit(np.cross(a, axis))[0]


def min_rotation(a, b):
    """The minimal rotation (..., 3, 3) taking unit vectors a to unit vectors b (..., 3).

    Rodrigues with axis a x b; for (near-)opposite vectors a 180 degree turn about a fixed axis
    perpendicular to a, followed by the (then small) minimal rotation to b.
    """
    a = np.asarray(a, np.float64)
    b = np.asarray(b, np.float64)
    a, b = np.broadcast_arrays(a, b)
    c = np.sum(a * b, axis=-1)
    flip = (1.0 + c) < _ANTIPODAL
    n = _perpendicular(a)
    # for flipped entries: first turn a -> -a by pi about n, then a small swing -a -> b
    a_eff = np.where(flip[..., None], -a, a)
    R_pi = 2.0 * n[..., :, None] * n[..., None, :] - np.eye(3)
    v = np.cross(a_eff, b)
    c_eff = np.sum(a_eff * b, axis=-1)
    K = _skew(v)
    R = np.eye(3) + K + (K @ K) / (1.0 + c_eff)[..., None, None]
    return np.where(flip[..., None, None], R @ R_pi, R)


def _skew(v):
    z = np.zeros_like(v[..., 0])
    return np.stack([np.stack([z, -v[..., 2], v[..., 1]], -1),
                     np.stack([v[..., 2], z, -v[..., 0]], -1),
                     np.stack([-v[..., 1], v[..., 0], z], -1)], -2)


def kabsch(rest_KxD, posed_xKx3):
    """Best-fit rotation(s) R with R @ rest_k ~ posed_k (unit directions, equal weights).
    rest: (K, 3); posed: (..., K, 3). Returns (..., 3, 3), proper (det +1)."""
    H = np.einsum("ki,...kj->...ij", rest_KxD, posed_xKx3)  # sum_k rest_k posed_k^T
    U, _, Vt = np.linalg.svd(H)
    V = np.swapaxes(Vt, -1, -2)
    d = np.sign(np.linalg.det(V @ np.swapaxes(U, -1, -2)))
    d = np.where(d == 0, 1.0, d)
    D = np.broadcast_to(np.eye(3), d.shape + (3, 3)).copy()
    D[..., 2, 2] = d
    return V @ D @ np.swapaxes(U, -1, -2)


_AXIS = {"X": 0, "Y": 1, "Z": 2}


def matrix_to_euler(R, order: str) -> np.ndarray:
    """Intrinsic Tait-Bryan angles in degrees (..., 3) with R = R_o0(a0) R_o1(a1) R_o2(a2).

    `order` is a permutation of "XYZ" (kinematics.euler_to_matrix's convention). The middle angle
    is in [-90, 90]; at gimbal lock the last angle is 0.
    """
    if sorted(order) != ["X", "Y", "Z"]:
        raise ValueError(f"order must be a permutation of 'XYZ', got {order!r}")
    i, j, k = (_AXIS[c] for c in order)
    s = 1.0 if (j - i) % 3 == 1 else -1.0  # cyclic (XYZ, YZX, ZXY) or not
    R = np.asarray(R, np.float64)
    cb = np.hypot(R[..., i, i], R[..., i, j])
    b = np.arctan2(s * R[..., i, k], cb)
    lock = cb < 1e-12
    a = np.where(lock, np.arctan2(s * R[..., k, j], R[..., j, j]),
                 np.arctan2(-s * R[..., j, k], R[..., k, k]))
    c = np.where(lock, 0.0, np.arctan2(-s * R[..., i, j], R[..., i, i]))
    return np.degrees(np.stack([a, b, c], axis=-1))


# ---------------------------------------------------------------------------------------------
# The export skeleton
# ---------------------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True, eq=False)
class ExportSkeleton:
    skeleton: bvh.Skeleton  # the BVH hierarchy, OFFSETs in file units
    kept_index: tuple[int, ...]  # layout joint -> index in the export skeleton
    units_per_m: float
    # layout joint -> the zero-length export joint between it and its layout parent (a branch
    # joint or a leaf's restored joint), -1 for none
    helper_index: tuple[int, ...] = ()
    hierarchy: str = "source"


HIERARCHIES = ("source", "exact")
_END = "_EndSite"


def _children(parents) -> list[list[int]]:
    out: list[list[int]] = [[] for _ in parents]
    for j, p in enumerate(parents):
        if p >= 0:
            out[p].append(j)
    return out


def _check_layout(joint_names, parents, rest_offsets_m):
    parents = tuple(int(p) for p in parents)
    J = len(parents)
    if len(joint_names) != J:
        raise IKError(f"{len(joint_names)} joint names but {J} parents")
    if J < 2 or parents[0] != -1 or any(not 0 <= p < j for j, p in enumerate(parents) if j > 0):
        raise IKError("parents must be -1 for joint 0 and satisfy 0 <= parents[j] < j otherwise")
    if rest_offsets_m is None:
        raise IKError("no rest offsets: the skeleton's rest pose is unknown")
    rest = np.asarray(rest_offsets_m, np.float64)
    if rest.shape != (J, 3) or not np.isfinite(rest).all():
        raise IKError(f"rest offsets must be a finite ({J}, 3) array, got shape {rest.shape}")
    short = [joint_names[j] for j in range(1, J) if np.linalg.norm(rest[j]) <= _EPS_LEN]
    if short:
        raise IKError(f"zero-length rest bones to {short}: drop those joints first")
    return parents, rest


def export_skeleton(joint_names, parents, rest_offsets_m, units_per_m: float = 1.0,
                    hierarchy: str = "source") -> ExportSkeleton:
    """The BVH skeleton of a row layout (see the module doc), OFFSETs in file units."""
    if hierarchy not in HIERARCHIES:
        raise IKError(f"hierarchy must be one of {', '.join(HIERARCHIES)}, got {hierarchy!r}")
    parents, rest = _check_layout(joint_names, parents, rest_offsets_m)
    children = _children(parents)
    names, par, offs, chans = [], [], [], []
    kept, helper = [-1] * len(parents), [-1] * len(parents)
    used = set(joint_names)

    def add(name, parent, offset, channels):
        names.append(name)
        par.append(parent)
        offs.append(offset)
        chans.append(channels)
        return len(names) - 1

    def order_for(direction) -> tuple[str, ...]:
        order = _ORDER_BY_MIDDLE[int(np.argmax(np.abs(direction)))]
        return tuple(f"{c}rotation" for c in order)

    def fresh(name: str) -> str:
        while name in used:
            name += "_"
        used.add(name)
        return name

    def visit(j: int, export_parent: int, offset) -> None:
        kids = children[j]
        name = joint_names[j]
        if j == 0:
            kept[j] = add(name, -1, offset, ROOT_CHANNELS + tuple(f"{c}rotation" for c in ROOT_ORDER))
        elif kids:
            channels = order_for(rest[kids[0]]) if len(kids) == 1 else tuple(f"{c}rotation" for c in "ZYX")
            kept[j] = add(name, export_parent, offset, channels)
        elif name == names[export_parent] + _END:  # reads back as "<parent>_EndSite"
            kept[j] = add(name, export_parent, offset, ())
        elif name.endswith(_END):  # the source's zero-length joint X of "X_EndSite", then the End Site
            h = add(fresh(name[: -len(_END)]), export_parent, np.zeros(3), order_for(rest[j]))
            helper[j] = h
            kept[j] = add(name, h, offset, ())
        else:  # a joint whose End Site had zero length in the source
            kept[j] = add(name, export_parent, offset, order_for(rest[j]))
            add(name + _END, kept[j], np.zeros(3), ())
        for c in kids:
            if hierarchy == "exact" and len(kids) > 1:
                child = joint_names[c]
                base = child[: -len(_END)] if child.endswith(_END) else f"{child}_branch"
                helper[c] = add(fresh(base), kept[j], np.zeros(3), order_for(rest[c]))
                visit(c, helper[c], rest[c] * units_per_m)
            else:
                visit(c, kept[j], rest[c] * units_per_m)

    visit(0, -1, np.zeros(3))
    sk = bvh.Skeleton(names=tuple(names), parents=tuple(par), offsets=np.asarray(offs, np.float64),
                      channels=tuple(chans))
    return ExportSkeleton(sk, tuple(kept), float(units_per_m), tuple(helper), hierarchy)


# ---------------------------------------------------------------------------------------------
# Solving
# ---------------------------------------------------------------------------------------------


def solve_rotations(positions_m, joint_names, parents, rest_offsets_m, units_per_m: float = 1.0,
                    hierarchy: str = "source"):
    """(export skeleton, local rotations (F, Je, 3, 3), root positions (F, 3) in file units).

    positions_m: (F, J, 3) world positions of the layout's joints in metres (Y up).
    Rotations are given for every export joint (identity for End Sites).
    """
    ex = export_skeleton(joint_names, parents, rest_offsets_m, units_per_m, hierarchy)
    parents, rest = _check_layout(joint_names, parents, rest_offsets_m)
    pos = np.asarray(positions_m, np.float64)
    J = len(parents)
    if pos.ndim != 3 or pos.shape[1:] != (J, 3):
        raise IKError(f"positions must be (frames, {J}, 3), got shape {pos.shape}")
    if len(pos) == 0:
        raise IKError("no frames")
    if not np.isfinite(pos).all():
        f = int(np.flatnonzero(~np.isfinite(pos).all(axis=(1, 2)))[0])
        raise IKError(f"non-finite joint position in frame {f}")
    F = len(pos)
    sk = ex.skeleton
    Je = sk.num_joints
    eye = np.broadcast_to(np.eye(3), (F, 3, 3))
    local = np.broadcast_to(np.eye(3), (F, Je, 3, 3)).copy()
    world = [None] * Je  # world rotation of each export joint, (F, 3, 3)
    children = _children(parents)
    rest_dir, _ = _unit(rest)

    def parent_world(e):
        p = sk.parents[e]
        return eye if p < 0 else world[p]

    def swing(e, target_world, rest_unit):
        """Local swing at export joint e pointing rest_unit (in e's frame) along target_world."""
        Gp = parent_world(e)
        d, n = _unit(target_world)
        d_local = np.einsum("fji,fj->fi", Gp, d)  # Gp^T d
        R = min_rotation(rest_unit, d_local)
        R = np.where((n > _EPS_LEN)[:, None, None], R, np.eye(3))
        local[:, e] = R
        world[e] = Gp @ R

    for j in range(J):  # kept joints in depth-first order: parents first
        e = ex.kept_index[j]
        kids = children[j]
        if not kids:
            world[e] = parent_world(e)
            continue
        targets = pos[:, kids] - pos[:, j:j + 1]  # (F, K, 3)
        if len(kids) == 1:
            swing(e, targets[:, 0], rest_dir[kids[0]])
        else:
            rest_k = rest_dir[kids]
            if np.linalg.svd(rest_k, compute_uv=False)[1] > _COLLINEAR:  # the children span a plane
                d, n = _unit(targets)
                # children without a direction do not vote (their rest direction is kept below)
                d = np.where((n > _EPS_LEN)[..., None], d, 0.0)
                G = kabsch(rest_k, d)
                local[:, e] = np.swapaxes(parent_world(e), -1, -2) @ G
                world[e] = G
            else:
                swing(e, targets[:, 0], rest_k[0])
        for k, c in enumerate(kids):
            if ex.helper_index[c] >= 0:  # the zero-length joint above c makes c's direction exact
                swing(ex.helper_index[c], targets[:, k], rest_dir[c])
    root = pos[:, 0] * units_per_m
    return ex, local, root


def positions_to_motion(positions_m, joint_names, parents, rest_offsets_m, frame_time: float, *,
                        units_per_m: float = 1.0, hierarchy: str = "source",
                        source: str = "<generated>") -> bvh.Motion:
    """A BVH Motion on the export skeleton whose FK follows `positions_m` (see the module doc).

    positions_m: (F, J, 3) metres, Y up; frame_time: seconds per frame; units_per_m: file units
    per metre (1 for metres, 100 for centimetres); hierarchy: one of HIERARCHIES.
    """
    if not (np.isfinite(frame_time) and frame_time > 0):
        raise IKError(f"frame time must be > 0 seconds, got {frame_time}")
    if not (np.isfinite(units_per_m) and units_per_m > 0):
        raise IKError(f"units_per_m must be > 0, got {units_per_m}")
    ex, local, root = solve_rotations(positions_m, joint_names, parents, rest_offsets_m, units_per_m, hierarchy)
    sk = ex.skeleton
    cols = []
    for e, ch in enumerate(sk.channels):
        if not ch:
            continue
        order = "".join(c[0] for c in ch if c.endswith("rotation"))
        angles = np.unwrap(matrix_to_euler(local[:, e], order), period=360.0, axis=0)
        rot = iter(angles.T)
        for c in ch:
            cols.append(root[:, "XYZ".index(c[0])] if c.endswith("position") else next(rot))
    values = np.stack(cols, axis=-1)
    return bvh.Motion(skeleton=sk, frame_time=float(frame_time), values=values, source=source)


def layout_positions(motion: bvh.Motion, ex: ExportSkeleton) -> np.ndarray:
    """FK of an exported motion at the layout's joints, (F, J, 3) metres."""
    from motiongan_jax.motion import kinematics

    return kinematics.world_positions(motion)[:, list(ex.kept_index)] / ex.units_per_m


def bone_directions(positions, parents) -> np.ndarray:
    """Unit bone vectors (..., J-1, 3), child minus parent, for joints 1..J-1."""
    pos = np.asarray(positions, np.float64)
    p = np.asarray(parents[1:])
    return _unit(pos[..., 1:, :] - pos[..., p, :])[0]


def bone_errors(positions_m, exported_m, parents) -> np.ndarray:
    """Angles (radians, (F, J-1)) between the generated bone directions and the exported ones
    (both (F, J, 3) layout positions); 0 where a generated bone has no direction."""
    a, b = bone_directions(positions_m, parents), bone_directions(exported_m, parents)
    angle = np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.sum(a * b, axis=-1))
    pos = np.asarray(positions_m, np.float64)
    n = np.linalg.norm(pos[..., 1:, :] - pos[..., list(parents[1:]), :], axis=-1)
    return np.where(n > _EPS_LEN, angle, 0.0)
