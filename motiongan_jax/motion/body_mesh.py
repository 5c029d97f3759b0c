"""A simple body for a skeleton: one tapered capsule per bone, skinned to the joints by linear
blend weights that change smoothly near each joint.

Made from the skeleton alone, in its rest pose (metres, every rotation zero): a bone from joint p
to its child c is a capsule whose radii at p and c come from the child's role (`rigs.ROLES`: a
thigh is thicker than a shin, the head is a ball), as fractions of the skeleton's pelvis height,
so a taller or stockier rig gets a body of its own proportions; a bone without a role gets a thin
one. Only bones at or below the pelvis are drawn (a root on the floor above the hips, as in Bandai's
files, has none). A leaf head joint gets a head of its own along the neck's direction.

Skinning. The capsule of bone p -> c moves with joint p (p's rotation aims the bone). Within
`BLEND` of the bone's length (at most its radius times BLEND_RADII) of either end, its vertices share
their weight with the joint on the other side of that end: the bone into p at the start, joint c
(which moves the bones after it) at the end; at the joint itself the two weigh 1/2 each, and the
share falls to 0 with a smoothstep, so a bending knee or elbow stretches the skin between the two
capsules instead of tearing it. Each vertex has at most two joints with weights summing to 1.
"""

from __future__ import annotations

import dataclasses

import numpy as np

SEGMENTS = 14  # vertices around a capsule
CAP_RINGS = 4  # rings per hemispherical end
SHAFT_RINGS = (0.12, 0.25, 0.5, 0.75, 0.88)  # rings along the bone, as fractions of its length
BLEND = 0.35  # fraction of a bone's length over which its ends blend with the next joint
BLEND_RADII = 1.2  # ... at most this many of the end's radius
MIN_BONE_M = 1e-4

# (radius at the parent, radius at the child) by the child's role, as fractions of the pelvis height
_RADII = {
    "spine": (0.12, 0.12), "chest": (0.12, 0.14), "neck": (0.12, 0.055), "head": (0.05, 0.05),
    "head_end": (0.105, 0.1), "hip": (0.11, 0.085), "knee": (0.085, 0.055), "ankle": (0.055, 0.04),
    "toe": (0.04, 0.034), "toe_end": (0.032, 0.024), "clavicle": (0.065, 0.06), "shoulder": (0.065, 0.055),
    "elbow": (0.052, 0.042), "wrist": (0.042, 0.03), "hand_end": (0.03, 0.025),
}
_DEFAULT = 0.02  # a bone without a role: this fraction of the pelvis height at most (0.15 of its length)
HEAD_LENGTH = 0.2  # a leaf head's own length (fraction of the pelvis height)


@dataclasses.dataclass(frozen=True, eq=False)
class Body:
    vertices: np.ndarray  # (V, 3) float32, metres, rest pose
    normals: np.ndarray  # (V, 3) float32, unit
    joints: np.ndarray  # (V, 4) joint indices (into the skeleton), unused slots 0
    weights: np.ndarray  # (V, 4) float32, rows sum to 1
    triangles: np.ndarray  # (N, 3) vertex indices, counter-clockwise seen from outside


def _basis(e):
    a = np.eye(3)[np.argmin(np.abs(e))]
    n1 = np.cross(e, a)
    n1 /= np.linalg.norm(n1)
    return n1, np.cross(e, n1)


def capsule(a, b, r0: float, r1: float, segments: int = SEGMENTS, cap_rings: int = CAP_RINGS,
            shaft_rings=SHAFT_RINGS):
    """(vertices (V, 3), triangles (N, 3), axial position of each vertex along a -> b in metres)."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    L = float(np.linalg.norm(b - a))
    e = (b - a) / L
    n1, n2 = _basis(e)
    rings = []  # (axial, radius)
    for k in range(1, cap_rings + 1):
        t = 0.5 * np.pi * k / cap_rings
        rings.append((-r0 * np.cos(t), r0 * np.sin(t)))
    rings += [(f * L, r0 + (r1 - r0) * f) for f in shaft_rings]
    for k in range(cap_rings, 0, -1):
        t = 0.5 * np.pi * k / cap_rings
        rings.append((L + r1 * np.cos(t), r1 * np.sin(t)))
    phi = 2 * np.pi * np.arange(segments) / segments
    radial = np.cos(phi)[:, None] * n1 + np.sin(phi)[:, None] * n2  # (S, 3)
    verts = [a - r0 * e]
    axial = [-r0]
    for x, r in rings:
        verts.extend(a + x * e + r * radial)
        axial.extend([x] * segments)
    verts.append(b + r1 * e)
    axial.append(L + r1)
    R, S = len(rings), segments
    tris = []
    ring = lambda i, k: 1 + i * S + k % S  # noqa: E731
    for k in range(S):
        tris.append((0, ring(0, k + 1), ring(0, k)))
        for i in range(R - 1):
            tris += [(ring(i, k), ring(i, k + 1), ring(i + 1, k + 1)), (ring(i, k), ring(i + 1, k + 1), ring(i + 1, k))]
        tris.append((ring(R - 1, k), ring(R - 1, k + 1), 1 + R * S))
    verts = np.asarray(verts)
    tris = np.asarray(tris, np.int64)
    # outward winding whatever the basis' handedness: flip faces whose normal points at the axis
    p = verts[tris]
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    c = p.mean(axis=1)
    on_axis = a + np.clip((c - a) @ e, 0.0, L)[:, None] * e
    flip = np.sum(n * (c - on_axis), axis=1) < 0
    tris[flip] = tris[flip][:, ::-1]
    return verts, tris, np.asarray(axial)


def vertex_normals(verts, tris) -> np.ndarray:
    """Area-weighted mean of the face normals at each vertex, unit length."""
    p = verts[tris]
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    out = np.zeros_like(verts)
    for k in range(3):
        np.add.at(out, tris[:, k], n)
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def _smoothstep(x):
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3 - 2 * x)


PREVIEW = dict(segments=7, cap_rings=1, shaft_rings=(0.5,))  # a coarse body for matplotlib's previews


def body_mesh(parents, rest_world_m, roles: dict[int, str], pelvis: int, **detail) -> Body:
    """The body of a skeleton (module doc). parents: per joint (-1 root); rest_world_m (J, 3): rest
    positions in metres; roles: joint -> role (rigs.ROLES); pelvis: the joint the body starts at;
    `detail`: capsule() keywords (`PREVIEW`: fewer triangles)."""
    rest = np.asarray(rest_world_m, np.float64)
    J = len(parents)
    height = rest[pelvis, 1] - rest[:, 1].min()
    if not height > 0:
        raise ValueError("the pelvis is not above the feet in the rest pose: cannot size a body")
    below = {pelvis}
    for j in range(J):
        if parents[j] in below:
            below.add(j)
    children = [[c for c in range(J) if parents[c] == j] for j in range(J)]
    bones = []  # (p, c or -1, start, end, role)
    for c in range(J):
        p = parents[c]
        if p < 0 or c not in below or p not in below:
            continue
        if np.linalg.norm(rest[c] - rest[p]) < MIN_BONE_M:
            continue
        bones.append((p, c, rest[p], rest[c], roles.get(c)))
    for j, role in roles.items():
        if role == "head" and j in below and not any(np.linalg.norm(rest[c] - rest[j]) >= MIN_BONE_M
                                                     for c in children[j]):
            up = rest[j] - rest[parents[j]]
            up = up / np.linalg.norm(up) if np.linalg.norm(up) > MIN_BONE_M else np.array([0.0, 1.0, 0.0])
            bones.append((j, -1, rest[j], rest[j] + HEAD_LENGTH * height * up, "head_end"))
    V, N, JI, W, T = [], [], [], [], []
    count = 0
    for p, c, a, b, role in bones:
        L = float(np.linalg.norm(b - a))
        key = None if role is None else role.replace("left_", "").replace("right_", "")
        if key in _RADII:
            r0, r1 = (height * r for r in _RADII[key])
        else:
            r0 = r1 = min(_DEFAULT * height, 0.15 * L)
        verts, tris, x = capsule(a, b, r0, r1, **detail)
        ji = np.zeros((len(verts), 4), np.int64)
        wt = np.zeros((len(verts), 4))
        ji[:, 0], wt[:, 0] = p, 1.0
        gp = parents[p]
        if gp >= 0 and p != pelvis:  # the start blends with the joint that moves the bone into p
            share = 0.5 * (1 - _smoothstep(x / min(BLEND * L, BLEND_RADII * r0)))
            ji[:, 1], wt[:, 1] = gp, share
            wt[:, 0] -= share
        if c >= 0 and children[c]:  # the end blends with c, which moves the bones after it
            share = 0.5 * (1 - _smoothstep((L - x) / min(BLEND * L, BLEND_RADII * r1)))
            ji[:, 2], wt[:, 2] = c, share
            wt[:, 0] -= share
        # two joints at most per vertex: the larger share of the two ends (they never overlap by BLEND < 0.5)
        end = wt[:, 2] > wt[:, 1]
        ji[end, 1], wt[end, 1] = ji[end, 2], wt[end, 2]
        ji[:, 2], wt[:, 2] = 0, 0.0
        ji[wt[:, 1] <= 0, 1] = 0
        wt[:, 1] = np.maximum(wt[:, 1], 0.0)
        wt[:, 0] = 1.0 - wt[:, 1]
        V.append(verts)
        N.append(vertex_normals(verts, tris))
        JI.append(ji)
        W.append(wt)
        T.append(tris + count)
        count += len(verts)
    if not V:
        raise ValueError("the skeleton has no bone below its pelvis: no body to make")
    weights = np.concatenate(W).astype(np.float32)
    weights[:, 0] = 1.0 - weights[:, 1]  # exactly 1 in float32 too
    return Body(np.concatenate(V).astype(np.float32), np.concatenate(N).astype(np.float32),
                np.concatenate(JI), weights, np.concatenate(T))


def skin(body: Body, rest_world_m, world_rot_FxJx3x3, world_pos_FxJx3) -> np.ndarray:
    """(F, V, 3) vertices of the body posed by linear blend skinning: each joint moves its
    vertices by its world transform times the inverse of its rest (bind) transform, weighted."""
    rest = np.asarray(rest_world_m, np.float64)
    R = np.asarray(world_rot_FxJx3x3, np.float64)
    P = np.asarray(world_pos_FxJx3, np.float64)
    v = body.vertices.astype(np.float64)
    out = np.zeros((len(R), len(v), 3))
    for k in range(body.joints.shape[1]):
        w = body.weights[:, k].astype(np.float64)
        if not w.any():
            continue
        j = body.joints[:, k]
        local = v - rest[j]  # the vertex in joint j's rest frame (rest rotations are the identity)
        out += w[None, :, None] * (np.einsum("fvab,vb->fva", R[:, j], local) + P[:, j])
    return out
