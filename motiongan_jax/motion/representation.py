"""The network's motion representation: which joints, in which row order, with which bones.

MotionGAN describes a pose as the root's world position plus every other kept joint's position
relative to the root (a translation only: the root's orientation is not removed), laid out
joint-major as x, y, z rows. The rules, applied to any skeleton read from a file:

1. The representation root is the first joint, walking down from the file root, that has more
   than one child (the pelvis). CMU's file root `Hips` branches at once; Bandai's `joint_Root`
   has the single child `Hips`, which becomes the root.
2. Below it, joints whose OFFSET has squared length <= 1e-8 are dropped (they coincide with their
   parent). What remains, in depth-first file order, are the kept joints. For CMU that is the
   paper's 28 joints (81 rows); for Bandai, Hips plus 20 joints (60 rows).
3. A kept joint's bone runs to its nearest kept ancestor. Since only zero-length joints are
   skipped, the bone's length is the norm of the joint's own OFFSET.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from motiongan_jax.motion.bvh import Skeleton

# Metres per CMU unit: the paper's unit of length (its data were CMU mocap).
CMU_UNIT_M = 0.056444
# The networks' unit of length: G and D see lengths divided by it and the curve, bone and foot
# losses are measured in it, so that the instance norms and the paper's loss weights see the
# scale they were made for (in metres the first norm's variances would be near its epsilon).
LENGTH_UNIT_M = CMU_UNIT_M
# Metres per file unit, by source.
UNITS_TO_M = {"cmu": CMU_UNIT_M, "paper": CMU_UNIT_M, "synthetic": CMU_UNIT_M, "bandai": 0.01, "bandai_session": 0.01}

_ZERO_LENGTH_SQ = 1e-8

# Units a BVH file is likely to be in, for files whose source is not known (a curve from a BVH):
# chosen by which makes the leg about 0.9 m long.
_COMMON_UNITS = {"CMU units": CMU_UNIT_M, "centimetres": 0.01, "inches": 0.0254, "metres": 1.0}


@dataclasses.dataclass(frozen=True, eq=False)
class RowLayout:
    joint_names: tuple[str, ...]  # kept joints, index 0 = root
    parents: tuple[int, ...]  # nearest kept ancestor, -1 for the root
    source_index: tuple[int, ...]  # kept joint -> index in the skeleton (End Sites included)
    bone_pairs: tuple[tuple[int, int], ...]  # (parent, child) in kept indices, one per non-root joint
    bone_lengths_m: np.ndarray  # (J - 1,) metres, in the order of bone_pairs
    # (J, 3) metres: each kept joint's rest-pose offset from its kept parent (row 0: zeros);
    # the skeleton a generated motion is exported on. None when unknown.
    rest_offsets_m: np.ndarray | None = None

    @property
    def num_joints(self) -> int:
        """Kept joints including the root."""
        return len(self.joint_names)

    @property
    def num_rel_joints(self) -> int:
        return len(self.joint_names) - 1

    @property
    def num_rows(self) -> int:
        return 3 * (len(self.joint_names) - 1)

    def signature(self) -> tuple:
        """What must match between a dataset and a checkpoint (lengths may differ slightly)."""
        return (self.joint_names, self.parents)


def guess_units_to_m(skeleton: Skeleton) -> float:
    """Metres per file unit, guessed from the rest-pose height of the skeleton's lowest point
    below the representation root (a leg, ~0.9 m for an adult)."""
    world_y = np.zeros(skeleton.num_joints)
    for j, p in enumerate(skeleton.parents):
        world_y[j] = (world_y[p] if p >= 0 else 0.0) + skeleton.offsets[j, 1]
    root = representation_root(skeleton)
    leg = world_y[root] - world_y.min()
    if leg <= 0:
        raise ValueError("cannot guess the units of a skeleton with nothing below its root")
    return min(_COMMON_UNITS.values(), key=lambda u: abs(np.log(leg * u / 0.9)))


def layout_from_parents(joint_names, parents, bone_lengths_m, rest_offsets_m=None) -> RowLayout:
    """A layout rebuilt from what a checkpoint stores (no skeleton needed)."""
    parents = tuple(int(p) for p in parents)
    return RowLayout(
        joint_names=tuple(joint_names),
        parents=parents,
        source_index=tuple(range(len(parents))),
        bone_pairs=tuple((parents[k], k) for k in range(1, len(parents))),
        bone_lengths_m=np.asarray(bone_lengths_m, np.float64),
        rest_offsets_m=None if rest_offsets_m is None else np.asarray(rest_offsets_m, np.float64),
    )


def representation_root(skeleton: Skeleton) -> int:
    children: dict[int, list[int]] = {j: [] for j in range(skeleton.num_joints)}
    for j, p in enumerate(skeleton.parents):
        if p >= 0:
            children[p].append(j)
    j = 0
    while len(children[j]) == 1:
        j = children[j][0]
    if not children[j]:
        raise ValueError(f"skeleton has no branching joint below {skeleton.names[0]!r}: cannot pick a root")
    return j


def layout_from_skeleton(skeleton: Skeleton, units_to_m: float) -> RowLayout:
    root = representation_root(skeleton)
    below_root = {root}
    kept = [root]
    kept_parent = {root: -1}
    nearest_kept = {root: root}
    for j in range(root + 1, skeleton.num_joints):
        p = skeleton.parents[j]
        if p not in below_root:
            continue
        below_root.add(j)
        if float(np.sum(np.square(skeleton.offsets[j]))) <= _ZERO_LENGTH_SQ:
            nearest_kept[j] = nearest_kept[p]
            continue
        kept_parent[j] = nearest_kept[p]
        nearest_kept[j] = j
        kept.append(j)
    position = {src: k for k, src in enumerate(kept)}
    parents = tuple(-1 if kept_parent[src] < 0 else position[kept_parent[src]] for src in kept)
    pairs = tuple((parents[k], k) for k in range(1, len(kept)))
    lengths = np.array([np.linalg.norm(skeleton.offsets[kept[k]]) * units_to_m for k in range(1, len(kept))])
    rest = np.zeros((len(kept), 3))
    for k in range(1, len(kept)):
        # skipped joints between a kept joint and its kept parent have zero offsets
        rest[k] = skeleton.offsets[kept[k]] * units_to_m
    return RowLayout(
        joint_names=tuple(skeleton.names[s] for s in kept),
        parents=parents,
        source_index=tuple(kept),
        bone_pairs=pairs,
        bone_lengths_m=lengths,
        rest_offsets_m=rest,
    )


def rest_positions(layout: RowLayout) -> np.ndarray:
    """(J, 3) metres: every kept joint's rest-pose position relative to the root."""
    if layout.rest_offsets_m is None:
        raise ValueError("the layout has no rest offsets")
    off = np.asarray(layout.rest_offsets_m, np.float64)
    pos = np.zeros_like(off)
    for k in range(1, len(off)):
        pos[k] = pos[layout.parents[k]] + off[k]
    return pos


def to_rows(world_m_FxJx3: np.ndarray, layout: RowLayout) -> tuple[np.ndarray, np.ndarray]:
    """World positions of every skeleton joint -> (root_Fx3, pose_FxR)."""
    kept_FxKx3 = world_m_FxJx3[:, list(layout.source_index)]
    root_Fx3 = kept_FxKx3[:, 0]
    rel_FxKx3 = kept_FxKx3[:, 1:] - root_Fx3[:, None]
    return root_Fx3, rel_FxKx3.reshape(len(root_Fx3), -1)


def from_rows(root_Fx3, pose_FxR, layout: RowLayout):
    """(root, rows) -> world positions of the kept joints, (F, J, 3). Works for numpy and jnp."""
    rel = pose_FxR.reshape(pose_FxR.shape[:-1] + (layout.num_rel_joints, 3))
    return _concat(root_Fx3[..., None, :], rel + root_Fx3[..., None, :])


def _concat(a, b):
    xp = np if isinstance(a, np.ndarray) and isinstance(b, np.ndarray) else _xp(None)
    return xp.concatenate([a, b], axis=-2)


def _xp(x):
    if isinstance(x, np.ndarray):
        return np
    import jax.numpy as jnp

    return jnp


def joint_bone_lengths(joints_xJx3, bone_pairs):
    """Lengths (..., len(bone_pairs)) of the (parent, child) joint pairs of positions (..., J, 3):
    numpy in, numpy out; jnp (traced included) in, jnp out. A zero-length bone is 0 with a finite
    gradient (sqrt's gradient at 0 is infinite, and a generated bone can collapse)."""
    xp = _xp(joints_xJx3)
    pairs = np.asarray(bone_pairs, dtype=np.int32).reshape(-1, 2)
    diff = joints_xJx3[..., pairs[:, 0], :] - joints_xJx3[..., pairs[:, 1], :]
    sq = xp.sum(xp.square(diff), axis=-1)
    return xp.where(sq > 0, xp.sqrt(xp.where(sq > 0, sq, 1.0)), 0.0)


def bone_lengths(pose_xR, bone_pairs):
    """Bone lengths (..., len(bone_pairs)) of root-relative rows (..., R) (kept joint 0 is the root
    at the origin, joint k >= 1 is rows 3(k-1) .. 3(k-1)+2); `bone_pairs` as layout.bone_pairs.
    numpy or jnp, as `joint_bone_lengths`."""
    xp = _xp(pose_xR)
    rel = pose_xR.reshape(pose_xR.shape[:-1] + (pose_xR.shape[-1] // 3, 3))
    return joint_bone_lengths(xp.concatenate([xp.zeros_like(rel[..., :1, :]), rel], axis=-2), bone_pairs)


# Skeleton semantics: which joints are the feet and the hips


def foot_joints(layout) -> tuple[int, int]:
    """The two contact joints: the toe joints by name (not end sites), else the lowest rest-pose
    joint on each side of the body."""
    names = [n.lower() for n in layout.joint_names]
    toes = [i for i, n in enumerate(names) if "toe" in n and "end" not in n]
    if len(toes) == 2:
        return toes[0], toes[1]
    if layout.rest_offsets_m is None:
        raise ValueError(f"cannot find the feet of joints {layout.joint_names}")
    pos = rest_positions(layout)
    left = [i for i in range(len(pos)) if pos[i, 0] > 0]
    right = [i for i in range(len(pos)) if pos[i, 0] < 0]
    if not left or not right:
        raise ValueError(f"cannot find two feet in joints {layout.joint_names}")
    return min(left, key=lambda i: pos[i, 1]), min(right, key=lambda i: pos[i, 1])


def joint_side(name: str) -> str | None:
    """'left', 'right' or None from a joint's name (LeftUpLeg, LThumb, UpperLeg_L, l_knee, Foot.R)."""
    n = name.lower()
    if (n.startswith(("left", "l_")) or n.endswith(("_l", ".l"))
            or (len(name) > 1 and name[0] == "L" and name[1].isupper())):
        return "left"
    if (n.startswith(("right", "r_")) or n.endswith(("_r", ".r"))
            or (len(name) > 1 and name[0] == "R" and name[1].isupper())):
        return "right"
    return None


def facing_joints(layout) -> tuple[int, int] | None:
    """(left hip, right hip) for metrics.facing_error_deg: the root's children named left and
    right (LeftUpLeg / RightUpLeg, UpperLeg_L / UpperLeg_R), else the two furthest apart along x
    in the rest pose, left at +x (BVH's convention: a body facing +z has its left at +x). None
    when neither finds two (facing is then not reported)."""
    children = [k for k, p in enumerate(layout.parents) if p == 0]
    named = {side: [k for k in children if joint_side(layout.joint_names[k]) == side] for side in ("left", "right")}
    if len(named["left"]) == 1 and len(named["right"]) == 1:
        return named["left"][0], named["right"][0]
    if layout.rest_offsets_m is None or len(children) < 2:
        return None
    pos = rest_positions(layout)
    return max(children, key=lambda k: pos[k, 0]), min(children, key=lambda k: pos[k, 0])
