"""Rigs: a skeleton's joints named by what they are (roles), the built-in name maps, the user's
JSON map, and a few skeletons of our own to retarget onto.

A *role* is an anatomical point (`ROLES`): the pelvis, the left knee, the tip of the right toes, ...
A rig's joints are matched to roles by name through the built-in maps (`NAME_MAPS`: the Bandai
and CMU skeletons, Mixamo's `mixamorig:` names, SMPL's 24 joints), the one matching most roles
winning, and a user's JSON map (`{"left_knee": "Knee.L", "spine": null, ...}`) overriding it role by
role (null: leave that role unmatched). Names are compared without a namespace (`mixamorig:Hips`,
`mixamorig1:Hips` and `Hips` are the same) and without case. A matched joint that sits on its matched
parent in the rest pose has no direction and is left unmatched. A rig must match `REQUIRED`, the
pelvis and both legs (hip, knee, ankle); `RigError` names what is missing otherwise.

Rest pose: a BVH skeleton's OFFSETs with every rotation zero, so at rest every joint's frame is the
world's; a rig may stand in a T-pose, an A-pose or face another way (retargeting works on world
directions). Units: metres per file unit, guessed from the leg (`representation.guess_units_to_m`)
unless given.

The built-in rigs (`BUILTIN_RIGS`, `builtin_rig`) are skeletons made here with those joint names
and their own proportions, for the demo's rig picker and for trying `--rig` without a file.
"""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path

import numpy as np

from motiongan_jax.motion import bvh, representation

_SIDED = ("hip", "knee", "ankle", "toe", "toe_end", "clavicle", "shoulder", "elbow", "wrist", "hand_end")
ROLES: tuple[str, ...] = (("pelvis", "spine", "chest", "neck", "head", "head_end")
                          + tuple(f"{s}_{r}" for s in ("left", "right") for r in _SIDED))
REQUIRED = ("pelvis", "left_hip", "left_knee", "left_ankle", "right_hip", "right_knee", "right_ankle")
_MIN_BONE_M = 1e-4  # a matched joint this close to its matched parent at rest has no direction


class RigError(ValueError):
    """A rig that cannot be used (unreadable, legs not matched, a bad map); the message says why."""


def _sided(left: dict[str, list[str]], mirror) -> dict[str, list[str]]:
    out = {}
    for role, names in left.items():
        out[f"left_{role}"] = names
        out[f"right_{role}"] = [mirror(n) for n in names]
    return out


def _lr(name: str) -> str:  # LeftArm -> RightArm, LThumb -> RThumb
    return name.replace("Left", "Right") if "Left" in name else "R" + name[1:]


# Candidate joint names per role, first found wins (compared without namespace and case).
NAME_MAPS: dict[str, dict[str, list[str]]] = {
    "cmu": {"pelvis": ["Hips"], "spine": ["Spine"], "chest": ["Spine1"], "neck": ["Neck1"], "head": ["Head"],
            "head_end": ["Head_EndSite"],
            **_sided({"hip": ["LeftUpLeg"], "knee": ["LeftLeg"], "ankle": ["LeftFoot"], "toe": ["LeftToeBase"],
                      "toe_end": ["LeftToeBase_EndSite"], "shoulder": ["LeftArm"], "elbow": ["LeftForeArm"],
                      "wrist": ["LeftHand"], "hand_end": ["LeftHandIndex1"]}, _lr)},
    # CMU's walks as converted with anatomical names (LeftHip, LeftKnee, ...; e.g. subject 131's)
    "cmu_anatomical": {"pelvis": ["Hips"], "spine": ["lowerback"], "chest": ["Chest2", "Chest"],
                       "neck": ["Neck", "lowerneck"], "head": ["Head"], "head_end": ["Head_EndSite"],
                       **_sided({"hip": ["LeftHip"], "knee": ["LeftKnee"], "ankle": ["LeftAnkle"], "toe": ["LeftToe"],
                                 "toe_end": ["LeftToe_EndSite"], "clavicle": ["LeftCollar"],
                                 "shoulder": ["LeftShoulder"], "elbow": ["LeftElbow"], "wrist": ["LeftWrist"],
                                 "hand_end": ["lhand", "LeftWrist_EndSite"]}, _lr)},
    "bandai": {"pelvis": ["Hips"], "spine": ["Spine"], "chest": ["Chest"], "neck": ["Neck"], "head": ["Head"],
               "head_end": ["Head_EndSite"],
               **_sided({"hip": ["UpperLeg_L"], "knee": ["LowerLeg_L"], "ankle": ["Foot_L"], "toe": ["Toes_L"],
                         "toe_end": ["Toes_L_EndSite"], "clavicle": ["Shoulder_L"], "shoulder": ["UpperArm_L"],
                         "elbow": ["LowerArm_L"], "wrist": ["Hand_L"], "hand_end": ["Hand_L_EndSite"]},
                        lambda n: n.replace("_L", "_R"))},
    "mixamo": {"pelvis": ["Hips"], "spine": ["Spine"], "chest": ["Spine2", "Spine1"], "neck": ["Neck"],
               "head": ["Head"], "head_end": ["HeadTop_End", "Head_EndSite"],
               **_sided({"hip": ["LeftUpLeg"], "knee": ["LeftLeg"], "ankle": ["LeftFoot"], "toe": ["LeftToeBase"],
                         "toe_end": ["LeftToe_End", "LeftToeBase_EndSite"], "clavicle": ["LeftShoulder"],
                         "shoulder": ["LeftArm"], "elbow": ["LeftForeArm"], "wrist": ["LeftHand"],
                         "hand_end": ["LeftHandMiddle1", "LeftHandIndex1", "LeftHand_EndSite"]}, _lr)},
    "smpl": {"pelvis": ["pelvis"], "spine": ["spine1"], "chest": ["spine3"], "neck": ["neck"], "head": ["head"],
             "head_end": ["head_EndSite"],
             **_sided({"hip": ["left_hip", "L_Hip"], "knee": ["left_knee", "L_Knee"],
                       "ankle": ["left_ankle", "L_Ankle"], "toe": ["left_foot", "L_Foot"],
                       "toe_end": ["left_foot_EndSite", "L_Foot_EndSite"], "clavicle": ["left_collar", "L_Collar"],
                       "shoulder": ["left_shoulder", "L_Shoulder"], "elbow": ["left_elbow", "L_Elbow"],
                       "wrist": ["left_wrist", "L_Wrist"], "hand_end": ["left_hand", "L_Hand"]},
                      lambda n: n.replace("left", "right").replace("L_", "R_"))},
}


def plain_name(name: str) -> str:
    """A joint name without its namespace ("mixamorig:Hips" -> "hips"), lower case."""
    return name.rsplit(":", 1)[-1].strip().lower()


def _describe(role: str) -> str:
    return role.replace("_", " ")


@dataclasses.dataclass(frozen=True, eq=False)
class Rig:
    name: str  # the built-in rig's name or the file's
    skeleton: bvh.Skeleton  # OFFSETs in file units; rest pose = zero rotations
    units_to_m: float  # metres per file unit
    roles: dict  # role -> joint index, only matched roles
    map_name: str  # the built-in map that matched ("user" when a JSON map set any role)
    frame_time: float = 1.0 / 30.0

    @property
    def joint_roles(self) -> dict[int, str]:
        return {j: r for r, j in self.roles.items()}

    def rest_world_m(self) -> np.ndarray:
        """(J, 3) rest-pose world positions in metres."""
        return rest_world(self.skeleton) * self.units_to_m

    def unmatched(self) -> list[str]:
        """Joints (End Sites excluded) that no role names: they keep their rest rotation."""
        used = set(self.roles.values())
        return [n for j, n in enumerate(self.skeleton.names) if j not in used and self.skeleton.channels[j]]


def rest_world(skeleton: bvh.Skeleton) -> np.ndarray:
    """(J, 3) rest-pose world positions in file units (every rotation zero: offsets summed)."""
    pos = np.zeros((skeleton.num_joints, 3))
    for j, p in enumerate(skeleton.parents):
        pos[j] = (pos[p] if p >= 0 else 0.0) + skeleton.offsets[j]
    return pos


def match_roles(names, name_map: dict[str, list[str]]) -> dict[str, int]:
    """role -> joint index for every role of `name_map` whose candidates name a joint."""
    index = {}
    for j, n in enumerate(names):
        index.setdefault(plain_name(n), j)
    out = {}
    for role, candidates in name_map.items():
        for c in candidates:
            j = index.get(plain_name(c))
            if j is not None:
                out[role] = j
                break
    return out


def detect_roles(skeleton: bvh.Skeleton) -> tuple[str, dict[str, int]]:
    """(map name, role -> joint index) of the built-in map that matches the most roles with a rest
    direction (CMU's zero-length Neck and LeftShoulder do not count)."""
    found = {k: _directed(skeleton, match_roles(skeleton.names, m), 0.0) for k, m in NAME_MAPS.items()}
    best = max(found, key=lambda k: len(found[k]))
    return best, found[best]


def _directed(skeleton: bvh.Skeleton, roles: dict, min_length: float) -> dict:
    """`roles` without the joints within `min_length` (file units) of their nearest matched
    ancestor in the rest pose."""
    rest = rest_world(skeleton)
    roles = dict(roles)
    for role in sorted(roles, key=lambda r: roles[r]):
        j = roles[role]
        used = set(roles.values())
        anc = skeleton.parents[j]
        while anc >= 0 and anc not in used:
            anc = skeleton.parents[anc]
        if anc >= 0 and np.linalg.norm(rest[j] - rest[anc]) <= min_length:
            roles.pop(role)
    return roles


def read_map(path) -> dict[str, str | None]:
    """A user's JSON map: an object of role -> joint name (or null). RigError naming the problem."""
    try:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
    except OSError as e:
        raise RigError(f"rig map {path}: cannot read it ({e.strerror or e})") from None
    except ValueError as e:
        raise RigError(f"rig map {path}: not valid JSON: {e}") from None
    if not isinstance(data, dict):
        raise RigError(f"rig map {path}: expected a JSON object of role -> joint name, got {type(data).__name__}")
    unknown = sorted(k for k in data if k not in ROLES)
    if unknown:
        raise RigError(f"rig map {path}: unknown role(s) {', '.join(map(repr, unknown))}; the roles are "
                       f"{', '.join(ROLES)}")
    bad = sorted(k for k, v in data.items() if v is not None and not isinstance(v, str))
    if bad:
        raise RigError(f"rig map {path}: the value of {', '.join(map(repr, bad))} must be a joint name or null")
    return data


def resolve_roles(skeleton: bvh.Skeleton, user_map: dict | None = None, where: str = "rig") -> tuple[str, dict]:
    """(map name, role -> joint index) of a skeleton: the best built-in map, overridden by `user_map`;
    matched joints without a rest direction dropped; RigError when the legs are not all matched."""
    names = skeleton.names
    map_name, roles = detect_roles(skeleton)
    if user_map:
        index = {n: j for j, n in enumerate(names)}
        plain = {}
        for j, n in enumerate(names):
            plain.setdefault(plain_name(n), j)
        for role, joint in user_map.items():
            if joint is None:
                roles.pop(role, None)
                continue
            j = index.get(joint, plain.get(plain_name(joint)))
            if j is None:
                raise RigError(f"{where}: the map names joint {joint!r} for {role}, but the rig has no such joint")
            roles[role] = j
        map_name = "user"
        twice = {j for j in roles.values() if list(roles.values()).count(j) > 1}
        if twice:
            raise RigError(f"{where}: the map names joint(s) {', '.join(repr(names[j]) for j in sorted(twice))} "
                           "for more than one role")
    missing = [r for r in REQUIRED if r not in roles]
    if missing:
        raise RigError(f"{where}: cannot match its legs: no joint for {', '.join(_describe(r) for r in missing)} "
                       f"(best built-in map: {map_name}; joints: {', '.join(names[:40])}"
                       f"{', ...' if len(names) > 40 else ''}); name them in a JSON map (--rig-map)")
    pelvis = roles["pelvis"]
    outside = [r for r, j in roles.items() if j != pelvis and not descends(skeleton.parents, j, pelvis)]
    for r in outside:
        if r in REQUIRED:
            raise RigError(f"{where}: the {_describe(r)} ({names[roles[r]]}) is not below the pelvis "
                           f"({names[pelvis]})")
        roles.pop(r)
    return map_name, roles


def descends(parents, j: int, ancestor: int) -> bool:
    while j >= 0:
        j = parents[j]
        if j == ancestor:
            return True
    return False


def drop_degenerate(skeleton: bvh.Skeleton, roles: dict, units_to_m: float) -> dict:
    """`roles` without the matched joints that sit on their nearest matched ancestor at rest (no
    direction to give them); RigError if that leaves a leg unmatched."""
    kept = _directed(skeleton, roles, _MIN_BONE_M / units_to_m)
    lost = [r for r in REQUIRED if r in roles and r not in kept]
    if lost:
        raise RigError(f"the {', '.join(f'{_describe(r)} ({skeleton.names[roles[r]]})' for r in lost)} sit(s) on "
                       "the joint above in the rest pose: no bone to aim")
    return kept


UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001, "inch": 0.0254}


def make_rig(skeleton: bvh.Skeleton, name: str, *, units_to_m: float | None = None, user_map: dict | None = None,
             frame_time: float = 1.0 / 30.0) -> Rig:
    """A Rig from a skeleton: roles resolved (`resolve_roles`), units guessed from the leg unless given."""
    map_name, roles = resolve_roles(skeleton, user_map, f"rig {name}")
    if units_to_m is None:
        try:
            units_to_m = representation.guess_units_to_m(skeleton)
        except ValueError as e:
            raise RigError(f"rig {name}: {e}") from None
    roles = drop_degenerate(skeleton, roles, units_to_m)
    return Rig(name, skeleton, float(units_to_m), roles, map_name, frame_time)


def load_rig(spec: str, *, map_path=None, units: str | float | None = None) -> Rig:
    """A built-in rig by name (`BUILTIN_RIGS`) or a BVH file's skeleton, with an optional JSON map
    and units ("m", "cm", "mm", "inch" or metres per unit; default: guessed). RigError when unusable."""
    user_map = read_map(map_path) if map_path else None
    if isinstance(units, str):
        if units not in UNITS:
            try:
                units = float(units)
            except ValueError:
                raise RigError(f"rig units must be one of {', '.join(UNITS)} or metres per unit, got {units!r}") \
                    from None
        else:
            units = UNITS[units]
    if units is not None and not (np.isfinite(units) and units > 0):
        raise RigError(f"rig units must be > 0 metres per unit, got {units}")
    if spec in BUILTIN_RIGS:
        skeleton, default_units = builtin_skeleton(spec)
        return make_rig(skeleton, spec, units_to_m=units or default_units, user_map=user_map)
    path = Path(spec)
    if path.suffix.lower() != ".bvh" or not path.exists():
        if path.suffix.lower() == ".bvh":
            raise RigError(f"rig {spec}: no such file")
        raise RigError(f"rig {spec!r}: not a built-in rig ({', '.join(BUILTIN_RIGS)}) or a .bvh file")
    try:
        motion = bvh.read_bvh(path)
    except bvh.BVHError as e:
        raise RigError(f"rig {e}") from None
    except OSError as e:
        raise RigError(f"rig {spec}: cannot read it ({e.strerror or e})") from None
    return make_rig(motion.skeleton, os.path.basename(spec), units_to_m=units, user_map=user_map,
                    frame_time=motion.frame_time)


# ---------------------------------------------------------------------------------------------
# Built-in rigs: our own skeletons with the common rigs' joint names


def _skeleton(table, root_channels=("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation"),
              rot=("Zrotation", "Xrotation", "Yrotation")) -> bvh.Skeleton:
    """A Skeleton from (name, parent name, offset) rows in depth-first order; names ending in
    "_EndSite" are End Sites."""
    names = [r[0] for r in table]
    idx = {n: i for i, n in enumerate(names)}
    parents = tuple(-1 if r[1] is None else idx[r[1]] for r in table)
    channels = tuple(() if r[0].endswith("_EndSite") else (root_channels if r[1] is None else rot) for r in table)
    return bvh.Skeleton(tuple(names), parents, np.array([r[2] for r in table], np.float64), channels)


def _mirror(rows, rename):
    return [(rename(n), None if p is None else rename(p), (-o[0], o[1], o[2])) for n, p, o in rows]


def _mixamo() -> bvh.Skeleton:
    """A Mixamo-named skeleton in an A-pose (arms 45 degrees down), centimetres, 1.80 m tall."""
    s = np.sqrt(0.5)
    left_leg = [("mixamorig:LeftUpLeg", "mixamorig:Hips", (9.5, -6.0, 0.5)),
                ("mixamorig:LeftLeg", "mixamorig:LeftUpLeg", (0.0, -45.0, 0.5)),
                ("mixamorig:LeftFoot", "mixamorig:LeftLeg", (0.0, -43.0, -2.0)),
                ("mixamorig:LeftToeBase", "mixamorig:LeftFoot", (0.0, -7.0, 14.0)),
                ("mixamorig:LeftToe_End", "mixamorig:LeftToeBase", (0.0, 0.0, 7.0)),
                ("mixamorig:LeftToe_End_EndSite", "mixamorig:LeftToe_End", (0.0, 0.0, 2.0))]
    left_arm = [("mixamorig:LeftShoulder", "mixamorig:Spine2", (6.0, 11.0, -1.0)),
                ("mixamorig:LeftArm", "mixamorig:LeftShoulder", (13.0, 0.0, 0.0)),
                ("mixamorig:LeftForeArm", "mixamorig:LeftArm", (28.0 * s, -28.0 * s, 0.0)),
                ("mixamorig:LeftHand", "mixamorig:LeftForeArm", (26.0 * s, -26.0 * s, 0.0)),
                ("mixamorig:LeftHandMiddle1", "mixamorig:LeftHand", (9.0 * s, -9.0 * s, 0.0)),
                ("mixamorig:LeftHandMiddle1_EndSite", "mixamorig:LeftHandMiddle1", (8.0 * s, -8.0 * s, 0.0))]

    def rl(n):
        return n.replace("Left", "Right")

    rows = ([("mixamorig:Hips", None, (0.0, 100.0, 0.0))] + left_leg + _mirror(left_leg, rl)
            + [("mixamorig:Spine", "mixamorig:Hips", (0.0, 10.0, 0.0)),
               ("mixamorig:Spine1", "mixamorig:Spine", (0.0, 12.0, 0.0)),
               ("mixamorig:Spine2", "mixamorig:Spine1", (0.0, 13.0, 0.0))]
            + left_arm + _mirror(left_arm, rl)
            + [("mixamorig:Neck", "mixamorig:Spine2", (0.0, 16.0, 0.0)),
               ("mixamorig:Head", "mixamorig:Neck", (0.0, 10.0, 1.5)),
               ("mixamorig:HeadTop_End", "mixamorig:Head", (0.0, 19.0, 0.0)),
               ("mixamorig:HeadTop_End_EndSite", "mixamorig:HeadTop_End", (0.0, 1.0, 0.0))])
    # BVH order is depth first: the arms hang from Spine2, which comes after the spine rows above
    order = ["mixamorig:Hips"] + [r[0] for r in left_leg] + [rl(r[0]) for r in left_leg]
    order += ["mixamorig:Spine", "mixamorig:Spine1", "mixamorig:Spine2", "mixamorig:Neck", "mixamorig:Head",
              "mixamorig:HeadTop_End", "mixamorig:HeadTop_End_EndSite"]
    order += [r[0] for r in left_arm] + [rl(r[0]) for r in left_arm]
    by = {r[0]: r for r in rows}
    return _skeleton([by[n] for n in order])


def _smpl() -> bvh.Skeleton:
    """SMPL's 24 joints in its order and T-pose, metres, our own round proportions (1.70 m)."""
    rows = [("pelvis", None, (0.0, 0.93, 0.0)),
            ("left_hip", "pelvis", (0.06, -0.09, 0.0)), ("left_knee", "left_hip", (0.04, -0.38, 0.0)),
            ("left_ankle", "left_knee", (-0.01, -0.40, -0.04)), ("left_foot", "left_ankle", (0.02, -0.05, 0.12)),
            ("left_foot_EndSite", "left_foot", (0.0, 0.0, 0.04)),
            ("right_hip", "pelvis", (-0.06, -0.09, 0.0)), ("right_knee", "right_hip", (-0.04, -0.38, 0.0)),
            ("right_ankle", "right_knee", (0.01, -0.40, -0.04)), ("right_foot", "right_ankle", (-0.02, -0.05, 0.12)),
            ("right_foot_EndSite", "right_foot", (0.0, 0.0, 0.04)),
            ("spine1", "pelvis", (0.0, 0.11, -0.01)), ("spine2", "spine1", (0.0, 0.13, 0.01)),
            ("spine3", "spine2", (0.0, 0.05, 0.0)), ("neck", "spine3", (0.0, 0.21, -0.03)),
            ("head", "neck", (0.0, 0.07, 0.05)), ("head_EndSite", "head", (0.0, 0.18, 0.0)),
            ("left_collar", "spine3", (0.07, 0.11, -0.02)), ("left_shoulder", "left_collar", (0.11, 0.04, -0.01)),
            ("left_elbow", "left_shoulder", (0.26, 0.0, 0.0)), ("left_wrist", "left_elbow", (0.25, 0.0, 0.0)),
            ("left_hand", "left_wrist", (0.08, 0.0, 0.0)), ("left_hand_EndSite", "left_hand", (0.08, 0.0, 0.0)),
            ("right_collar", "spine3", (-0.07, 0.11, -0.02)),
            ("right_shoulder", "right_collar", (-0.11, 0.04, -0.01)),
            ("right_elbow", "right_shoulder", (-0.26, 0.0, 0.0)), ("right_wrist", "right_elbow", (-0.25, 0.0, 0.0)),
            ("right_hand", "right_wrist", (-0.08, 0.0, 0.0)), ("right_hand_EndSite", "right_hand", (-0.08, 0.0, 0.0))]
    return _skeleton(rows, rot=("Xrotation", "Yrotation", "Zrotation"),
                     root_channels=("Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation"))


def _bandai() -> bvh.Skeleton:
    """Bandai Namco's joint names (a root on the floor above the hips), T-pose, centimetres, 1.65 m."""
    def leg(s, x):
        return [(f"UpperLeg_{s}", "Hips", (x * 9.0, -5.0, 0.0)), (f"LowerLeg_{s}", f"UpperLeg_{s}", (0.0, -41.0, 0.0)),
                (f"Foot_{s}", f"LowerLeg_{s}", (0.0, -39.0, -1.0)), (f"Toes_{s}", f"Foot_{s}", (0.0, -6.0, 13.0)),
                (f"Toes_{s}_EndSite", f"Toes_{s}", (0.0, 0.0, 6.0))]

    def arm(s, x):
        return [(f"Shoulder_{s}", "Chest", (x * 3.0, 17.0, 0.0)),
                (f"UpperArm_{s}", f"Shoulder_{s}", (x * 14.0, 0.0, 0.0)),
                (f"LowerArm_{s}", f"UpperArm_{s}", (x * 26.0, 0.0, 0.0)),
                (f"Hand_{s}", f"LowerArm_{s}", (x * 24.0, 0.0, 0.0)),
                (f"Hand_{s}_EndSite", f"Hand_{s}", (x * 15.0, 0.0, 0.0))]

    rows = ([("joint_Root", None, (0.0, 0.0, 0.0)), ("Hips", "joint_Root", (0.0, 91.0, 0.0)),
             ("Spine", "Hips", (0.0, 10.0, 0.0)), ("Chest", "Spine", (0.0, 17.0, 0.0)),
             ("Neck", "Chest", (0.0, 22.0, 0.0)), ("Head", "Neck", (0.0, 9.0, 1.0)),
             ("Head_EndSite", "Head", (0.0, 16.0, 0.0))]
            + arm("L", 1.0) + arm("R", -1.0) + leg("L", 1.0) + leg("R", -1.0))
    return _skeleton(rows, rot=("Zrotation", "Yrotation", "Xrotation"),
                     root_channels=("Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation"))


# name -> (skeleton maker, metres per unit, one line for the picker)
BUILTIN_RIGS = {
    "mixamo": (_mixamo, 0.01, "Mixamo names (mixamorig:), A-pose, 1.80 m, centimetres"),
    "smpl": (_smpl, 1.0, "SMPL's 24 joints, T-pose, 1.70 m, metres"),
    "bandai": (_bandai, 0.01, "Bandai Namco names, T-pose, 1.65 m, centimetres"),
}


def builtin_skeleton(name: str) -> tuple[bvh.Skeleton, float]:
    """(skeleton, metres per unit) of a built-in rig; RigError for an unknown name."""
    if name not in BUILTIN_RIGS:
        raise RigError(f"unknown rig {name!r}; the built-in rigs are {', '.join(BUILTIN_RIGS)}")
    make, units, _ = BUILTIN_RIGS[name]
    return make(), units
