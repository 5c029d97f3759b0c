"""Positions -> BVH rotations (ik.py): Euler decomposition, round trips through FK and BVH text."""

import itertools

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from motiongan_jax.data import synthetic
from motiongan_jax.motion import bvh, ik, kinematics, representation


@pytest.fixture(scope="module")
def layout():
    """The embedded dataset's kept joints: 28 joints, several with 2 or 3 children."""
    return representation.layout_from_skeleton(synthetic.cmu_skeleton(), synthetic.UNITS_TO_M)


def _layout_motion(layout, F, seed):
    """Random poses by FK on the layout's own rest skeleton (every non-leaf joint rotates)."""
    rng = np.random.default_rng(seed)
    J = layout.num_joints
    has_child = {p for p in layout.parents if p >= 0}
    channels = tuple(("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation") if j == 0
                     else (("Zrotation", "Xrotation", "Yrotation") if j in has_child else ())
                     for j in range(J))
    sk = bvh.Skeleton(layout.joint_names, layout.parents, np.asarray(layout.rest_offsets_m), channels)
    cols = []
    for j, ch in enumerate(channels):
        for c in ch:
            cols.append(rng.normal(0, 1, F) if c.endswith("position") else rng.uniform(-180, 180, F))
    motion = bvh.Motion(sk, 1 / 15, np.stack(cols, -1))
    return kinematics.world_positions(motion)


def _angles(a, b):
    """Angle (rad) between unit vectors, accurate near 0."""
    return np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.sum(a * b, axis=-1))


def _lengths(pos, parents):
    return np.linalg.norm(pos[..., 1:, :] - pos[..., list(parents[1:]), :], axis=-1)


@pytest.mark.parametrize("order", ["".join(p) for p in itertools.permutations("XYZ")])
def test_matrix_to_euler_inverts_the_bvh_convention_even_at_gimbal_lock(order):
    rng = np.random.default_rng(0)
    ang = rng.uniform(-180, 180, (500, 3))
    ang[:20, 1] = 90.0
    ang[20:40, 1] = -90.0
    R = Rotation.from_euler(order, ang, degrees=True).as_matrix()  # uppercase: intrinsic
    np.testing.assert_allclose(np.asarray(kinematics.euler_to_matrix(ang[:5].astype(np.float32), order)),
                               R[:5], atol=1e-5)  # same convention as the reader's FK
    back = ik.matrix_to_euler(R, order)
    assert np.all(np.abs(back[:, 1]) <= 90 + 1e-9)
    np.testing.assert_allclose(Rotation.from_euler(order, back, degrees=True).as_matrix(), R, atol=1e-12)


def test_min_rotation_maps_a_to_b_including_opposite_and_equal_vectors():
    rng = np.random.default_rng(1)
    a = rng.normal(size=(300, 3))
    b = rng.normal(size=(300, 3))
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    b /= np.linalg.norm(b, axis=1, keepdims=True)
    b[:10] = -a[:10]
    b[10:20] = a[10:20]
    R = ik.min_rotation(a, b)
    np.testing.assert_allclose(np.einsum("nij,nj->ni", R, a), b, atol=1e-12)
    np.testing.assert_allclose(R @ np.swapaxes(R, 1, 2), np.broadcast_to(np.eye(3), R.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-12)
    np.testing.assert_allclose(R[10:20], np.broadcast_to(np.eye(3), (10, 3, 3)), atol=1e-12)
    # minimal: the rotation axis is perpendicular to a (no twist about a)
    rotvec = Rotation.from_matrix(R[20:]).as_rotvec()
    np.testing.assert_allclose(np.sum(rotvec * a[20:], axis=-1), 0.0, atol=1e-9)


def _fitted_bones(layout):
    """Bone indices (joint - 1) leaving a joint with several children (their parent's best fit)."""
    kids = np.bincount(np.asarray(layout.parents[1:]), minlength=layout.num_joints)
    return np.array([kids[layout.parents[j]] > 1 for j in range(1, layout.num_joints)])


def test_export_skeleton_source_keeps_the_training_hierarchy_exact_adds_branches(layout):
    src = ik.export_skeleton(layout.joint_names, layout.parents, layout.rest_offsets_m)
    sk = src.skeleton
    assert [sk.names[e] for e in src.kept_index] == list(layout.joint_names)
    # the source hierarchy: the layout's joints plus the source's zero-length thumb joints (their
    # End Sites are "LThumb_EndSite"), nothing else; each kept joint under its own layout parent
    source = synthetic.cmu_skeleton()
    extra = [n for n in sk.names if n not in layout.joint_names]
    assert sorted(extra) == ["LThumb", "RThumb"] and all(n in source.names for n in extra)
    assert not any("branch" in n for n in sk.names)
    for j in range(1, layout.num_joints):
        e = src.kept_index[j]
        above = sk.parents[e] if src.helper_index[j] < 0 else sk.parents[sk.parents[e]]
        assert above == src.kept_index[layout.parents[j]], layout.joint_names[j]
    ex = ik.export_skeleton(layout.joint_names, layout.parents, layout.rest_offsets_m, hierarchy="exact")
    sk = ex.skeleton
    assert [sk.names[e] for e in ex.kept_index] == list(layout.joint_names)
    extra = [n for n in sk.names if n not in layout.joint_names]
    # Hips (3 children), Spine1 (3), each hand (2)
    assert len(extra) == 3 + 3 + 2 + 2
    assert "LThumb" in extra and "RThumb" in extra  # a leaf's branch is named so the reader restores it
    assert sum(n.endswith("_branch") for n in extra) == 8
    for e, n in enumerate(sk.names):
        if n in extra:
            assert np.all(sk.offsets[e] == 0) and len(sk.channels[e]) == 3
    assert sk.channels[0][:3] == ik.ROOT_CHANNELS
    with pytest.raises(ik.IKError, match="hierarchy must be one of"):
        ik.export_skeleton(layout.joint_names, layout.parents, layout.rest_offsets_m, hierarchy="branched")


@pytest.mark.parametrize("hierarchy,units", [("source", "m"), ("source", "cm"), ("exact", "m"), ("exact", "cm")])
def test_rigid_poses_round_trip_through_bvh_text(layout, hierarchy, units, tmp_path):
    """FK on the rest skeleton -> IK -> BVH file -> read_bvh -> FK gives the positions back
    (a rigid pose is its own best fit, so the source hierarchy is exact here too)."""
    scale = {"m": 1.0, "cm": 100.0}[units]
    pos = _layout_motion(layout, 60, seed=2)
    motion = ik.positions_to_motion(pos, layout.joint_names, layout.parents, layout.rest_offsets_m,
                                    1 / 15, units_per_m=scale, hierarchy=hierarchy)
    ex = ik.export_skeleton(layout.joint_names, layout.parents, layout.rest_offsets_m, scale, hierarchy)
    assert np.abs(ik.layout_positions(motion, ex) - pos).max() < 1e-9  # in memory
    path = tmp_path / f"rigid_{units}.bvh"
    bvh.write_bvh(path, motion, precision=7)
    back = bvh.read_bvh(path)
    assert back.skeleton.names == ex.skeleton.names and back.skeleton.parents == ex.skeleton.parents
    got = kinematics.world_positions(back)[:, list(ex.kept_index)] / scale
    assert np.abs(got - pos).max() < 1e-5  # measured 5e-8 m (metres, 7 decimals), 2e-8 m (cm, 6)
    # reading the file with the usual rules recovers the layout: extra joints are zero-length
    again = representation.layout_from_skeleton(back.skeleton, 1.0 / scale)
    assert again.joint_names == layout.joint_names and again.parents == layout.parents
    np.testing.assert_allclose(again.rest_offsets_m, layout.rest_offsets_m, atol=1e-6)


def test_leaves_read_back_under_their_own_names(tmp_path):
    """Bandai's form: leaves are joints whose End Sites have zero length (dropped from the
    layout); a leaf "X_EndSite" under another parent gets its zero-length joint X back."""
    offsets = np.array([[0, 0, 0], [0, 90, 0], [0, 10, 0], [0, 0, 0], [9, -40, 0], [0, 0, 0],
                        [-9, -40, 0], [0, 0, 0], [0, 0, 3]], float)
    names = ("joint_Root", "Hips", "Head", "Head_EndSite", "Leg_L", "Leg_L_EndSite", "Leg_R", "Toe", "Toe_EndSite")
    parents = (-1, 0, 1, 2, 1, 4, 1, 6, 7)
    chans = tuple(() if n.endswith("_EndSite") else ("Xposition", "Yposition", "Zposition", "Zrotation",
                                                       "Xrotation", "Yrotation") for n in names)
    layout = representation.layout_from_skeleton(bvh.Skeleton(names, parents, offsets, chans), 0.01)
    assert layout.joint_names == ("Hips", "Head", "Leg_L", "Leg_R", "Toe_EndSite")  # Toe is zero-length
    rng = np.random.default_rng(7)
    pos = representation.rest_positions(layout)[None] + rng.normal(0, 0.02, (20, 5, 3))
    for hierarchy in ik.HIERARCHIES:
        motion = ik.positions_to_motion(pos, layout.joint_names, layout.parents, layout.rest_offsets_m,
                                        1 / 30, units_per_m=100.0, hierarchy=hierarchy)
        bvh.write_bvh(tmp_path / f"{hierarchy}.bvh", motion, precision=6)
        back = bvh.read_bvh(tmp_path / f"{hierarchy}.bvh")
        again = representation.layout_from_skeleton(back.skeleton, 0.01)
        assert again.joint_names == layout.joint_names and again.parents == layout.parents, hierarchy
        if hierarchy == "source":
            assert [n for n in back.skeleton.names if n not in layout.joint_names] == \
                ["Head_EndSite", "Leg_L_EndSite", "Toe"]  # the source's own names, nothing added


@pytest.mark.parametrize("hierarchy", ik.HIERARCHIES)
def test_non_rigid_poses_get_the_skeletons_lengths_and_exact_or_best_fit_directions(layout, hierarchy):
    rng = np.random.default_rng(3)
    rigid = _layout_motion(layout, 80, seed=4)
    pos = rigid + rng.normal(0, 0.03, rigid.shape)  # bones 3 cm off in every direction
    motion = ik.positions_to_motion(pos, layout.joint_names, layout.parents, layout.rest_offsets_m, 1 / 15,
                                    hierarchy=hierarchy)
    ex = ik.export_skeleton(layout.joint_names, layout.parents, layout.rest_offsets_m, hierarchy=hierarchy)
    got = ik.layout_positions(motion, ex)
    angle = _angles(ik.bone_directions(got, layout.parents), ik.bone_directions(pos, layout.parents))
    np.testing.assert_allclose(ik.bone_errors(pos, got, layout.parents), angle, atol=1e-12)
    np.testing.assert_allclose(_lengths(got, layout.parents),
                               np.broadcast_to(layout.bone_lengths_m, (80, layout.num_joints - 1)), atol=1e-9)
    np.testing.assert_allclose(got[:, 0], pos[:, 0], atol=1e-12)
    fitted = _fitted_bones(layout) & (np.asarray(ex.helper_index[1:]) < 0)
    if hierarchy == "exact":
        assert angle.max() < 1e-4  # measured 3e-11 rad (5e-8 rad through BVH text)
        return
    assert angle[:, ~fitted].max() < 1e-9  # every bone not leaving a branching joint is exact
    assert angle[:, fitted].mean() > 1e-3  # the 3 cm noise moves the others (~0.1 rad)
    # the best fit: each branching joint's world rotation minimises sum |R r_k - d_k|^2 over its
    # children (unit directions): no nearby rotation does better
    rest_dir = layout.rest_offsets_m / np.linalg.norm(layout.rest_offsets_m, axis=-1, keepdims=True).clip(1e-12)
    parents = np.asarray(layout.parents)
    checked = []
    for j in sorted(set(parents[1:][fitted])):
        kids = np.flatnonzero(parents == j)
        if any(ex.helper_index[c] >= 0 for c in kids):
            continue  # a hand: its thumb's restored joint makes the thumb exact (checked above)
        checked.append(layout.joint_names[j])
        d = pos[:, kids] - pos[:, j:j + 1]
        d /= np.linalg.norm(d, axis=-1, keepdims=True)
        # the fitted rotation, recovered from FK: it maps the rest directions to the exported ones
        out = got[:, kids] - got[:, j:j + 1]
        out /= np.linalg.norm(out, axis=-1, keepdims=True)
        R = ik.kabsch(rest_dir[kids], out)  # exact: the exported child directions are R r_k
        np.testing.assert_allclose(np.einsum("fij,kj->fki", R, rest_dir[kids]), out, atol=1e-9)
        cost = np.sum((np.einsum("fij,kj->fki", R, rest_dir[kids]) - d) ** 2, axis=(1, 2))
        for _ in range(20):
            Q = Rotation.from_rotvec(rng.normal(0, 0.01, (80, 3))).as_matrix() @ R
            worse = np.sum((np.einsum("fij,kj->fki", Q, rest_dir[kids]) - d) ** 2, axis=(1, 2))
            assert np.all(worse >= cost - 1e-12), layout.joint_names[j]
    assert checked == ["Hips", "Spine1"]


def test_degenerate_and_collinear_cases():
    # joint 1 has two children along the same rest direction (no plane): fallback is still exact
    names = ("root", "a", "b", "c", "b_EndSite", "c_EndSite")
    parents = (-1, 0, 1, 1, 2, 3)
    rest = np.array([[0, 0, 0], [0, 1, 0], [0, 1, 0], [0, 2, 0], [1, 0, 0], [1, 0, 0]], float)
    rng = np.random.default_rng(5)
    pos = rng.normal(size=(30, 6, 3))  # arbitrary, non-rigid
    pos[3, 1] = pos[3, 0]  # a zero-length posed bone keeps its rest direction
    ok = np.ones((30, 5), bool)
    ok[3, 0] = False
    for hierarchy in ik.HIERARCHIES:
        motion = ik.positions_to_motion(pos, names, parents, rest, 0.1, hierarchy=hierarchy)
        ex = ik.export_skeleton(names, parents, rest, hierarchy=hierarchy)
        got = ik.layout_positions(motion, ex)
        assert np.isfinite(got).all()
        angle = _angles(ik.bone_directions(got, parents), ik.bone_directions(pos, parents))
        if hierarchy == "exact":
            assert angle[ok].max() < 1e-9
        else:  # joint a points its first child b exactly; its second, c, goes where that puts it
            others = [0, 1, 3, 4]
            assert angle[:, others][ok[:, others]].max() < 1e-9
            assert angle[:, 2].max() > 0.1
    with pytest.raises(ik.IKError, match="non-finite"):
        bad = pos.copy()
        bad[4, 2, 0] = np.nan
        ik.positions_to_motion(bad, names, parents, rest, 0.1)
    with pytest.raises(ik.IKError, match="zero-length rest"):
        ik.export_skeleton(names, parents, np.zeros((6, 3)))
    with pytest.raises(ik.IKError, match="positions must be"):
        ik.positions_to_motion(pos[:, :4], names, parents, rest, 0.1)


def test_euler_channels_are_continuous_for_a_spinning_root(layout):
    """Heading through several full turns: unwrapped angles, no 360 degree jumps."""
    F = 200
    pos0 = _layout_motion(layout, 1, seed=6)[0] - _layout_motion(layout, 1, seed=6)[0, :1]
    heading = np.linspace(0, 4 * np.pi, F)
    R = Rotation.from_rotvec(heading[:, None] * np.array([0, 1, 0])).as_matrix()
    pos = np.einsum("fij,kj->fki", R, pos0)
    motion = ik.positions_to_motion(pos, layout.joint_names, layout.parents, layout.rest_offsets_m, 1 / 15)
    jumps = np.abs(np.diff(motion.values, axis=0))
    assert jumps.max() < 10.0  # degrees per frame (the heading moves 3.6)
