"""motion.rigs and motion.retarget: joints matched by name, a walk on skeletons of other
proportions and rest poses, feet kept planted, rigs that cannot be used refused (and
generate.py's --rig errors). The rigs are built here: a Mixamo-named skeleton in an A-pose with
other proportions, the project's CMU-named skeleton, one without a right leg, one needing a map."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import run_cli, toy_walk

from motiongan_jax.data import synthetic
from motiongan_jax.motion import bvh, kinematics, representation, retarget, rigs

FPS = 15.0


@pytest.fixture(scope="module")
def walk():
    return toy_walk()


def mixamo_bvh(arm_down_deg: float = 45.0, drop: tuple[str, ...] = (), rename=lambda n: n) -> str:
    """A Mixamo-named skeleton (mixamorig: names, centimetres) with long legs and short arms, an
    unmatched thigh twist leaf and finger chain, arms `arm_down_deg` below horizontal (45: A-pose)."""
    a = np.radians(arm_down_deg)
    arm = lambda L: (L * np.cos(a), -L * np.sin(a), 0.0)  # noqa: E731
    rows = [("Hips", None, (0, 104, 0)),
            ("LeftUpLeg", "Hips", (10, -7, 0)), ("LeftUpLegTwist", "LeftUpLeg", (0, -20, 0)),
            ("LeftLeg", "LeftUpLeg", (0, -50, 1)), ("LeftFoot", "LeftLeg", (0, -47, -2)),
            ("LeftToeBase", "LeftFoot", (0, -7, 15)), ("LeftToe_End", "LeftToeBase", (0, 0, 8)),
            ("RightUpLeg", "Hips", (-10, -7, 0)), ("RightLeg", "RightUpLeg", (0, -50, 1)),
            ("RightFoot", "RightLeg", (0, -47, -2)), ("RightToeBase", "RightFoot", (0, -7, 15)),
            ("RightToe_End", "RightToeBase", (0, 0, 8)),
            ("Spine", "Hips", (0, 9, 0)), ("Spine1", "Spine", (0, 11, 0)), ("Spine2", "Spine1", (0, 12, 0)),
            ("Neck", "Spine2", (0, 15, 0)), ("Head", "Neck", (0, 9, 2)), ("HeadTop_End", "Head", (0, 20, 0)),
            ("LeftShoulder", "Spine2", (5, 10, 0)), ("LeftArm", "LeftShoulder", (12, 0, 0)),
            ("LeftForeArm", "LeftArm", arm(24)), ("LeftHand", "LeftForeArm", arm(22)),
            ("LeftHandIndex1", "LeftHand", arm(8)), ("LeftHandIndex2", "LeftHandIndex1", arm(3)),
            ("RightShoulder", "Spine2", (-5, 10, 0)), ("RightArm", "RightShoulder", (-12, 0, 0)),
            ("RightForeArm", "RightArm", (-arm(24)[0], arm(24)[1], 0)),
            ("RightHand", "RightForeArm", (-arm(22)[0], arm(22)[1], 0))]
    for n, p, _ in list(rows):  # the dropped joints and everything below them (rows are parents first)
        if p in drop:
            drop = drop + (n,)
    rows = [r for r in rows if r[0] not in drop]
    kids = {}
    for n, p, _ in rows:
        kids.setdefault(p, []).append(n)
    out = ["HIERARCHY"]

    def emit(name, offset, depth, root=False):
        ind = "  " * depth
        out.append(f"{ind}{'ROOT' if root else 'JOINT'} {rename('mixamorig:' + name)}")
        out.append(ind + "{")
        out.append(f"{ind}  OFFSET {offset[0]:.6f} {offset[1]:.6f} {offset[2]:.6f}")
        order = "Yrotation Xrotation Zrotation" if name == "Spine1" else "Zrotation Xrotation Yrotation"
        out.append(f"{ind}  CHANNELS {6 if root else 3} " + ("Xposition Yposition Zposition " if root else "") + order)
        for k in kids.get(name, []):
            emit(k, dict((r[0], r[2]) for r in rows)[k], depth + 1)
        if name not in kids:
            out.extend([f"{ind}  End Site", ind + "  {", f"{ind}    OFFSET 0 1 0", ind + "  }"])
        out.append(ind + "}")

    emit("Hips", (0, 104, 0), 0, root=True)
    channels = 6 + 3 * (len(rows) - 1)
    out += ["MOTION", "Frames: 1", "Frame Time: 0.0333333", " ".join(["0"] * channels)]
    return "\n".join(out) + "\n"


def rig_from(text: str, name="rig.bvh", **kw) -> rigs.Rig:
    return rigs.make_rig(bvh.parse_bvh(text, name).skeleton, name, **kw)


def run(walk, rig) -> retarget.Retargeted:
    pos, layout, _ = walk
    return retarget.retarget(pos, layout.joint_names, layout.parents, layout.rest_offsets_m, rig, FPS)


def test_roles_are_found_by_name_without_namespace_or_zero_length_joints():
    rig = rig_from(mixamo_bvh())
    names = rig.skeleton.names
    assert rig.map_name == "mixamo" and rig.units_to_m == 0.01  # the leg says centimetres
    assert names[rig.roles["left_knee"]] == "mixamorig:LeftLeg"
    assert names[rig.roles["chest"]] == "mixamorig:Spine2"
    assert {"mixamorig:LeftUpLegTwist", "mixamorig:Spine1", "mixamorig:LeftHandIndex2"} <= set(rig.unmatched())
    # CMU's names: the zero-length Neck and LeftShoulder are not roles; Neck1 is the neck
    map_name, roles = rigs.detect_roles(synthetic.cmu_skeleton())
    cmu = synthetic.cmu_skeleton().names
    assert map_name == "cmu" and cmu[roles["neck"]] == "Neck1" and "left_clavicle" not in roles


def test_a_walk_on_a_rig_of_other_proportions(walk, tmp_path):
    pos, layout, _ = walk
    rig = rig_from(mixamo_bvh())
    r = run(walk, rig)
    names = rig.skeleton.names
    j = {n.split(":")[1]: i for i, n in enumerate(names)}
    src = {n: i for i, n in enumerate(layout.joint_names)}
    # the root path stays on the source's: the pelvis's floor position, frame for frame
    np.testing.assert_allclose(r.positions_m[:, j["Hips"], [0, 2]], pos[:, 0, [0, 2]], atol=1e-9)
    # the file holds the rig's own skeleton and units; its FK is the retargeted walk
    path = tmp_path / "onto.bvh"
    bvh.write_bvh(path, r.motion)
    back = bvh.read_bvh(path)
    np.testing.assert_array_equal(back.skeleton.offsets, rig.skeleton.offsets)
    assert back.skeleton.names == names
    world = kinematics.world_positions(back) * 0.01
    np.testing.assert_allclose(world, r.positions_m, atol=1e-5)
    # bones keep the rig's lengths in every frame
    rest = rig.rest_world_m()
    for c, p in enumerate(rig.skeleton.parents):
        if p >= 0:
            np.testing.assert_allclose(np.linalg.norm(world[:, c] - world[:, p], axis=-1),
                                       np.linalg.norm(rest[c] - rest[p]), atol=1e-5)

    # a joint with one matched child aims along the source's segment between the same roles
    def direction(x, a, b):
        d = x[:, b] - x[:, a]
        return d / np.linalg.norm(d, axis=-1, keepdims=True)

    for (ra, rb), (sa, sb) in {("LeftArm", "LeftForeArm"): ("LeftArm", "LeftForeArm"),
                               ("RightForeArm", "RightHand"): ("RightForeArm", "RightHand"),
                               ("Spine", "Spine2"): ("Spine", "Spine1"),
                               ("Head", "HeadTop_End"): ("Head", "Head_EndSite")}.items():
        np.testing.assert_allclose(direction(r.positions_m, j[ra], j[rb]), direction(pos, src[sa], src[sb]), atol=1e-6)
    # unmatched joints keep their rest rotation: their channels are 0 in every frame
    for name in ("LeftUpLegTwist", "Spine1", "LeftShoulder", "LeftHandIndex2"):
        sl = back.skeleton.channel_slices()[j[name]]
        np.testing.assert_allclose(back.values[:, sl], 0.0, atol=1e-6)
    # the feet: the balls of the rig's feet where the source's are, heights scaled by the standing
    # pelvis heights (1.11 m over the rig's toes, the source's over its own lowest joint)
    src_rest = np.zeros((len(layout.parents), 3))
    for k, p in enumerate(layout.parents):
        if p >= 0:
            src_rest[k] = src_rest[p] + layout.rest_offsets_m[k]
    scale = 1.11 / (src_rest[0, 1] - src_rest[:, 1].min())
    for side in ("Left", "Right"):
        np.testing.assert_allclose(r.positions_m[:, j[f"{side}ToeBase"]],
                                   pos[:, src[f"{side}ToeBase"]] * [1.0, scale, 1.0], atol=1e-6)
    assert r.report["retargeted"]["penetration_max_cm"] < 1.0  # its toe tips, longer than the source's


def test_t_pose_or_a_pose_rig_walks_the_same(walk):
    a_pose, t_pose = rig_from(mixamo_bvh(45.0)), rig_from(mixamo_bvh(0.0))
    ra, rt = run(walk, a_pose), run(walk, t_pose)
    matched = list(a_pose.roles.values())  # unmatched joints keep their rest rotations, which differ
    np.testing.assert_allclose(ra.positions_m[:, matched], rt.positions_m[:, matched], atol=1e-6)
    arm = ra.motion.skeleton.names.index("mixamorig:LeftArm")
    sl = ra.motion.skeleton.channel_slices()[arm]
    # ... through other rotations: the A-pose's arm starts 45 degrees lower
    assert np.abs(ra.motion.values[:, sl] - rt.motion.values[:, sl]).max() > 20


def test_its_own_skeleton_gives_the_walk_back(walk, tmp_path):
    """The CMU fixture: retargeting onto the skeleton the walk was made on (read from a BVH file
    in its own CMU units) reproduces the walk; its feet were planted, so pinning moves nothing."""
    pos, layout, motion = walk
    path = tmp_path / "cmu.bvh"
    bvh.write_bvh(path, motion)
    rig = rigs.load_rig(str(path))
    assert rig.map_name == "cmu" and abs(rig.units_to_m - synthetic.UNITS_TO_M) < 1e-12
    r = run(walk, rig)
    kept = r.positions_m[:, list(layout.source_index)]
    thumbs = [i for i, n in enumerate(layout.joint_names) if "Thumb" in n]  # unmatched: at rest, not posed
    others = [i for i in range(len(layout.joint_names)) if i not in thumbs]
    np.testing.assert_allclose(kept[:, others], pos[:, others], atol=2e-3)
    assert r.report["source"]["skate_cm_s"] < 0.5 and r.report["retargeted"]["skate_cm_s"] < 3.0


def test_feet_stay_planted_on_longer_legs(walk):
    pos, layout, _ = walk
    rig = rig_from(mixamo_bvh())
    r = run(walk, rig)
    toe = rig.roles["left_toe"]
    planted = retarget.contacts(pos[:, [4, 4]], FPS)[:, 0]  # the source's left toe
    stances = retarget._stances(planted)
    assert len(stances) >= 2
    for a, b in stances:
        track = r.positions_m[a:b, toe, [0, 2]]
        assert np.abs(track - track.mean(axis=0)).max() < 0.01, (a, b)


def test_pin_feet_and_two_bone_ik_by_hand():
    point = np.zeros((10, 3))
    point[:, 0] = np.arange(10) * 0.1  # a point moving 0.1 m per frame along x, rising 1 cm per frame
    point[:, 1] = np.arange(10) * 0.01
    planted = np.array([0, 0, 0, 1, 1, 1, 1, 0, 0, 0], bool)
    goal = retarget.pin_feet(point, planted)
    np.testing.assert_allclose(goal[3:7, 0], 0.45)  # the stance's mean
    # the corrections at the stance's ends (+0.15 before, -0.15 after) fade by thirds
    np.testing.assert_allclose(goal[[1, 2, 7, 8, 9], 0], [0.1 + 0.05, 0.2 + 0.1, 0.7 - 0.1, 0.8 - 0.05, 0.9])
    np.testing.assert_allclose(goal[:, [1, 2]], point[:, [1, 2]])  # heights its own
    hip, knee = np.array([[0.0, 1.0, 0.0]]), np.array([[0.0, 0.5, 0.3]])
    k, a = retarget.two_bone(hip, knee, np.array([[0.0, 0.2, 0.0]]), 0.5, 0.5)
    np.testing.assert_allclose(a, [[0.0, 0.2, 0.0]], atol=1e-12)
    np.testing.assert_allclose(k, [[0.0, 0.6, 0.3]], atol=1e-12)  # 0.4 down, 0.3 forward: a 3-4-5 triangle
    k, a = retarget.two_bone(hip, knee, np.array([[0.0, -1.0, 0.0]]), 0.5, 0.5)  # out of reach: straight
    np.testing.assert_allclose(a, [[0.0, 0.0, 0.0]], atol=1e-5)


def test_a_rig_missing_a_leg_is_refused(tmp_path, capsys):
    text = mixamo_bvh(drop=("RightUpLeg",))
    with pytest.raises(rigs.RigError, match="cannot match its legs: no joint for right hip, right knee, right ankle"):
        rig_from(text)
    path = tmp_path / "one_leg.bvh"
    path.write_text(text)
    out = tmp_path / "walk.glb"
    code, _, err = run_cli("generate", ["--style", "Normal", "--curve", "line", "--rig", path, "--out", out])
    assert code == 2 and "right hip, right knee, right ankle" in err and "Traceback" not in err
    assert not out.exists()


def test_a_json_map_names_what_the_built_in_maps_cannot(walk, tmp_path):
    odd = {"Hips": "pelvis_jnt", "LeftUpLeg": "thigh.L", "LeftLeg": "shin.L", "LeftFoot": "foot.L",
           "RightUpLeg": "thigh.R", "RightLeg": "shin.R", "RightFoot": "foot.R"}
    text = mixamo_bvh(rename=lambda n: odd.get(n.split(":")[1], n))
    with pytest.raises(rigs.RigError, match="no joint for pelvis, left hip"):
        rig_from(text)
    path = tmp_path / "map.json"
    path.write_text(json.dumps({"pelvis": "pelvis_jnt", "left_hip": "thigh.L", "left_knee": "shin.L",
                                "left_ankle": "foot.L", "right_hip": "thigh.R", "right_knee": "shin.R",
                                "right_ankle": "foot.R", "left_toe": None}))
    rig = rig_from(text, user_map=rigs.read_map(path))
    assert rig.map_name == "user" and "left_toe" not in rig.roles and "right_toe" in rig.roles
    r = run(walk, rig)
    np.testing.assert_allclose(r.positions_m[:, rig.roles["pelvis"], [0, 2]], walk[0][:, 0, [0, 2]], atol=1e-9)


@pytest.mark.parametrize("content, match", [
    ("{not json", "not valid JSON"),
    ("[1, 2]", "expected a JSON object"),
    ('{"left_kne": "x"}', "unknown role\\(s\\) 'left_kne'"),
    ('{"left_knee": 3}', "must be a joint name or null"),
    ('{"left_knee": "NoSuchJoint"}', "names joint 'NoSuchJoint' for left_knee, but the rig has no such joint"),
    ('{"left_knee": "mixamorig:Hips"}', "for more than one role"),
])
def test_bad_maps_are_clear_errors(tmp_path, content, match):
    (tmp_path / "rig.bvh").write_text(mixamo_bvh())
    (tmp_path / "map.json").write_text(content)
    with pytest.raises(rigs.RigError, match=match):
        rigs.load_rig(str(tmp_path / "rig.bvh"), map_path=tmp_path / "map.json")


@pytest.mark.parametrize("rig, extra, match", [
    ("nope", [], "rig 'nope': not a built-in rig \\(mixamo, smpl, bandai\\) or a .bvh file"),
    ("BAD", [], "bad.bvh:3: OFFSET needs 3 values"),
    ("MISSING", [], "missing.bvh: no such file"),
    ("mixamo", ["--rig-units", "furlong"], "rig units must be one of m, cm, mm, inch"),
    ("mixamo", ["--rig-map", "MAP"], "not valid JSON"),
    ("mixamo", ["--out", "walk.npz"], "is written as .bvh, .glb, .gltf, not .npz"),
])
def test_cli_rig_errors_exit_2_and_write_nothing(tmp_path, rig, extra, match):
    (tmp_path / "bad.bvh").write_text("HIERARCHY\nROOT Hips\n{ OFFSET 0 0\n")
    (tmp_path / "map.json").write_text("{oops")
    paths = {"BAD": tmp_path / "bad.bvh", "MISSING": tmp_path / "missing.bvh", "MAP": tmp_path / "map.json"}
    extra = [str(paths.get(x, x)) for x in extra]
    if "--out" not in extra:
        extra += ["--out", str(tmp_path / "walk.bvh")]
    else:
        extra[extra.index("--out") + 1] = str(tmp_path / extra[extra.index("--out") + 1])
    before = set(tmp_path.iterdir())
    code, _, err = run_cli("generate", ["--style", "Normal", "--curve", "line", "--rig", str(paths.get(rig, rig)),
                                        *extra])
    assert code == 2 and err.startswith("error: ") and "Traceback" not in err
    assert __import__("re").search(match, err), err
    assert set(tmp_path.iterdir()) == before


def test_built_in_rigs_take_the_walk():
    for name in rigs.BUILTIN_RIGS:
        rig = rigs.load_rig(name)
        assert set(rigs.REQUIRED) <= set(rig.roles), name
        height = np.ptp(rig.rest_world_m()[:, 1])
        assert 1.5 < height < 1.9, (name, height)


def directed(layout, rig) -> list[int]:
    """The source joints whose positions the rig's bone directions define: joints of a role the rig
    has, every role on their way up to the pelvis one the rig has too (CMU's unmatched thumbs are
    not; through a rig without clavicles neither are the shoulders of a skeleton with them)."""
    roles = retarget.source_roles(layout.joint_names, layout.parents, layout.rest_offsets_m)
    role_of = {j: r for r, j in roles.items()}
    out = []
    for j in range(len(layout.joint_names)):
        chain, a = [], j
        while a >= 0:
            chain.append(a)
            a = layout.parents[a]
        if j in role_of and all(role_of[c] in rig.roles for c in chain if c in role_of):
            out.append(j)
    return out


def round_trip(pos, layout, home, rig, fps=FPS):
    """(the walk on `rig`, the walk taken back onto `home` as positions of the source's joints)."""
    there = retarget.retarget(pos, layout.joint_names, layout.parents, layout.rest_offsets_m, rig, fps)
    sk = rig.skeleton
    back = retarget.retarget(there.positions_m, sk.names, sk.parents, sk.offsets * rig.units_to_m, home, fps)
    return there, back.positions_m[:, list(layout.source_index)]


def home_rig(source, motion):
    return rigs.make_rig(motion.skeleton, source, units_to_m=synthetic.UNITS_TO_M if source == "cmu" else 0.01)


@pytest.mark.parametrize("source, name",
                         [("bandai", n) for n in rigs.BUILTIN_RIGS] + [("cmu", "mixamo"), ("cmu", "smpl")])
def test_round_trip_keeps_every_joint_within_1_cm(source, name):
    """A walk onto a built-in rig and back onto its own skeleton: every joint the rig's bone
    directions define within 1 cm in every frame (about 2 mm at most: each step inverts where the
    rig's legs reach the walk's footprints). The toy walk's knees stay bent 10 degrees or more, as
    people's do: a straight leg's stride is out of reach of a rig whose legs are short for its
    height, and the next test shows what is lost then. The Bandai rig is the shortest built-in
    one; the CMU skeleton is taller than the Bandai and SMPL rigs."""
    pos, layout, motion = toy_walk(skeleton=source, knee_min_deg=10.0)
    rig = rigs.load_rig(name)
    _, back = round_trip(pos, layout, home_rig(source, motion), rig)
    err = np.linalg.norm(back - pos, axis=-1)
    joints = directed(layout, rig)
    assert len(joints) >= 20
    for j in joints:
        assert err[:, j].max() < 0.01, (layout.joint_names[j], err[:, j].max(), int(err[:, j].argmax()))


@pytest.mark.parametrize("name", list(rigs.BUILTIN_RIGS))
def test_round_trip_loses_only_what_the_rig_cannot_reach(walk, name):
    """The toy walk locks its knees straight in stance. A rig reaches the walk's footprints then
    only where its legs are long enough for the stride at its scaled height; where they are not,
    the rig's leg is at full stretch short of the footprint, the walk taken back bends a straight
    knee to meet that shorter reach, and a millimetre of reach moves a straight leg's knee by
    centimetres. Every other frame keeps every joint within 1 cm. Every built-in rig is short of
    this stride somewhere; the Bandai rig in about half of the frames."""
    pos, layout, motion = walk
    rig = rigs.load_rig(name)
    there, back = round_trip(pos, layout, home_rig("cmu", motion), rig)
    err = np.linalg.norm(back - pos, axis=-1)[:, directed(layout, rig)].max(axis=1)
    rest = rig.rest_world_m()
    stretched = np.zeros(len(pos), bool)
    for side in ("left", "right"):
        h, k, a = (rig.roles[f"{side}_{r}"] for r in ("hip", "knee", "ankle"))
        leg = np.linalg.norm(rest[k] - rest[h]) + np.linalg.norm(rest[a] - rest[k])
        stretched |= np.linalg.norm(there.positions_m[:, a] - there.positions_m[:, h], axis=-1) > leg - 1e-5
    assert err[~stretched].max() < 0.01, np.flatnonzero(err > 0.01)
    if name == "bandai":
        assert 0.3 < stretched.mean() < 0.7 and err[stretched].max() > 0.01


def test_a_skeleton_whose_rest_pose_folds_its_legs_walks_at_its_standing_height():
    """Bandai's files fold the legs sideways at rest (each joint's offsets in a turned frame), so a
    rest pose says nothing of heights; the standing pelvis height then comes from the legs' lengths.
    The Bandai walk with its rest offsets so folded (the same bones, the same walk) goes onto a rig
    at its pelvis height within 3 % of where the skeleton standing at rest puts it, its feet on the
    same footprints."""
    from scipy.spatial.transform import Rotation

    pos, layout, _ = toy_walk(skeleton="bandai", knee_min_deg=10.0)
    turns = Rotation.random(len(layout.parents), random_state=0).as_matrix()
    rest = np.asarray(layout.rest_offsets_m)
    folded = np.array([rest[j] if p < 0 else turns[p] @ rest[j] for j, p in enumerate(layout.parents)])
    src = retarget.source_roles(layout.joint_names, layout.parents, rest)
    folded_world = np.zeros_like(folded)
    for j, p in enumerate(layout.parents):
        folded_world[j] = folded[j] + (folded_world[p] if p >= 0 else 0.0)
    height, floor = retarget.standing(folded_world, layout.parents, src)
    assert floor is None and abs(height / 0.91 - 1) < 0.03  # the rig stands 0.91 m at the pelvis
    rig = rigs.load_rig("smpl")
    upright, bent = (retarget.retarget(pos, layout.joint_names, layout.parents, r, rig, FPS) for r in (rest, folded))
    ratio = bent.positions_m[:, rig.roles["pelvis"], 1] / upright.positions_m[:, rig.roles["pelvis"], 1]
    np.testing.assert_allclose(ratio, 0.91 / height, rtol=1e-9)
    for role in ("pelvis", "left_toe", "right_toe"):
        np.testing.assert_allclose(bent.positions_m[:, rig.roles[role], [0, 2]],
                                   upright.positions_m[:, rig.roles[role], [0, 2]], atol=1e-6)


def test_real_bandai_walks_round_trip(shared_data):
    """Bandai Namco's own clips (their rest pose folds the legs sideways, so the skeleton's standing
    height comes from its leg lengths): onto each built-in rig and back onto the clip's skeleton,
    every joint the rig's bone directions define within 1 cm of the clip taken onto its own
    skeleton (which pins the clip's own foot skate the same way)."""
    for name in ("dataset-2_walk-turn-left_active_001.bvh", "dataset-2_walk_elderly_001.bvh"):
        path = shared_data / "bandai" / "dataset-2" / name
        m = bvh.read_bvh(path)
        layout = representation.layout_from_skeleton(m.skeleton, 0.01)
        pos = (kinematics.world_positions(m)[:240:2] * 0.01)[:, list(layout.source_index)]  # 8 s at 15 Hz
        home = rigs.make_rig(m.skeleton, path.name, units_to_m=0.01)
        own = retarget.retarget(pos, layout.joint_names, layout.parents, layout.rest_offsets_m, home, FPS)
        own = own.positions_m[:, list(layout.source_index)]
        # on its own skeleton the walk stays itself above the legs (whose feet are pinned)
        legs = [j for j, n in enumerate(layout.joint_names) if "Leg" in n or "Foot" in n or "Toes" in n]
        body = [j for j in range(len(layout.joint_names)) if j not in legs]
        np.testing.assert_allclose(own[:, body], pos[:, body], atol=1e-6)
        assert np.abs(own - pos).max() < 0.1
        for name in rigs.BUILTIN_RIGS:
            rig = rigs.load_rig(name)
            there, back = round_trip(pos, layout, home, rig)
            heights = there.positions_m[:, rig.roles["pelvis"], 1] / pos[:, 0, 1]
            assert 0.9 < heights.min() and heights.max() < 1.15, (name, heights.min(), heights.max())
            err = np.linalg.norm(back - own, axis=-1)
            for j in directed(layout, rig):
                assert err[:, j].max() < 0.01, (path.name, name, layout.joint_names[j], err[:, j].max())
