"""Euler angles and forward kinematics, checked against scipy and hand-built homogeneous chains."""

from __future__ import annotations

import dataclasses
import itertools

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from motiongan_jax.motion import bvh
from motiongan_jax.motion.kinematics import (
    euler_to_matrix,
    fk,
    local_transforms,
    world_positions,
)

ORDERS = ["".join(p) for p in itertools.permutations("XYZ")]


# ---------------------------------------------------------------------------------------------
# An independent FK: 4x4 matrices from scipy, multiplied along each joint's chain from the root.
# ---------------------------------------------------------------------------------------------

def reference_local_matrices(motion: bvh.Motion) -> np.ndarray:
    """(F, J, 4, 4) local transforms straight from the channel names and values."""
    sk, vals = motion.skeleton, motion.values
    F = vals.shape[0]
    out = np.zeros((F, sk.num_joints, 4, 4))
    out[..., 3, 3] = 1.0
    col = 0
    for j, chans in enumerate(sk.channels):
        t = np.tile(sk.offsets[j], (F, 1))
        letters, angle_cols = "", []
        for c in chans:
            if c.endswith("position"):
                t[:, "XYZ".index(c[0])] = vals[:, col]
            else:
                letters += c[0]
                angle_cols.append(col)
            col += 1
        if letters:
            R = Rotation.from_euler(letters, vals[:, angle_cols], degrees=True).as_matrix()
        else:
            R = np.tile(np.eye(3), (F, 1, 1))
        out[:, j, :3, :3] = R
        out[:, j, :3, 3] = t
    assert col == vals.shape[1]
    return out


def reference_world(local44: np.ndarray, parents) -> np.ndarray:
    F, J = local44.shape[:2]
    out = np.zeros((F, J, 3))
    for j in range(J):
        chain, k = [], j
        while k >= 0:
            chain.append(k)
            k = parents[k]
        M = np.tile(np.eye(4), (F, 1, 1))
        for k in reversed(chain):  # root first
            M = M @ local44[:, k]
        out[:, j] = M[:, :3, 3]
    return out


def random_motion(rng, num_joints=12, frames=7) -> bvh.Motion:
    """Random tree in depth-first order with random channel subsets and orders per joint."""
    parents = [-1]
    stack = [0]
    for j in range(1, num_joints):
        del stack[rng.integers(1, len(stack) + 1):]  # pop a random number of levels, keep the root
        parents.append(stack[-1])
        stack.append(j)
    names = tuple(f"j{j}" for j in range(num_joints))
    channels = []
    for j in range(num_joints):
        if j == 0:
            chans = list(bvh.CHANNEL_NAMES)
        else:
            chans = list(rng.choice(bvh.CHANNEL_NAMES, size=rng.integers(1, 7), replace=False))
        rng.shuffle(chans)
        channels.append(tuple(str(c) for c in chans))
    sk = bvh.Skeleton(names=names, parents=tuple(parents), offsets=rng.normal(size=(num_joints, 3)) * 5,
                      channels=tuple(channels))
    values = np.empty((frames, sk.num_channels))
    col = 0
    for chans in channels:
        for c in chans:
            values[:, col] = rng.uniform(-180, 180, frames) if c.endswith("rotation") else rng.normal(0, 5, frames)
            col += 1
    return bvh.Motion(skeleton=sk, frame_time=0.01, values=values)


def scale_of(x) -> float:
    return float(np.max(np.abs(x))) + 1.0


# ---------------------------------------------------------------------------------------------
# euler_to_matrix
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("order", ORDERS)
def test_euler_matches_scipy_intrinsic(order):
    angles = np.random.default_rng(hash(order) % 2**32).uniform(-360, 360, size=(64, 3))
    got = euler_to_matrix(jnp.asarray(angles, jnp.float32), order)
    chex.assert_shape(got, (64, 3, 3))
    want = Rotation.from_euler(order, angles, degrees=True).as_matrix()
    np.testing.assert_allclose(np.asarray(got), want, atol=2e-6)


@pytest.mark.parametrize("order", ["Z", "XY", "ZXZ"])
def test_euler_other_lengths(order):
    angles = np.random.default_rng(1).uniform(-180, 180, size=(2, 5, len(order)))
    got = euler_to_matrix(angles, order)
    chex.assert_shape(got, (2, 5, 3, 3))
    want = Rotation.from_euler(order, angles.reshape(-1, len(order)), degrees=True).as_matrix()
    np.testing.assert_allclose(np.asarray(got).reshape(-1, 3, 3), want, atol=2e-6)


def test_euler_elementary_matrices():
    # A positive angle about Z takes +X to +Y (right-handed), about X takes +Y to +Z, about Y takes +Z to +X.
    ex, ey, ez = np.eye(3)
    np.testing.assert_allclose(euler_to_matrix(jnp.array([90.0, 0, 0]), "ZXY") @ ex, ey, atol=1e-6)
    np.testing.assert_allclose(euler_to_matrix(jnp.array([90.0, 0, 0]), "XYZ") @ ey, ez, atol=1e-6)
    np.testing.assert_allclose(euler_to_matrix(jnp.array([90.0, 0, 0]), "YZX") @ ez, ex, atol=1e-6)
    # Channel order matters: Rz(90) @ Rx(90) applied to +Y: Rx takes it to +Z, Rz leaves +Z.
    np.testing.assert_allclose(euler_to_matrix(jnp.array([90.0, 90.0, 0]), "ZXY") @ ey, ez, atol=1e-6)


@pytest.mark.parametrize("bad", ["zyx", "ZYW", "", "ZYXZ "])
def test_euler_rejects_bad_orders(bad):
    with pytest.raises(ValueError):
        euler_to_matrix(jnp.zeros((1, 3)), bad)


def test_euler_under_jit_and_grad():
    f = jax.jit(lambda a: euler_to_matrix(a, "ZYX"))
    a = jnp.array([[10.0, 20.0, 30.0]])
    np.testing.assert_allclose(np.asarray(f(a)), np.asarray(euler_to_matrix(a, "ZYX")), atol=1e-7)
    g = jax.grad(lambda a: euler_to_matrix(a, "ZYX")[0, 0, 1])(a)
    assert np.isfinite(np.asarray(g)).all() and np.abs(np.asarray(g)).max() > 0


# ---------------------------------------------------------------------------------------------
# fk / world_positions against the reference
# ---------------------------------------------------------------------------------------------

def test_random_skeleton_matches_reference():
    rng = np.random.default_rng(0)
    for _ in range(3):
        m = random_motion(rng)
        want = reference_world(reference_local_matrices(m), m.skeleton.parents)
        got = world_positions(m)
        chex.assert_shape(got, (7, 12, 3))
        assert got.dtype == np.float64
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-9 * scale_of(want))
        rot, trans = local_transforms(m)
        chex.assert_shape([rot, trans], [(7, 12, 3, 3), (7, 12, 3)])
        got32 = fk(jnp.asarray(rot, jnp.float32), jnp.asarray(trans, jnp.float32), m.skeleton.parents)
        chex.assert_shape(got32, (7, 12, 3))
        np.testing.assert_allclose(np.asarray(got32), want, rtol=0, atol=1e-4 * scale_of(want))


def test_local_transforms_follow_the_channels():
    m = bvh.parse_bvh(
        "HIERARCHY\nROOT r\n{\n OFFSET 1 2 3\n CHANNELS 3 Xrotation Yposition Zrotation\n"
        " JOINT c\n {\n  OFFSET 4 5 6\n  CHANNELS 1 Yrotation\n  End Site\n  {\n   OFFSET 7 8 9\n  }\n }\n}\n"
        "MOTION\nFrames: 1\nFrame Time: 0.5\n30 -2 40 50\n")
    rot, trans = local_transforms(m)
    np.testing.assert_allclose(trans[0], [[1, -2, 3], [4, 5, 6], [7, 8, 9]])  # Y from the channel
    np.testing.assert_allclose(rot[0, 0], Rotation.from_euler("XZ", [30, 40], degrees=True).as_matrix(),
                               atol=1e-12)
    np.testing.assert_allclose(rot[0, 1], Rotation.from_euler("Y", 50, degrees=True).as_matrix(), atol=1e-12)
    np.testing.assert_allclose(rot[0, 2], np.eye(3))


@pytest.fixture(scope="module")
def cmu(shared_data):
    return bvh.read_bvh(shared_data / "cmu" / "CMU_standard.bvh")


@pytest.fixture(scope="module")
def bandai_walk(shared_data):
    return bvh.read_bvh(shared_data / "bandai" / "dataset-2" / "dataset-2_walk_active_001.bvh")


@pytest.mark.parametrize("which", ["CMU_standard", "131_01", "bandai_walk", "bandai_turn"])
def test_real_files_match_reference(shared_data, which):
    path = {
        "CMU_standard": "cmu/CMU_standard.bvh",
        "131_01": "cmu/131_01.bvh",
        "bandai_walk": "bandai/dataset-2/dataset-2_walk_active_001.bvh",
        "bandai_turn": "bandai/dataset-2/dataset-2_walk-turn-right_feminine_001.bvh",
    }[which]
    m = bvh.read_bvh(shared_data / path)
    m = dataclasses.replace(m, values=m.values[::7])  # a subset of frames keeps it quick
    want = reference_world(reference_local_matrices(m), m.skeleton.parents)
    got = world_positions(m)
    chex.assert_shape(got, (m.num_frames, m.skeleton.num_joints, 3))
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-4 * scale_of(want))
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-9 * scale_of(want))  # float64 path
    # The jnp fk (float32) agrees with the float64 path.
    rot, trans = local_transforms(m)
    got32 = fk(rot.astype(np.float32), trans.astype(np.float32), m.skeleton.parents)
    np.testing.assert_allclose(np.asarray(got32), got, rtol=0, atol=1e-4 * scale_of(want))


def test_fk_float64_equals_world_positions(cmu):
    rot, trans = local_transforms(cmu)
    with jax.enable_x64(True):
        got = fk(jnp.asarray(rot), jnp.asarray(trans), cmu.skeleton.parents)
        assert got.dtype == jnp.float64
        np.testing.assert_allclose(np.asarray(got), world_positions(cmu), rtol=0, atol=1e-10)


# ---------------------------------------------------------------------------------------------
# Invariants
# ---------------------------------------------------------------------------------------------

def summed_offsets(sk: bvh.Skeleton) -> np.ndarray:
    """Rest pose: each joint at the sum of the OFFSETs below the root along its chain."""
    out = np.zeros((sk.num_joints, 3))
    for j in range(sk.num_joints):
        k = j
        while sk.parents[k] >= 0:
            out[j] += sk.offsets[k]
            k = sk.parents[k]
    return out


@pytest.mark.parametrize("which", ["cmu", "bandai_walk"])
def test_rest_pose_is_summed_offsets(request, which):
    m = request.getfixturevalue(which)
    sk = m.skeleton
    values = np.zeros((2, sk.num_channels))
    for j, (chans, sl) in enumerate(zip(sk.channels, sk.channel_slices())):
        for i, c in enumerate(chans):
            if c.endswith("position") and j > 0:  # Bandai: non-root position channels = OFFSET
                values[:, sl.start + i] = sk.offsets[j, "XYZ".index(c[0])]
    rest = world_positions(dataclasses.replace(m, values=values))
    np.testing.assert_allclose(rest[0], summed_offsets(sk), atol=1e-9)
    np.testing.assert_allclose(rest[1], rest[0])


@pytest.mark.parametrize("which", ["cmu", "bandai_walk"])
def test_root_yaw_rotates_everything_about_the_root(request, which):
    m = request.getfixturevalue(which)
    m = dataclasses.replace(m, values=m.values[::10].copy())
    sk = m.skeleton
    sl = sk.channel_slices()[0]
    rot_cols = [sl.start + i for i, c in enumerate(sk.channels[0]) if c.endswith("rotation")]
    order = sk.rotation_order(0)
    yaw = Rotation.from_euler("Y", 37.0, degrees=True)
    old = Rotation.from_euler(order, m.values[:, rot_cols], degrees=True)
    values = m.values.copy()
    values[:, rot_cols] = (yaw * old).as_euler(order, degrees=True)
    before = world_positions(m)
    after = world_positions(dataclasses.replace(m, values=values))
    root = before[:, :1]
    want = root + (before - root) @ yaw.as_matrix().T
    np.testing.assert_allclose(after, want, atol=1e-8 * scale_of(before))
    np.testing.assert_allclose(after[..., 1], before[..., 1], atol=1e-8 * scale_of(before))  # heights kept


def test_bandai_root_stays_and_hips_walk(shared_data, bandai_walk):
    for name in ["dataset-2_walk_active_001.bvh", "dataset-2_walk-turn-left_normal_002.bvh"]:
        w = world_positions(bvh.read_bvh(shared_data / "bandai" / "dataset-2" / name))
        np.testing.assert_allclose(w[:, 0], 0.0, atol=1e-9)  # joint_Root
    w = world_positions(bandai_walk)
    hips = w[:, bandai_walk.skeleton.names.index("Hips")]
    travel_cm = np.linalg.norm(hips[-1, [0, 2]] - hips[0, [0, 2]])
    assert 700 < travel_cm < 1300  # the straight walk is about 9.8 m
    assert 70 < hips[:, 1].mean() < 110  # hip height in cm
    head = w[:, bandai_walk.skeleton.names.index("Head")]
    assert (head[:, 1] > hips[:, 1] + 30).all()  # upright


def test_cmu_frame0_is_a_t_pose(cmu):
    w = world_positions(cmu)[0]
    n = cmu.skeleton.names.index
    for side in ("Left", "Right"):
        arm, hand = w[n(f"{side}Arm")], w[n(f"{side}Hand")]
        d = hand - arm
        assert abs(d[1]) < 0.2 * np.linalg.norm(d)  # the arm is horizontal
    head, foot = w[n("Head")], w[n("LeftFoot")]
    assert head[1] - foot[1] > 20  # upright, in CMU units (~0.056 m)


# ---------------------------------------------------------------------------------------------
# jit / vmap / grad
# ---------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def small_case():
    rng = np.random.default_rng(3)
    m = random_motion(rng, num_joints=6, frames=4)
    rot, trans = local_transforms(m)
    return m.skeleton.parents, jnp.asarray(rot, jnp.float32), jnp.asarray(trans, jnp.float32)


def test_fk_jit(small_case):
    parents, rot, trans = small_case
    eager = fk(rot, trans, parents)
    jitted = jax.jit(fk, static_argnums=2)(rot, trans, parents)
    closed = jax.jit(lambda r, t: fk(r, t, parents))(rot, trans)
    chex.assert_trees_all_close(jitted, eager, atol=1e-5)
    chex.assert_trees_all_close(closed, eager, atol=1e-5)


def test_fk_vmap(small_case):
    parents, rot, trans = small_case
    rot_b = jnp.stack([rot, rot[::-1], rot[:, ::1]])
    trans_b = jnp.stack([trans, trans * 2, trans[::-1]])
    got = jax.vmap(lambda r, t: fk(r, t, parents))(rot_b, trans_b)
    chex.assert_shape(got, (3, 4, 6, 3))
    for b in range(3):
        chex.assert_trees_all_close(got[b], fk(rot_b[b], trans_b[b], parents), atol=1e-5)


def test_fk_grad_matches_finite_differences():
    rng = np.random.default_rng(5)
    parents = (-1, 0, 1, 2, 1, 4)
    offsets = rng.normal(size=(6, 3))
    weights = rng.normal(size=(2, 6, 3))

    def loss(angles):
        rot = euler_to_matrix(angles, "ZXY")
        trans = jnp.broadcast_to(jnp.asarray(offsets, angles.dtype), (2, 6, 3))
        return jnp.sum(fk(rot, trans, parents) * weights)

    angles64 = rng.uniform(-90, 90, size=(2, 6, 3))
    grad32 = jax.grad(loss)(jnp.asarray(angles64, jnp.float32))  # the default precision works too
    assert grad32.dtype == jnp.float32 and np.isfinite(np.asarray(grad32)).all()

    with jax.enable_x64(True):  # locally, for finite differences accurate enough to compare
        angles = jnp.asarray(angles64)
        grad = np.asarray(jax.jit(jax.grad(loss))(angles))
        assert np.isfinite(grad).all()
        eps = 1e-4
        steps = (eps * np.eye(grad.size)).reshape((grad.size,) + grad.shape)  # one per coordinate
        batched = jax.jit(jax.vmap(loss))
        numeric = np.asarray(batched(angles + steps) - batched(angles - steps)).reshape(grad.shape) / (2 * eps)
        np.testing.assert_allclose(grad, numeric, rtol=1e-6, atol=1e-9)
        # The last joint of each chain has no children: its own rotation does not move anything.
        np.testing.assert_array_equal(grad[:, [3, 5]], 0.0)


def test_fk_rejects_bad_parents():
    with pytest.raises(ValueError):
        fk(jnp.zeros((1, 3, 3, 3)), jnp.zeros((1, 3, 3)), (-1, 2, 0))
    with pytest.raises(ValueError):
        fk(jnp.zeros((1, 3, 3, 3)), jnp.zeros((1, 3, 3)), (-1, 0))
