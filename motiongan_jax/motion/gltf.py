"""glTF 2.0 out: a skeleton as a node hierarchy with a skin, a body skinned to it, and one
animation per motion (pygltflib writes the file format).

What the file holds (metres, Y up, +Z forward, as glTF's own conventions and this project's):
- nodes 0..J-1: the skeleton's joints in file order, End Sites included, each node's translation
  its OFFSET in metres and no rotation: the rest pose (BVH's, every rotation zero), which is the
  bind pose. Node J: the body's mesh with the skin, at the scene's root without a transform (glTF
  ignores a skinned mesh node's own transform; the validator warns about one).
- skin: every joint node, inverse bind matrices of the rest pose.
- mesh: `body_mesh.Body` (POSITION, NORMAL, JOINTS_0, WEIGHTS_0, one material), when given.
- animations: one per motion, named by its title: each joint with rotation channels gets a
  rotation channel (unit quaternions, x y z w, neighbours in one hemisphere so LINEAR
  interpolation takes the short way), each joint with position channels (the root) a translation
  channel, sampled at the motion's frame times. A glTF viewer shows the motion of a BVH file of
  the same skeleton joint for joint: `kinematics.world_positions` of each motion, in metres, is what
  a glTF loader's scene graph computes.
`write_gltf` writes `.glb` (binary) or `.gltf` (JSON with the buffer inside as a data URI, one file)
by suffix, atomically.
"""

from __future__ import annotations

import base64
from pathlib import Path
from typing import Sequence

import numpy as np

from motiongan_jax import atomic
from motiongan_jax.motion import body_mesh, bvh, kinematics, rigs

SUFFIXES = (".glb", ".gltf")
GENERATOR = "motiongan_jax"
BODY_COLOR = (0.78, 0.74, 0.70, 1.0)
_FLOAT, _UBYTE, _USHORT, _UINT = 5126, 5121, 5123, 5125
_ARRAY, _ELEMENTS = 34962, 34963


class GLTFError(ValueError):
    """Motions that cannot be written as one glTF file; the message says why."""


def body_for(skeleton: bvh.Skeleton, units_to_m: float, **detail) -> body_mesh.Body:
    """The project's body for a skeleton (body_mesh.body_mesh), its roles from the built-in name maps
    (bones without a role get thin capsules); the pelvis is the joint of that role, else the first
    joint with several children."""
    from motiongan_jax.motion import representation

    _, roles = rigs.detect_roles(skeleton)
    pelvis = roles.get("pelvis")
    if pelvis is None:
        pelvis = representation.representation_root(skeleton)
    rest = rigs.rest_world(skeleton) * units_to_m
    return body_mesh.body_mesh(skeleton.parents, rest, {j: r for r, j in roles.items()}, pelvis, **detail)


def _quaternions(rot_Fx3x3: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    q = Rotation.from_matrix(rot_Fx3x3).as_quat()  # x, y, z, w: glTF's order
    flips = np.concatenate([[1.0], np.sign(np.sum(q[1:] * q[:-1], axis=1))])
    flips[flips == 0] = 1.0
    q *= np.cumprod(flips)[:, None]
    return q / np.linalg.norm(q, axis=1, keepdims=True)


class _Blob:
    """The one binary buffer: each view 4-byte aligned."""

    def __init__(self):
        self.parts: list[bytes] = []
        self.size = 0
        self.views: list = []
        self.accessors: list = []

    def add(self, array: np.ndarray, component: int, kind: str, target=None, minmax: bool = False) -> int:
        import pygltflib as g

        data = np.ascontiguousarray(array).tobytes()
        self.views.append(g.BufferView(buffer=0, byteOffset=self.size, byteLength=len(data), target=target))
        pad = -len(data) % 4
        self.parts.append(data + b"\0" * pad)
        self.size += len(data) + pad
        flat = np.asarray(array).reshape(len(array), -1)
        acc = g.Accessor(bufferView=len(self.views) - 1, componentType=component, count=len(array), type=kind)
        if minmax:
            acc.min = [float(v) for v in flat.min(axis=0)]
            acc.max = [float(v) for v in flat.max(axis=0)]
        self.accessors.append(acc)
        return len(self.accessors) - 1

    def bytes(self) -> bytes:
        return b"".join(self.parts)


def _check(skeleton: bvh.Skeleton, motions: Sequence[bvh.Motion]):
    if not motions:
        raise GLTFError("no motion to write")
    for m in motions:
        sk = m.skeleton
        if (sk.names != skeleton.names or sk.parents != skeleton.parents
                or not np.array_equal(sk.offsets, skeleton.offsets)):
            raise GLTFError("every motion of one glTF file must be on the same skeleton")
        if not np.isfinite(m.values).all():
            raise GLTFError("a motion has NaN or infinite values")


def build_gltf(skeleton: bvh.Skeleton, units_to_m: float, motions: Sequence[bvh.Motion], titles: Sequence[str],
               body: body_mesh.Body | None = None):
    """A pygltflib.GLTF2 of `motions` (all on `skeleton`, file units times `units_to_m` metres),
    one animation each named by `titles`, with `body` skinned to the joints (module doc)."""
    import pygltflib as g

    _check(skeleton, motions)
    J = skeleton.num_joints
    blob = _Blob()
    nodes = []
    children = [[c for c in range(J) if skeleton.parents[c] == j] for j in range(J)]
    for j in range(J):
        t = (np.asarray(skeleton.offsets[j], np.float64) * units_to_m).tolist()
        nodes.append(g.Node(name=skeleton.names[j], children=children[j] or [],
                            translation=t if any(t) else None))
    roots = [j for j in range(J) if skeleton.parents[j] < 0]
    meshes, skins, materials = [], [], []
    if body is not None:
        rest = rigs.rest_world(skeleton) * units_to_m
        ibm = np.broadcast_to(np.eye(4, dtype=np.float32), (J, 4, 4)).copy()
        ibm[:, :3, 3] = -rest
        # glTF matrices are column-major: the transpose's rows are the columns
        ibm_acc = blob.add(np.transpose(ibm, (0, 2, 1)).reshape(J, 16).astype(np.float32), _FLOAT, "MAT4")
        skins.append(g.Skin(name="skeleton", joints=list(range(J)), skeleton=roots[0], inverseBindMatrices=ibm_acc))
        small = J < 256
        attrs = g.Attributes(
            POSITION=blob.add(body.vertices.astype(np.float32), _FLOAT, "VEC3", _ARRAY, minmax=True),
            NORMAL=blob.add(body.normals.astype(np.float32), _FLOAT, "VEC3", _ARRAY),
            JOINTS_0=blob.add(body.joints.astype(np.uint8 if small else np.uint16), _UBYTE if small else _USHORT,
                              "VEC4", _ARRAY),
            WEIGHTS_0=blob.add(body.weights.astype(np.float32), _FLOAT, "VEC4", _ARRAY))
        wide = len(body.vertices) > 65535
        idx = blob.add(body.triangles.reshape(-1).astype(np.uint32 if wide else np.uint16),
                       _UINT if wide else _USHORT, "SCALAR", _ELEMENTS)
        materials.append(g.Material(name="body", pbrMetallicRoughness=g.PbrMetallicRoughness(
            baseColorFactor=list(BODY_COLOR), metallicFactor=0.0, roughnessFactor=0.75)))
        meshes.append(g.Mesh(name="body", primitives=[g.Primitive(attributes=attrs, indices=idx, material=0)]))
        nodes.append(g.Node(name="body", mesh=0, skin=0))
    animations = []
    for title, motion in zip(titles, motions):
        rot, trans = kinematics.local_transforms(motion)
        F = motion.num_frames
        times = blob.add((np.arange(F) * motion.frame_time).astype(np.float32), _FLOAT, "SCALAR", minmax=True)
        samplers, channels = [], []
        for j, ch in enumerate(skeleton.channels):
            if any(c.endswith("rotation") for c in ch):
                out = blob.add(_quaternions(rot[:, j]).astype(np.float32), _FLOAT, "VEC4")
                samplers.append(g.AnimationSampler(input=times, output=out, interpolation="LINEAR"))
                channels.append(g.AnimationChannel(sampler=len(samplers) - 1,
                                                   target=g.AnimationChannelTarget(node=j, path="rotation")))
            if any(c.endswith("position") for c in ch):
                out = blob.add((trans[:, j] * units_to_m).astype(np.float32), _FLOAT, "VEC3")
                samplers.append(g.AnimationSampler(input=times, output=out, interpolation="LINEAR"))
                channels.append(g.AnimationChannel(sampler=len(samplers) - 1,
                                                   target=g.AnimationChannelTarget(node=j, path="translation")))
        animations.append(g.Animation(name=str(title), samplers=samplers, channels=channels))
    data = blob.bytes()
    gl = g.GLTF2(asset=g.Asset(version="2.0", generator=GENERATOR), scene=0,
                 scenes=[g.Scene(name="walk", nodes=roots + ([J] if body is not None else []))],
                 nodes=nodes, meshes=meshes, skins=skins, materials=materials, animations=animations,
                 accessors=blob.accessors, bufferViews=blob.views, buffers=[g.Buffer(byteLength=len(data))])
    gl.set_binary_blob(data)
    return gl


def gltf_bytes(gl, suffix: str) -> bytes:
    """The file's bytes: GLB for ".glb", JSON with a data-URI buffer for ".gltf"."""
    if suffix == ".glb":
        return b"".join(gl.save_to_bytes())
    data = gl.binary_blob()
    gl.buffers[0].uri = "data:application/octet-stream;base64," + base64.b64encode(data).decode("ascii")
    try:
        return (gl.to_json(indent=None, separators=(",", ":")) + "\n").encode("utf-8")
    finally:
        gl.buffers[0].uri = None


def write_gltf(path, skeleton: bvh.Skeleton, units_to_m: float, motions: Sequence[bvh.Motion], titles: Sequence[str],
               body: body_mesh.Body | None = None) -> Path:
    """`build_gltf` written to `path` (.glb or .gltf by suffix) atomically: nothing is left on error."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in SUFFIXES:
        raise GLTFError(f"{path}: a glTF file ends in {' or '.join(SUFFIXES)}")
    data = gltf_bytes(build_gltf(skeleton, units_to_m, motions, titles, body), suffix)
    with atomic.atomic_path(path) as tmp:
        Path(tmp).write_bytes(data)
    return path
