"""Retargeting: a walk's joint positions onto another skeleton (a `rigs.Rig`), as rotations of
that skeleton's own joints.

How (every step on world directions, so a rig's rest pose, T or A, and the way it faces do not
matter):
1. Roles. The source joints (the model's skeleton) and the rig's are matched by role
   (`rigs.resolve_roles`); the roles both have are *matched*. Each matched rig joint aims along the
   segment from its nearest matched ancestor in the rig to it; the rig's joints in between, and
   every unmatched joint, keep their rest rotation.
2. Directions, not lengths. The segment's direction is the source's between the same two roles;
   its length is the rig's own rest length. Heights over the floor (y = 0) are scaled by the ratio
   of the two skeletons' standing pelvis heights (`standing`: from the rest pose where it stands,
   else from the legs' lengths), floor positions are not: the pelvis keeps the source's floor
   path (the root path stays on the user's curve) at the scaled height.
3. Rotations, top down. A matched joint with one matched child turns by the minimal rotation that
   takes its rest segment to the wanted direction (no twist relative to its parent); one with
   several (pelvis, chest) takes the best-fit rotation of them all (`ik.kabsch`), so its children
   land where its rotation puts them. The positions are the rig's forward kinematics by
   construction: bone lengths are the rig's.
4. Feet. The rig's contact point (the ball of its foot, or its ankle if no toe is matched) goes
   where the source's does, in every frame: the same floor position, the height scaled as in 2.
   (from each one's rest clearance). Where the source's foot is planted (low and slow:
   `contacts`, its height band scaled with the skeleton) the point is pinned to its median floor
   position over that stance (the correction faded in and out over `PIN_BLEND` frames), so the
   source's own skate is not copied. The ankle keeps the source's foot direction, and each leg is
   solved by two-bone IK with the knee on the side of the hip-ankle line that the source's knee
   is on; an ankle out of the leg's reach goes as far as the straightened leg allows.
Both feet and pelvis follow the source's, so a rig of other proportions does not slide its feet,
and a walk taken onto a rig and back returns to itself wherever the rig's legs reached (the
steps 2-4 invert exactly; a shorter rig cannot take a straight leg's full stride, and there the
walk loses what the rig could not reach). `foot_report` measures the foot skate and the floor
penetration, the same way for the source and the retargeted walk, for the notes that generate.py
prints.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from motiongan_jax.motion import bvh, ik, rigs

CONTACT_BAND_M = 0.03  # a foot is low when within this of its own 5th-percentile height
# retarget scales the band with the skeleton's standing pelvis height over this, so a walk and
# its copy on a rig of another size find the same stances
BAND_PELVIS_M = 0.95
CONTACT_SPEED_MPS = 0.5  # ... and planted when also slower than this (horizontally)
MIN_STANCE = 3  # frames: shorter low-and-slow runs are not pinned
PIN_BLEND = 2  # frames either side of a stance over which the pin fades in and out
FLOOR_PERCENTILE = 5.0
STANDING_TILT_DEG = 30.0  # a rest pose stands when every thigh and shin is this close to straight down
STANDING_PER_LEG = 1.16  # pelvis height / (thigh + shin) standing: 1.14-1.17 on CMU's and the built-in skeletons
_EPS = 1e-9


@dataclasses.dataclass(frozen=True, eq=False)
class Retargeted:
    motion: bvh.Motion  # on the rig's skeleton (its channels made whole: 3 rotations per joint), file units
    positions_m: np.ndarray  # (F, J, 3) world positions of every rig joint (FK of `motion`), metres
    matched: tuple[str, ...]  # roles matched on both skeletons
    report: dict  # foot skate and floor penetration, source and retargeted (`foot_report`)


def layout_skeleton(joint_names, parents, rest_offsets_m) -> bvh.Skeleton:
    """A bvh.Skeleton (metres) of a row layout's joints, to match roles on."""
    chans = tuple(() if str(n).endswith("_EndSite") else ("Zrotation", "Xrotation", "Yrotation")
                  for n in joint_names)
    return bvh.Skeleton(tuple(joint_names), tuple(int(p) for p in parents),
                        np.asarray(rest_offsets_m, np.float64), chans)


def source_roles(joint_names, parents, rest_offsets_m) -> dict[str, int]:
    """role -> index of the model's (source) joints; RigError when its legs are not matched."""
    sk = layout_skeleton(joint_names, parents, rest_offsets_m)
    _, roles = rigs.resolve_roles(sk, None, "the model's skeleton")
    return roles


def output_skeleton(skeleton: bvh.Skeleton) -> bvh.Skeleton:
    """The rig's skeleton with every joint given three rotation channels (its own order where it has
    all three, else ZXY) and the root three position channels first; other position channels kept."""
    chans = []
    for j, ch in enumerate(skeleton.channels):
        if not ch:
            chans.append(())
            continue
        rot = [c for c in ch if c.endswith("rotation")]
        if len(rot) != 3:
            rot = ["Zrotation", "Xrotation", "Yrotation"]
        pos = ["Xposition", "Yposition", "Zposition"] if j == 0 else [c for c in ch if c.endswith("position")]
        chans.append(tuple(pos + rot))
    return bvh.Skeleton(skeleton.names, skeleton.parents, skeleton.offsets, tuple(chans))


# ---------------------------------------------------------------------------------------------
# Feet: contacts, skate, penetration


def contacts(feet_Fx2x3, fps: float, *, speed: bool = True, band_m: float = CONTACT_BAND_M) -> np.ndarray:
    """(F, 2) bool: the foot is low (within `band_m` of its own 5th-percentile height) and,
    with `speed`, slower than CONTACT_SPEED_MPS on the floor (central differences)."""
    feet = np.asarray(feet_Fx2x3, np.float64)
    h = feet[..., 1]
    low = h < np.percentile(h, FLOOR_PERCENTILE, axis=0) + band_m
    if not speed or len(feet) < 2:
        return low
    v = np.linalg.norm(np.gradient(feet[..., [0, 2]], axis=0), axis=-1) * fps
    return low & (v < CONTACT_SPEED_MPS)


def foot_report(feet_Fx2x3, joints_FxJx3, fps: float) -> dict:
    """Foot skate: the mean horizontal speed (cm/s) of a foot while it is low (`contacts` without
    the speed test, so sliding counts); floor penetration: the depth of the lowest joint below
    y = 0, mean over frames and deepest (cm), and the share of frames more than 5 mm under."""
    feet = np.asarray(feet_Fx2x3, np.float64)
    low = contacts(feet, fps, speed=False)
    v = np.linalg.norm(np.gradient(feet[..., [0, 2]], axis=0), axis=-1) * fps
    depth = np.maximum(0.0, -np.asarray(joints_FxJx3, np.float64)[..., 1].min(axis=-1))
    return {"skate_cm_s": float(100 * v[low].mean()) if low.any() else float("nan"),
            "penetration_mean_cm": float(100 * depth.mean()), "penetration_max_cm": float(100 * depth.max()),
            "penetration_frames": float(np.mean(depth > 0.005))}


def _stances(mask_F: np.ndarray) -> list[tuple[int, int]]:
    """[start, end) runs of True at least MIN_STANCE long."""
    out, start = [], None
    for f, on in enumerate(list(mask_F) + [False]):
        if on and start is None:
            start = f
        elif not on and start is not None:
            if f - start >= MIN_STANCE:
                out.append((start, f))
            start = None
    return out


def pin_feet(point_Fx3, planted_F) -> np.ndarray:
    """Goals for a contact point: on the floor (x, z), each stance's median position held over the
    stance (a few frames at its ends that differ, such as those a shorter rig could not reach, do
    not move it); the correction this makes at the stance's first (last) frame fades out linearly
    over PIN_BLEND frames before (after) it, so the swing keeps its own motion; the point's own
    path elsewhere. Heights stay the point's own (a foot rolling over its ball lifts it a little)."""
    point = np.asarray(point_Fx3, np.float64)
    goal = point.copy()
    weight = np.zeros(len(point))
    for a, b in _stances(planted_F):
        mean = np.median(point[a:b], axis=0) * np.array([1.0, 0.0, 1.0])
        goal[a:b] = mean + point[a:b] * np.array([0.0, 1.0, 0.0])
        weight[a:b] = 1.0
        for edge, frames in ((a, range(a - 1, a - 1 - PIN_BLEND, -1)), (b - 1, range(b, b + PIN_BLEND))):
            for i, f in enumerate(frames):
                w = 1.0 - (i + 1) / (PIN_BLEND + 1)
                if 0 <= f < len(point) and w > weight[f]:
                    weight[f] = w
                    goal[f] = point[f] + w * (mean - point[edge]) * np.array([1.0, 0.0, 1.0])
    return goal


def two_bone(hip_Fx3, knee_Fx3, goal_Fx3, upper: float, lower: float) -> tuple[np.ndarray, np.ndarray]:
    """(knee, ankle) positions: the ankle at the goal where the leg reaches it (else as far toward
    it as the leg allows), the knee in the plane of hip, goal and the given knee."""
    hip, knee, goal = (np.asarray(a, np.float64) for a in (hip_Fx3, knee_Fx3, goal_Fx3))
    u, d = ik._unit(goal - hip)
    d = np.clip(d, abs(upper - lower) + 1e-6, upper + lower - 1e-6)
    side = knee - hip
    side = side - np.sum(side * u, axis=-1, keepdims=True) * u
    v, n = ik._unit(side)
    v = np.where((n > 1e-9)[:, None], v, ik._perpendicular(u))
    cos_a = np.clip((upper ** 2 + d ** 2 - lower ** 2) / (2 * upper * d), -1.0, 1.0)
    new_knee = hip + upper * (cos_a[:, None] * u + np.sqrt(1 - cos_a ** 2)[:, None] * v)
    return new_knee, hip + d[:, None] * u


# ---------------------------------------------------------------------------------------------
# The retargeting


def _solve(parent_m, rest_vec, directions, pelvis_pos):
    """World rotations (F, M, 3, 3) and positions (F, M, 3) of the matched joints, top down
    (module doc, step 3). parent_m: nearest matched ancestor (-1 for the pelvis, index 0);
    rest_vec (M, 3): rest segment from it; directions (F, M, 3): wanted unit directions."""
    F, M = directions.shape[0], len(parent_m)
    kids = [[c for c in range(M) if parent_m[c] == j] for j in range(M)]
    G = np.zeros((F, M, 3, 3))
    X = np.zeros((F, M, 3))
    X[:, 0] = pelvis_pos
    eye = np.broadcast_to(np.eye(3), (F, 3, 3))
    rest_dir = ik._unit(rest_vec)[0]
    for j in range(M):
        Gp = eye if parent_m[j] < 0 else G[:, parent_m[j]]
        k = kids[j]
        if not k:
            G[:, j] = Gp
        elif len(k) > 1 and np.linalg.svd(rest_dir[k], compute_uv=False)[1] > 1e-3:
            G[:, j] = ik.kabsch(rest_dir[k], directions[:, k])
        else:
            local = ik.min_rotation(rest_dir[k[0]], np.einsum("fji,fj->fi", Gp, directions[:, k[0]]))
            G[:, j] = Gp @ local
        for c in k:
            X[:, c] = X[:, j] + G[:, j] @ rest_vec[c]
    return G, X


def standing(rest_m, parents, roles) -> tuple[float, float | None]:
    """(pelvis height, floor height or None) of a skeleton standing, metres, from its rest pose
    (world positions): where the rest pose stands (every thigh and shin within STANDING_TILT_DEG of
    straight down), the pelvis's height over the lowest joint below it, and that joint's height;
    otherwise (a rest pose with the legs folded, as Bandai's files have) STANDING_PER_LEG times the
    mean thigh + shin length, and no floor (rest heights say nothing then)."""
    rest = np.asarray(rest_m, np.float64)
    legs = [(roles[f"{s}_hip"], roles[f"{s}_knee"], roles[f"{s}_ankle"]) for s in ("left", "right")]
    bones = [rest[b] - rest[a] for h, k, a_ in legs for a, b in ((h, k), (k, a_))]
    down = all(-v[1] > np.cos(np.radians(STANDING_TILT_DEG)) * np.linalg.norm(v) for v in bones)
    if down:
        pelvis = roles["pelvis"]
        body = [j for j in range(len(rest)) if j == pelvis or rigs.descends(parents, j, pelvis)]
        floor = float(rest[body, 1].min())
        return float(rest[pelvis, 1] - floor), floor
    return STANDING_PER_LEG * float(np.mean([np.linalg.norm(v) for v in bones]) * 2), None


def retarget(positions_m, joint_names, parents, rest_offsets_m, rig: rigs.Rig, fps: float) -> Retargeted:
    """The walk `positions_m` (F, J, 3, metres, the source layout's joints) on `rig` (module doc)."""
    pos = np.asarray(positions_m, np.float64)
    if pos.ndim != 3 or pos.shape[1:] != (len(joint_names), 3) or not np.isfinite(pos).all():
        raise rigs.RigError(f"positions must be finite (frames, {len(joint_names)}, 3), got shape {pos.shape}")
    src = source_roles(joint_names, parents, rest_offsets_m)
    sk = rig.skeleton
    matched = sorted((r for r in rig.roles if r in src), key=lambda r: rig.roles[r])
    joints = [rig.roles[r] for r in matched]  # rig indices, parents before children
    if joints[0] != rig.roles["pelvis"]:
        raise rigs.RigError(f"rig {rig.name}: a matched joint lies above the pelvis")
    role_of = {rig.roles[r]: r for r in matched}
    slot = {j: m for m, j in enumerate(joints)}
    parent_m = []
    for j in joints:
        a = sk.parents[j]
        while a >= 0 and a not in slot:
            a = sk.parents[a]
        parent_m.append(slot.get(a, -1))
    rest_w = rig.rest_world_m()
    rest_vec = np.array([rest_w[j] - (rest_w[joints[p]] if p >= 0 else rest_w[j]) for j, p in zip(joints, parent_m)])

    # 2. directions from the source; heights over the floor scaled by the standing pelvis heights
    src_rest = np.zeros((len(joint_names), 3))
    for k, p in enumerate(parents):
        if p >= 0:
            src_rest[k] = src_rest[p] + np.asarray(rest_offsets_m[k], np.float64)
    (h_rig, floor_rig), (h_src, floor_src) = standing(rest_w, sk.parents, rig.roles), standing(src_rest, parents, src)
    scale = h_rig / h_src
    F = len(pos)
    directions = np.zeros((F, len(joints), 3))
    for m, (j, p) in enumerate(zip(joints, parent_m)):
        if p < 0:
            continue
        d, n = ik._unit(pos[:, src[role_of[j]]] - pos[:, src[role_of[joints[p]]]])
        directions[:, m] = np.where((n > 1e-6)[:, None], d, ik._unit(rest_vec[m])[0])
    pelvis = pos[:, src["pelvis"]] * np.array([1.0, scale, 1.0])
    G, X = _solve(parent_m, rest_vec, directions, pelvis)

    # 4. feet: the rig's contact point where the source's is, pinned where that is planted
    for side in ("left", "right"):
        h, k, a = (slot[rig.roles[f"{side}_{r}"]] for r in ("hip", "knee", "ankle"))
        if parent_m[k] != h or parent_m[a] != k:
            continue
        role = f"{side}_toe" if f"{side}_toe" in matched else f"{side}_ankle"
        c, c_src = slot[rig.roles[role]], src[role]
        planted = contacts(pos[:, [c_src, c_src]], fps, band_m=CONTACT_BAND_M * h_src / BAND_PELVIS_M)[:, 0]
        clear_rig, clear_src = (0.0 if fl is None else float(r[j, 1] - fl)  # the point's rest height over the floor
                                for r, j, fl in ((rest_w, rig.roles[role], floor_rig), (src_rest, c_src, floor_src)))
        goal_c = pin_feet(pos[:, c_src], planted)
        goal_c[:, 1] = scale * (goal_c[:, 1] - clear_src) + clear_rig
        # the knee's side of the hip-ankle line is the source's own (its knee's offset from its own
        # line), not the source's thigh direction seen from the rig's line: the two lines differ,
        # and near a straight leg that difference would swing the knee. A hint towards the toes
        # bends a leg the source holds straight.
        hip_s, knee_s, ankle_s = (pos[:, src[f"{side}_{r}"]] for r in ("hip", "knee", "ankle"))
        line = ik._unit(ankle_s - hip_s)[0]
        bend = knee_s - hip_s
        bend = bend - np.sum(bend * line, axis=-1, keepdims=True) * line
        if role.endswith("toe"):
            bend = bend + 1e-6 * ik._unit(pos[:, c_src] - ankle_s)[0]
        knee, ankle = two_bone(X[:, h], X[:, h] + bend, goal_c + X[:, a] - X[:, c],
                               np.linalg.norm(rest_vec[k]), np.linalg.norm(rest_vec[a]))
        directions[:, k] = ik._unit(knee - X[:, h])[0]
        directions[:, a] = ik._unit(ankle - knee)[0]
    G, X = _solve(parent_m, rest_vec, directions, pelvis)

    # rotations on the rig: matched joints relative to their nearest matched ancestor, others at rest
    out_sk = output_skeleton(sk)
    J = sk.num_joints
    local = np.broadcast_to(np.eye(3), (F, J, 3, 3)).copy()
    for m, (j, p) in enumerate(zip(joints, parent_m)):
        local[:, j] = G[:, m] if p < 0 else np.swapaxes(G[:, p], -1, -2) @ G[:, m]
    root_m = pelvis - (rest_w[joints[0]] - rest_w[0])
    cols = []
    for j, ch in enumerate(out_sk.channels):
        if not ch:
            continue
        order = "".join(c[0] for c in ch if c.endswith("rotation"))
        angles = iter(np.unwrap(ik.matrix_to_euler(local[:, j], order), period=360.0, axis=0).T)
        for c in ch:
            axis = "XYZ".index(c[0])
            if c.endswith("rotation"):
                cols.append(next(angles))
            elif j == 0:
                cols.append(root_m[:, axis] / rig.units_to_m)
            else:
                cols.append(np.full(F, sk.offsets[j, axis]))
    motion = bvh.Motion(out_sk, 1.0 / fps, np.stack(cols, axis=-1), source=f"<retargeted onto {rig.name}>")
    from motiongan_jax.motion import kinematics

    world = kinematics.world_positions(motion) * rig.units_to_m
    body = [j for j in range(J) if j == joints[0] or rigs.descends(sk.parents, j, joints[0])]  # not a floor root
    feet_t = [rig.roles.get(f"{s}_toe", rig.roles[f"{s}_ankle"]) for s in ("left", "right")]
    feet_s = [src.get(f"{s}_toe", src[f"{s}_ankle"]) for s in ("left", "right")]
    report = {"source": foot_report(pos[:, feet_s], pos, fps),
              "retargeted": foot_report(world[:, feet_t], world[:, body], fps), "matched": len(matched),
              "unmatched": [n for j, n in enumerate(sk.names) if sk.channels[j] and j not in slot],
              "height_scale": float(scale)}
    return Retargeted(motion, world, tuple(matched), report)


def describe(report: dict, rig: rigs.Rig) -> str:
    """One line for generate.py's notes: what was matched, and the feet beside the source's."""
    s, t = report["source"], report["retargeted"]
    un = report["unmatched"]
    rest = f"; {len(un)} keep their rest rotation: {', '.join(un[:6])}{', ...' if len(un) > 6 else ''}" if un else ""
    return (f"retargeted onto {rig.name} ({rig.map_name} names, {report['matched']} joints matched{rest}"
            f"): foot skate {t['skate_cm_s']:.1f} cm/s (the model's skeleton: {s['skate_cm_s']:.1f}), floor "
            f"penetration {t['penetration_mean_cm']:.2f} cm mean, {t['penetration_max_cm']:.1f} cm deepest "
            f"(model's: {s['penetration_mean_cm']:.2f}, {s['penetration_max_cm']:.1f})")
