import numpy as np
import pytest
from expected import PAPER_BONES, PAPER_JOINTS

from motiongan_jax.motion import bvh, kinematics
from motiongan_jax.motion.representation import (
    bone_lengths,
    from_rows,
    layout_from_skeleton,
    representation_root,
    to_rows,
)

CMU_UNIT = 0.056444



@pytest.fixture(scope="module")
def cmu(shared_data):
    return bvh.read_bvh(shared_data / "cmu" / "CMU_standard.bvh")


@pytest.fixture(scope="module")
def bandai(shared_data):
    return bvh.read_bvh(shared_data / "bandai" / "dataset-2" / "dataset-2_walk_normal_001.bvh")


def test_cmu_layout_is_the_papers(cmu):
    layout = layout_from_skeleton(cmu.skeleton, CMU_UNIT)
    assert layout.joint_names == PAPER_JOINTS
    assert layout.num_rows == 81
    assert set(layout.bone_pairs) == PAPER_BONES
    assert len(layout.bone_pairs) == 27


def test_bandai_layout_roots_at_hips(bandai):
    sk = bandai.skeleton
    assert sk.names[representation_root(sk)] == "Hips"
    layout = layout_from_skeleton(sk, 0.01)
    assert layout.joint_names[0] == "Hips"
    assert layout.num_rel_joints == 20
    assert layout.num_rows == 60
    assert "joint_Root" not in layout.joint_names
    assert not any(n.endswith("_EndSite") for n in layout.joint_names)  # zero-length End Sites


def test_rows_roundtrip_and_bone_lengths_from_fk(cmu, bandai):
    for motion, unit in ((cmu, CMU_UNIT), (bandai, 0.01)):
        layout = layout_from_skeleton(motion.skeleton, unit)
        world = kinematics.world_positions(motion) * unit
        root, pose = to_rows(world, layout)
        assert root.shape == (motion.num_frames, 3)
        assert pose.shape == (motion.num_frames, layout.num_rows)
        back = from_rows(root, pose, layout)
        np.testing.assert_allclose(back, world[:, list(layout.source_index)], atol=1e-9)
        # Rigid bones: FK rows have the skeleton's bone lengths in every frame.
        lengths = bone_lengths(pose, layout.bone_pairs)
        np.testing.assert_allclose(lengths, np.broadcast_to(layout.bone_lengths_m, lengths.shape), atol=1e-6)


def test_hand_built_skeleton():
    # root -> a (zero length) -> b ; root -> c ; b -> End Site
    sk = bvh.Skeleton(
        names=("R", "a", "b", "b_EndSite", "c"),
        parents=(-1, 0, 1, 2, 0),
        offsets=np.array([[0, 0, 0], [0, 0, 0], [0, 2.0, 0], [0, 0, 3.0], [4.0, 0, 0]]),
        channels=(("Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation"),
                  ("Zrotation", "Yrotation", "Xrotation"), ("Zrotation", "Yrotation", "Xrotation"), (),
                  ("Zrotation", "Yrotation", "Xrotation")),
    )
    layout = layout_from_skeleton(sk, 0.5)
    assert layout.joint_names == ("R", "b", "b_EndSite", "c")
    assert layout.parents == (-1, 0, 1, 0)
    assert layout.bone_pairs == ((0, 1), (1, 2), (0, 3))
    np.testing.assert_allclose(layout.bone_lengths_m, [1.0, 1.5, 2.0])


def test_units_are_guessed_from_the_leg(cmu, bandai):
    from motiongan_jax.data import synthetic
    from motiongan_jax.motion.representation import guess_units_to_m

    assert guess_units_to_m(cmu.skeleton) == CMU_UNIT
    assert guess_units_to_m(synthetic.cmu_skeleton()) == CMU_UNIT
    assert guess_units_to_m(bandai.skeleton) == 0.01
    metres = bvh.Skeleton(bandai.skeleton.names, bandai.skeleton.parents, bandai.skeleton.offsets * 0.01,
                          bandai.skeleton.channels)
    assert guess_units_to_m(metres) == 1.0


def test_curve_from_bvh_is_the_root_floor_path(shared_data):
    from motiongan_jax.data import curves

    path = shared_data / "bandai" / "dataset-2" / "dataset-2_walk_normal_001.bvh"
    motion = bvh.read_bvh(path)
    hips = motion.skeleton.names.index("Hips")
    expected = kinematics.world_positions(motion)[:, hips][:, [0, 2]] * 0.01
    np.testing.assert_allclose(curves.curve_from_bvh(path), expected, atol=1e-9)


def test_rest_offsets_rebuild_the_rest_pose(cmu):
    layout = layout_from_skeleton(cmu.skeleton, CMU_UNIT)
    np.testing.assert_allclose(np.linalg.norm(layout.rest_offsets_m[1:], axis=-1), layout.bone_lengths_m)
    # summing rest offsets along kept parents gives the rest pose of the full skeleton's kept joints
    rest = np.zeros((layout.num_joints, 3))
    for k, p in enumerate(layout.parents):
        if p >= 0:
            rest[k] = rest[p] + layout.rest_offsets_m[k]
    full = np.zeros((cmu.skeleton.num_joints, 3))
    for j, p in enumerate(cmu.skeleton.parents):
        full[j] = (full[p] if p >= 0 else 0) + cmu.skeleton.offsets[j] * CMU_UNIT
    np.testing.assert_allclose(rest, full[list(layout.source_index)] - full[layout.source_index[0]], atol=1e-12)
