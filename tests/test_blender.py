"""Blender reads what we write: Debian's Blender, headless, imports a GLB of the project's skeleton,
retargeted GLB and BVH files (tests/blender_joints.py, Blender's own glTF and BVH importers), and the
head of every bone in world space equals the joint's world position by the project's forward
kinematics within 1 mm in every frame. Skips only where Blender is not installed."""

from __future__ import annotations

import json
import shutil
import subprocess

import numpy as np
import pytest
from conftest import REPO, toy_walk

from motiongan_jax.generate import writers
from motiongan_jax.motion import bvh, gltf, kinematics, retarget, rigs

FPS = 15
SCRIPT = REPO / "tests" / "blender_joints.py"


def blender_axes(p_FxJx3: np.ndarray) -> np.ndarray:
    """Our Y-up, +Z-forward metres as both importers turn them: Blender's Z up, our +Z to its -Y."""
    return np.stack([p_FxJx3[..., 0], -p_FxJx3[..., 2], p_FxJx3[..., 1]], axis=-1)


def test_blender_imports_the_joints_where_we_put_them(tmp_path):
    if shutil.which("blender") is None:
        pytest.skip("Blender is not installed: apt-get install blender python3-numpy (the README's install "
                    "command and .ci/run install it)")
    pos, layout, _ = toy_walk(frames=12)
    expected = {}  # file -> (bone names, (F, J, 3) world positions in metres), Y up

    motion, _ = writers.to_bvh_motion(pos, layout, FPS)
    path = tmp_path / "walk.glb"
    gltf.write_gltf(path, motion.skeleton, 1.0, [motion], ["toy"], gltf.body_for(motion.skeleton, 1.0))
    expected[f"{path}"] = (motion.skeleton.names, kinematics.world_positions(motion))
    for name in ("mixamo", "bandai", "smpl"):  # centimetres ZXY, centimetres ZYX, metres XYZ
        rig = rigs.load_rig(name)
        r = retarget.retarget(pos, layout.joint_names, layout.parents, layout.rest_offsets_m, rig, FPS)
        sk, units = r.motion.skeleton, rig.units_to_m
        if name == "mixamo":
            path = tmp_path / f"{name}.glb"
            gltf.write_gltf(path, sk, units, [r.motion], [name], gltf.body_for(sk, units))
            expected[f"{path}"] = (sk.names, kinematics.world_positions(r.motion) * units)
        path = tmp_path / f"{name}.bvh"
        bvh.write_bvh(path, r.motion)
        back = bvh.read_bvh(path)  # what Blender reads: the file's own text, End Sites are no bones
        joints = [j for j, ch in enumerate(back.skeleton.channels) if ch]
        world = kinematics.world_positions(back) * units
        np.testing.assert_allclose(world, r.positions_m, atol=1e-5)
        expected[f"{path}={units}"] = ([back.skeleton.names[j] for j in joints], world[:, joints])

    out = tmp_path / "heads.json"
    run = subprocess.run(["blender", "-b", "--factory-startup", "--python", str(SCRIPT), "--", str(out), str(FPS),
                          *expected], capture_output=True, text=True, timeout=600)
    assert run.returncode == 0 and out.exists(), run.stdout[-3000:] + run.stderr[-3000:]
    found = json.loads(out.read_text())
    for spec, (names, world) in expected.items():
        got = found["files"][spec.partition("=")[0]]
        assert len(got["frames"]) == len(world), (spec, got["frames"])
        index = {n: i for i, n in enumerate(got["bones"])}
        assert set(names) <= set(index), (spec, sorted(set(names) - set(index)))
        heads = np.asarray(got["heads"])[:, [index[n] for n in names]]
        err = np.linalg.norm(heads - blender_axes(world), axis=-1)
        worst = np.unravel_index(err.argmax(), err.shape)
        assert err.max() < 1e-3, (spec, found["blender"], names[worst[1]], int(worst[0]), err.max())
