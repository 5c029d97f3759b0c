"""motion.gltf and motion.body_mesh: the files read back with pygltflib and the joints' world
positions recomputed here from the nodes' TRS and the animation samples (a second forward
kinematics, quaternions through scipy) equal the walk; the body is closed and its skin weights
are whole; the Khronos glTF Validator (npm, run with node) finds nothing in any file we write."""

from __future__ import annotations

import json
import shutil
import subprocess

import numpy as np
import pytest
from conftest import REPO, run_cli, toy_walk
from scipy.spatial.transform import Rotation

from motiongan_jax.generate import writers
from motiongan_jax.motion import body_mesh, gltf, kinematics, retarget, rigs

FPS = 15.0
VALIDATOR = REPO / "tests" / "validate_gltf.js"
NODE_MODULES = REPO / "motiongan_jax" / "demo" / "static" / "node_modules"
_DTYPES = {5126: np.float32, 5121: np.uint8, 5123: np.uint16, 5125: np.uint32}
_WIDTH = {"SCALAR": 1, "VEC3": 3, "VEC4": 4, "MAT4": 16}


@pytest.fixture(scope="module")
def walk():
    return toy_walk()


def load(path):
    import pygltflib

    gl = pygltflib.GLTF2().load(str(path))
    uri = gl.buffers[0].uri
    blob = gl.binary_blob() if uri is None else gl.decode_data_uri(uri)

    def accessor(i):
        a = gl.accessors[i]
        v = gl.bufferViews[a.bufferView]
        start = (v.byteOffset or 0) + (a.byteOffset or 0)
        n = a.count * _WIDTH[a.type]
        return np.frombuffer(blob, _DTYPES[a.componentType], n, start).reshape(a.count, -1)

    return gl, accessor


def gltf_world(path, animation: int = 0) -> np.ndarray:
    """(F, nodes, 3) world positions of the skeleton's nodes from the file alone."""
    gl, accessor = load(path)
    anim = gl.animations[animation]
    F = gl.accessors[anim.samplers[0].input].count
    nodes = [n for n in gl.nodes if n.mesh is None]
    J = len(nodes)
    rot = np.broadcast_to(np.eye(3), (F, J, 3, 3)).copy()
    trans = np.array([n.translation or [0.0, 0.0, 0.0] for n in nodes])[None].repeat(F, 0)
    for ch in anim.channels:
        s = anim.samplers[ch.sampler]
        out = accessor(s.output).astype(np.float64)
        if ch.target.path == "rotation":
            rot[:, ch.target.node] = Rotation.from_quat(out).as_matrix()
        else:
            trans[:, ch.target.node] = out
    parent = {c: p for p, n in enumerate(nodes) for c in (n.children or [])}
    wr, wp = np.zeros_like(rot), np.zeros_like(trans)
    for j in range(J):  # parents come first in our files
        p = parent.get(j)
        if p is None:
            wr[:, j], wp[:, j] = rot[:, j], trans[:, j]
        else:
            wr[:, j] = wr[:, p] @ rot[:, j]
            wp[:, j] = wp[:, p] + np.einsum("fab,fb->fa", wr[:, p], trans[:, j])
    return wp


def validate(*paths) -> dict:
    if shutil.which("node") is None:
        pytest.skip("node is not installed: the glTF Validator runs on node (the README's install command "
                    "installs it)")
    assert (NODE_MODULES / "gltf-validator").is_dir(), \
        "npm packages missing: run `npm ci --prefix motiongan_jax/demo/static` (the README's install command)"
    out = subprocess.run(["node", str(VALIDATOR), *map(str, paths)], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout)


def assert_valid(*paths):
    for path, report in validate(*paths).items():
        assert (report["numErrors"], report["numWarnings"]) == (0, 0), (path, report["messages"])


@pytest.mark.parametrize("hierarchy", ["exact", "source"])
def test_glb_joints_are_the_walk(walk, tmp_path, hierarchy):
    pos, layout, _ = walk
    motion, ex = writers.to_bvh_motion(pos, layout, FPS, hierarchy=hierarchy)
    path = tmp_path / "walk.glb"
    gltf.write_gltf(path, motion.skeleton, 1.0, [motion], ["toy"], gltf.body_for(motion.skeleton, 1.0))
    world = gltf_world(path)
    np.testing.assert_allclose(world, kinematics.world_positions(motion), atol=1e-5)
    # the toy walk is a rigid skeleton's: every bone direction can be met, so the joints are the walk's
    np.testing.assert_allclose(world[:, list(ex.kept_index)], pos, atol=1e-5)
    gl, accessor = load(path)
    assert gl.asset.version == "2.0" and gl.animations[0].name == "toy"
    np.testing.assert_allclose(accessor(gl.animations[0].samplers[0].input)[:, 0], np.arange(len(pos)) / FPS,
                               rtol=1e-6)
    assert_valid(path)


def test_gltf_holds_one_animation_per_motion(walk, tmp_path):
    pos, layout, _ = walk
    mirrored = pos[::-1].copy()  # the walk backwards: another motion on the same skeleton
    motions = [writers.to_bvh_motion(p, layout, FPS)[0] for p in (pos, mirrored)]
    path = tmp_path / "two.gltf"
    gltf.write_gltf(path, motions[0].skeleton, 1.0, motions, ["forward", "backward"])  # no body: bones only
    assert path.read_text().startswith("{")
    gl, _ = load(path)
    assert [a.name for a in gl.animations] == ["forward", "backward"] and not gl.meshes
    for k, m in enumerate(motions):
        np.testing.assert_allclose(gltf_world(path, k), kinematics.world_positions(m), atol=1e-5)
    assert_valid(path)


def test_retargeted_glb_is_the_rig_and_its_walk(walk, tmp_path):
    pos, layout, _ = walk
    rig = rigs.load_rig("mixamo")
    r = retarget.retarget(pos, layout.joint_names, layout.parents, layout.rest_offsets_m, rig, FPS)
    path = tmp_path / "mixamo.glb"
    gltf.write_gltf(path, r.motion.skeleton, rig.units_to_m, [r.motion], ["onto mixamo"],
                    gltf.body_for(r.motion.skeleton, rig.units_to_m))
    np.testing.assert_allclose(gltf_world(path), r.positions_m, atol=1e-5)
    gl, accessor = load(path)
    joints = gl.nodes[:rig.skeleton.num_joints]
    assert [n.name for n in joints] == list(rig.skeleton.names)
    np.testing.assert_allclose([n.translation or [0, 0, 0] for n in joints[1:]], rig.skeleton.offsets[1:] * 0.01,
                               atol=1e-12)
    # the inverse bind matrices undo each joint's rest transform
    ibm = accessor(gl.skins[0].inverseBindMatrices).reshape(-1, 4, 4).transpose(0, 2, 1)
    rest = rig.rest_world_m()
    np.testing.assert_allclose(ibm[:, :3, 3], -rest, atol=1e-6)
    np.testing.assert_allclose(ibm[:, :3, :3], np.broadcast_to(np.eye(3), (len(rest), 3, 3)), atol=0)
    assert_valid(path)


def test_body_is_closed_and_its_skin_whole():
    rig = rigs.load_rig("smpl")
    rest = rig.rest_world_m()
    body = gltf.body_for(rig.skeleton, rig.units_to_m)
    V = len(body.vertices)
    # weights: at most two joints a vertex, summing to 1
    np.testing.assert_allclose(body.weights.sum(axis=1), 1.0, atol=1e-6)
    assert ((body.weights > 0).sum(axis=1) <= 2).all() and (body.weights >= 0).all()
    assert body.joints.max() < rig.skeleton.num_joints
    np.testing.assert_allclose(np.linalg.norm(body.normals, axis=1), 1.0, atol=1e-5)
    # closed surface: every edge is shared by exactly two triangles, in opposite directions
    t = body.triangles
    edges = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    directed = {tuple(e) for e in edges.tolist()}
    assert len(directed) == len(edges) and all((b, a) in directed for a, b in directed)
    assert set(np.unique(t)) == set(range(V))
    # the body spans the skeleton: feet to the top of the head, within the capsules' radii
    assert body.vertices[:, 1].min() < rest[:, 1].min() + 0.01 and body.vertices[:, 1].max() > rest[:, 1].max()
    # skinning at the rest pose changes nothing; posed, a vertex of one joint keeps its distance to it
    R = np.broadcast_to(np.eye(3), (1, len(rest), 3, 3))
    np.testing.assert_allclose(body_mesh.skin(body, rest, R, rest[None])[0], body.vertices, atol=1e-6)
    turn = Rotation.from_euler("y", 90, degrees=True).as_matrix()
    posed = body_mesh.skin(body, rest, np.broadcast_to(turn, R.shape), (rest @ turn.T)[None])[0]
    np.testing.assert_allclose(posed, body.vertices @ turn.T, atol=1e-5)  # the whole body turned


def test_cli_writes_a_valid_character_and_a_retargeted_one(random_tiny, tmp_path):
    common = ["--workdir", random_tiny, "--style", "Happy", "--curve", "line", "--length", "3"]
    code, out, err = run_cli("generate", [*common, "--z", "2", "--out", tmp_path / "walk.gltf"])
    assert code == 0, err
    code, out, err = run_cli("generate", [*common, "--rig", "smpl", "--out", tmp_path / "smpl.glb"])
    assert code == 0, err
    assert "retargeted onto smpl (smpl names" in err and "foot skate" in err and "penetration" in err
    gl, _ = load(tmp_path / "walk.gltf")
    assert [a.name for a in gl.animations] == ["Happy z0", "Happy z1"]
    assert_valid(tmp_path / "walk.gltf", tmp_path / "smpl.glb")


def test_preview_gif_frames_the_body(walk, tmp_path):
    """The GIF shows the skinned body large (most of the frame's height), the floor's grid and the
    path; the same writer draws stick figures with body=False."""
    from PIL import Image

    from motiongan_jax.generate.walk import Generated

    pos, layout, _ = walk
    T = 6
    gen = Generated(pos[None, :T], None, None, pos[:T, 0] * np.array([1.0, 0.0, 1.0]), np.zeros((1, 4)), np.zeros(1))
    path = writers.write_outputs(tmp_path / "walk.gif", gen, ["toy"], layout, FPS)[0]
    with Image.open(path) as im:
        assert im.n_frames == T
        im.seek(T // 2)
        rgb = np.asarray(im.convert("RGB"), np.int32)
    H = rgb.shape[0]
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    body = (np.abs(r - g) < 60) & (rgb.max(-1) < 200) & (rgb.max(-1) > 40)  # shaded skin and tints, not white
    rows = np.flatnonzero(body.sum(axis=1) > 2)
    assert rows[-1] - rows[0] > 0.55 * H, (rows[0], rows[-1], H)
    assert ((r > 200) & (g < 80) & (b < 80)).sum() > 10  # the red path on the floor
    sticks = writers.write_outputs(tmp_path / "sticks.gif", gen, ["toy"], layout, FPS, body=False)[0]
    assert sticks.read_bytes() != path.read_bytes()
