"""Euler angles and forward kinematics for BVH skeletons.

Conventions (BVH): angles in degrees; the rotation channels of a joint, read in file order
c0 c1 c2, give the local rotation R = R_c0(a0) @ R_c1(a1) @ R_c2(a2) (intrinsic order, equal to
scipy's Rotation.from_euler("C0C1C2", angles, degrees=True) with uppercase letters). Column
vectors, right-handed elementary rotations.

Forward kinematics: joint k has the local transform M_k = [R_k | t_k]; the world transform of
joint j is M_root @ ... @ M_j along its chain, and its world position is the translation part.
A joint's own rotation moves its children, not itself.

`euler_to_matrix` and `fk` are pure jnp (jit/vmap/grad-safe). `world_positions` runs the same
code with numpy in float64, so it is accurate without enabling jax_enable_x64.
"""

from __future__ import annotations

from typing import Any, Sequence

import jax.numpy as jnp
import numpy as np

from motiongan_jax.motion.bvh import Motion

_AXES = "XYZ"


def _check_order(order: str, n: int | None = None) -> str:
    if not isinstance(order, str) or not order or any(c not in _AXES for c in order):
        raise ValueError(f"rotation order must be uppercase letters from 'XYZ' (intrinsic), got {order!r}")
    if n is not None and n != len(order):
        raise ValueError(f"angles have {n} components but order {order!r} has {len(order)}")
    return order


def _elementary(xp: Any, axis: str, rad):
    """(..., 3, 3) rotation by `rad` about one axis."""
    c, s = xp.cos(rad), xp.sin(rad)
    one, zero = xp.ones_like(c), xp.zeros_like(c)
    if axis == "X":
        rows = ((one, zero, zero), (zero, c, -s), (zero, s, c))
    elif axis == "Y":
        rows = ((c, zero, s), (zero, one, zero), (-s, zero, c))
    else:
        rows = ((c, -s, zero), (s, c, zero), (zero, zero, one))
    return xp.stack([xp.stack(r, axis=-1) for r in rows], axis=-2)


def _euler(xp: Any, angles_deg, order: str):
    _check_order(order, angles_deg.shape[-1])
    rad = angles_deg * (np.pi / 180.0)
    out = _elementary(xp, order[0], rad[..., 0])
    for i in range(1, len(order)):
        out = out @ _elementary(xp, order[i], rad[..., i])
    return out


def euler_to_matrix(angles_deg, order: str):
    """Rotation matrices (..., 3, 3) from BVH Euler angles (..., 3) in degrees.

    `order` (static) is the intrinsic channel order, e.g. "ZXY" for
    "Zrotation Xrotation Yrotation": R = Rz(a0) @ Rx(a1) @ Ry(a2). Orders of 1 or 2 letters
    (joints with fewer rotation channels) are accepted with angles (..., len(order)).
    """
    return _euler(jnp, jnp.asarray(angles_deg), order)


def _check_parents(parents: Sequence[int], num_joints: int) -> tuple[int, ...]:
    parents = tuple(int(p) for p in parents)
    if len(parents) != num_joints:
        raise ValueError(f"{len(parents)} parents for {num_joints} joints")
    for j, p in enumerate(parents):
        if not (p == -1 or 0 <= p < j):
            raise ValueError(f"parents[{j}] = {p}: need -1 or 0 <= parent < {j}")
    return parents


def _fk(xp: Any, rot, trans, parents: tuple[int, ...], with_rotations: bool = False):
    J = rot.shape[-3]
    parents = _check_parents(parents, J)
    world_rot: list = [None] * J
    world_pos: list = [None] * J
    for j, p in enumerate(parents):
        if p < 0:
            world_rot[j] = rot[..., j, :, :]
            world_pos[j] = trans[..., j, :]
        else:
            world_pos[j] = world_pos[p] + (world_rot[p] @ trans[..., j, :, None])[..., 0]
            world_rot[j] = world_rot[p] @ rot[..., j, :, :]
    if with_rotations:
        return xp.stack(world_rot, axis=-3), xp.stack(world_pos, axis=-2)
    return xp.stack(world_pos, axis=-2)


def fk(local_rot, local_trans, parents: Sequence[int]):
    """World joint positions (..., J, 3) from local rotations (..., J, 3, 3) and translations (..., J, 3).

    `parents` is a static tuple (parents[j] < j, -1 for a root); close over it or mark it static
    under jax.jit. Pure jnp; leading axes (frames, batch) are vectorised.
    """
    return _fk(jnp, jnp.asarray(local_rot), jnp.asarray(local_trans), parents)


def local_transforms(motion: Motion) -> tuple[np.ndarray, np.ndarray]:
    """Per-frame local rotations (F, J, 3, 3) and translations (F, J, 3), float64, file units.

    Rotation: the joint's rotation channels composed in file order (identity when it has none,
    e.g. End Sites). Translation: the joint's position channels where it has them (a component
    without a channel keeps the OFFSET value), else its OFFSET.
    """
    sk = motion.skeleton
    values = np.asarray(motion.values, dtype=np.float64)
    F, J = values.shape[0], sk.num_joints
    trans = np.broadcast_to(np.asarray(sk.offsets, dtype=np.float64), (F, J, 3)).copy()
    rot = np.broadcast_to(np.eye(3), (F, J, 3, 3)).copy()
    by_order: dict[str, tuple[list[int], list[list[int]]]] = {}
    pos_joint, pos_axis, pos_col = [], [], []
    for j, (ch, sl) in enumerate(zip(sk.channels, sk.channel_slices())):
        cols = []
        for i, c in enumerate(ch):
            if c.endswith("position"):
                pos_joint.append(j)
                pos_axis.append("XYZ".index(c[0]))
                pos_col.append(sl.start + i)
            else:
                cols.append(sl.start + i)
        if cols:
            order = "".join(ch[i - sl.start][0] for i in cols)
            joints, columns = by_order.setdefault(order, ([], []))
            joints.append(j)
            columns.append(cols)
    trans[:, pos_joint, pos_axis] = values[:, pos_col]
    for order, (joints, columns) in by_order.items():
        rot[:, joints] = _euler(np, values[:, np.asarray(columns)], order)
    return rot, trans


def world_positions(motion: Motion) -> np.ndarray:
    """World positions (F, J, 3) float64 in file units for every joint, End Sites included."""
    rot, trans = local_transforms(motion)
    return _fk(np, rot, trans, motion.skeleton.parents)


def world_transforms(motion: Motion) -> tuple[np.ndarray, np.ndarray]:
    """World rotations (F, J, 3, 3) and positions (F, J, 3, file units) of every joint, float64:
    what skinning a body to the skeleton needs (a joint's world rotation turns the bones after it)."""
    rot, trans = local_transforms(motion)
    return _fk(np, rot, trans, motion.skeleton.parents, with_rotations=True)
