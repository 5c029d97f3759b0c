"""BVH reader/writer: real CMU and Bandai files, round trips, and one test per malformed case."""

from __future__ import annotations

import dataclasses
import os
import re

import numpy as np
import pytest
from expected import CMU_NAMES

from motiongan_jax.motion import bvh

# A small hand-written file: mixed channel orders, 3- and 6-channel joints, position channels
# after rotations, exponent notation, two End Sites. 6 + 3 + 6 + 3 = 18 channels.
SMALL_LINES = [
    "HIERARCHY",                                                                   # 1
    "ROOT pelvis",                                                                 # 2
    "{",                                                                           # 3
    "\tOFFSET 0 1.5e1 0",                                                          # 4
    "\tCHANNELS 6 Xposition Yposition Zposition Yrotation Xrotation Zrotation",    # 5
    "\tJOINT spine",                                                               # 6
    "\t{",                                                                         # 7
    "\t\tOFFSET 0 10 0",                                                           # 8
    "\t\tCHANNELS 3 Zrotation Xrotation Yrotation",                                # 9
    "\t\tEnd Site",                                                                # 10
    "\t\t{",                                                                       # 11
    "\t\t\tOFFSET 0 5 0",                                                          # 12
    "\t\t}",                                                                       # 13
    "\t}",                                                                         # 14
    "\tJOINT leg",                                                                 # 15
    "\t{",                                                                         # 16
    "\t\tOFFSET 3 -2.5E+0 0",                                                      # 17
    "\t\tCHANNELS 6 Xrotation Yrotation Zrotation Xposition Yposition Zposition",  # 18
    "\t\tJOINT foot",                                                              # 19
    "\t\t{",                                                                       # 20
    "\t\t\tOFFSET 0 -8 1",                                                         # 21
    "\t\t\tCHANNELS 3 Xrotation Zrotation Yrotation",                              # 22
    "\t\t\tEnd Site",                                                              # 23
    "\t\t\t{",                                                                     # 24
    "\t\t\t\tOFFSET 0 0 2",                                                        # 25
    "\t\t\t}",                                                                     # 26
    "\t\t}",                                                                       # 27
    "\t}",                                                                         # 28
    "}",                                                                           # 29
    "MOTION",                                                                      # 30
    "Frames: 3",                                                                   # 31
    "Frame Time: 4.1666667e-2",                                                    # 32
    "1 2 3 10 20 30 1e1 -2E1 3.5 5 6 7 3 -2.5 0 0.1 0.2 0.3",                      # 33
    "1.5 2 3 11 21 31 1e1 -2E1 3.5 5 6 7 3 -2.5 0 0.1 0.2 0.3",                    # 34
    "2 2 3 12 22 32 1e1 -2E1 3.5 5 6 7 3 -2.5 0 0.1 0.2 -3.0e-1",                  # 35
]
SMALL = "\n".join(SMALL_LINES) + "\n"
SMALL_FRAMES = np.array([[float(x) for x in ln.split()] for ln in SMALL_LINES[32:35]])


def line_of(lines, text):
    """1-based number of the (unique) line equal to `text`."""
    hits = [i + 1 for i, ln in enumerate(lines) if ln == text]
    assert len(hits) == 1, (text, hits)
    return hits[0]


def assert_same_motion(a: bvh.Motion, b: bvh.Motion, atol: float) -> None:
    assert a.skeleton.names == b.skeleton.names
    assert a.skeleton.parents == b.skeleton.parents
    assert a.skeleton.channels == b.skeleton.channels
    np.testing.assert_allclose(a.skeleton.offsets, b.skeleton.offsets, rtol=0, atol=atol)
    assert a.values.shape == b.values.shape
    np.testing.assert_allclose(a.values, b.values, rtol=0, atol=atol)
    assert a.frame_time == pytest.approx(b.frame_time, rel=1e-12)


# ---------------------------------------------------------------------------------------------
# Valid input
# ---------------------------------------------------------------------------------------------

def test_small_file_parses():
    m = bvh.parse_bvh(SMALL, source="small.bvh")
    sk = m.skeleton
    assert sk.names == ("pelvis", "spine", "spine_EndSite", "leg", "foot", "foot_EndSite")
    assert sk.parents == (-1, 0, 1, 0, 3, 4)
    assert sk.channels[0] == ("Xposition", "Yposition", "Zposition", "Yrotation", "Xrotation", "Zrotation")
    assert sk.channels[1] == ("Zrotation", "Xrotation", "Yrotation")
    assert sk.channels[2] == ()
    assert sk.channels[4] == ("Xrotation", "Zrotation", "Yrotation")
    assert sk.is_end_site == (False, False, True, False, False, True)
    assert sk.num_channels == 18
    assert [sk.rotation_order(j) for j in range(6)] == ["YXZ", "ZXY", "", "XYZ", "XZY", ""]
    np.testing.assert_array_equal(sk.offsets, [[0, 15, 0], [0, 10, 0], [0, 5, 0], [3, -2.5, 0],
                                               [0, -8, 1], [0, 0, 2]])
    assert sk.offsets.dtype == np.float64 and m.values.dtype == np.float64
    np.testing.assert_array_equal(m.values, SMALL_FRAMES)
    assert m.values[0, 6] == 10.0 and m.values[0, 7] == -20.0 and m.values[2, 17] == -0.3
    assert m.frame_time == pytest.approx(1 / 24, rel=1e-6)
    assert m.num_frames == 3 and m.source == "small.bvh"


@pytest.mark.parametrize("variant", ["crlf", "cr", "spaces", "blank_lines", "brace_same_line"])
def test_layout_variants_parse_the_same(variant):
    if variant == "crlf":
        text = SMALL.replace("\n", "\r\n")
    elif variant == "cr":
        text = SMALL.replace("\n", "\r")
    elif variant == "spaces":
        text = "\n".join("   ".join(ln.replace("\t", "    ").split(" ")) for ln in SMALL_LINES) + "\n\n"
    elif variant == "blank_lines":
        lines = list(SMALL_LINES)
        lines.insert(33, "   \t")
        lines.insert(3, "")
        text = "\n".join(lines) + "\n\n  \n"
    else:
        text = SMALL.replace("ROOT pelvis\n{", "ROOT pelvis {").replace("End Site\n\t\t{", "End Site {")
    assert_same_motion(bvh.parse_bvh(text), bvh.parse_bvh(SMALL), atol=0)


def test_no_trailing_newline_and_lowercase_channels():
    text = SMALL.rstrip("\n").replace("Xrotation Zrotation Yrotation", "xrotation ZROTATION Yrotation")
    m = bvh.parse_bvh(text)
    assert m.skeleton.channels[4] == ("Xrotation", "Zrotation", "Yrotation")  # canonical spelling
    np.testing.assert_array_equal(m.values, SMALL_FRAMES)


def test_three_channel_root_and_any_channel_subset():
    lines = list(SMALL_LINES)
    lines[4] = "\tCHANNELS 3 Zrotation Xrotation Yrotation"  # root without position channels
    lines[17] = "\t\tCHANNELS 2 Yposition Xrotation"
    frames = ["10 20 30 1 2 3 5 7 0.1 0.2 0.3"] * 3
    m = bvh.parse_bvh("\n".join(lines[:32] + frames))
    assert m.skeleton.channels[0] == ("Zrotation", "Xrotation", "Yrotation")
    assert m.skeleton.channels[3] == ("Yposition", "Xrotation")
    assert m.values.shape == (3, 11)


def test_two_end_sites_under_one_joint_get_distinct_names():
    lines = list(SMALL_LINES)
    lines[13:13] = ["\t\tEnd Site", "\t\t{", "\t\t\tOFFSET 1 0 0", "\t\t}"]
    m = bvh.parse_bvh("\n".join(lines))
    assert m.skeleton.names[:4] == ("pelvis", "spine", "spine_EndSite", "spine_EndSite2")
    assert m.skeleton.parents[:4] == (-1, 0, 1, 1)


# ---------------------------------------------------------------------------------------------
# Real files
# ---------------------------------------------------------------------------------------------

CMU_PARENT_NAMES = {
    "LHipJoint": "Hips", "LeftUpLeg": "LHipJoint", "LeftToeBase_EndSite": "LeftToeBase",
    "LowerBack": "Hips", "Spine1": "Spine", "Neck": "Spine1", "Head_EndSite": "Head",
    "LeftShoulder": "Spine1", "RightShoulder": "Spine1", "LThumb": "LeftHand",
    "LeftHandIndex1": "LeftFingerBase", "RThumb_EndSite": "RThumb",
}

# data/README.md: the 22 Bandai joints and their parents.
BANDAI_JOINTS = (
    "joint_Root", "Hips", "Spine", "Chest", "Neck", "Head", "Shoulder_L", "UpperArm_L", "LowerArm_L",
    "Hand_L", "Shoulder_R", "UpperArm_R", "LowerArm_R", "Hand_R", "UpperLeg_L", "LowerLeg_L", "Foot_L",
    "Toes_L", "UpperLeg_R", "LowerLeg_R", "Foot_R", "Toes_R",
)
BANDAI_PARENTS = (-1, 0, 1, 2, 3, 4, 3, 6, 7, 8, 3, 10, 11, 12, 1, 14, 15, 16, 1, 18, 19, 20)
BANDAI_CHANNELS = ("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation")
BANDAI_FILES = (
    "bandai/dataset-2/dataset-2_walk_active_001.bvh",
    "bandai/dataset-2/dataset-2_walk-turn-left_elderly_002.bvh",
    "bandai/dataset-1/dataset-1_walk_normal_001.bvh",
)


@pytest.fixture(scope="module")
def cmu_standard(shared_data):
    return bvh.read_bvh(shared_data / "cmu" / "CMU_standard.bvh")


def test_cmu_standard(cmu_standard, shared_data):
    m, sk = cmu_standard, cmu_standard.skeleton
    assert sk.names == CMU_NAMES
    assert sk.num_joints == 38 and sum(sk.is_end_site) == 7
    assert sk.num_channels == 96 and m.values.shape == (344, 96)
    assert m.frame_time == pytest.approx(1 / 120, rel=1e-4)
    assert m.source == str(shared_data / "cmu" / "CMU_standard.bvh")
    for child, parent in CMU_PARENT_NAMES.items():
        assert sk.names[sk.parents[sk.names.index(child)]] == parent
    assert sk.parents[0] == -1 and all(p < j for j, p in enumerate(sk.parents))
    assert sk.channels[0] == ("Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation")
    for j in range(1, 38):
        assert sk.channels[j] in ((), ("Zrotation", "Yrotation", "Xrotation"))
    # Each End Site's name is its parent's name + "_EndSite", and End Sites are leaves.
    for j in np.flatnonzero(sk.is_end_site):
        assert sk.names[j] == sk.names[sk.parents[j]] + "_EndSite"
        assert j not in sk.parents


def test_cmu_131_01(cmu_standard, shared_data):
    m = bvh.read_bvh(shared_data / "cmu" / "131_01.bvh")
    assert m.skeleton.num_joints == 38 and m.skeleton.num_channels == 96
    assert m.values.shape == (994, 96)
    assert m.fps == pytest.approx(120, rel=1e-4)
    assert m.skeleton.parents == cmu_standard.skeleton.parents  # same topology, other joint names
    assert m.skeleton.is_end_site == cmu_standard.skeleton.is_end_site
    assert np.isfinite(m.values).all()


@pytest.mark.parametrize("rel", BANDAI_FILES)
def test_bandai_files(shared_data, rel):
    m = bvh.read_bvh(shared_data / rel)
    sk = m.skeleton
    assert sk.num_joints == 22 + 5  # 5 End Sites: Head, both Hands, both Toes
    real = [j for j in range(sk.num_joints) if not sk.is_end_site[j]]
    assert tuple(sk.names[j] for j in real) == BANDAI_JOINTS
    index_in_real = {j: i for i, j in enumerate(real)}
    assert tuple(index_in_real.get(sk.parents[j], -1) for j in real) == BANDAI_PARENTS
    ends = [sk.names[sk.parents[j]] for j in range(sk.num_joints) if sk.is_end_site[j]]
    assert sorted(ends) == sorted(["Head", "Hand_L", "Hand_R", "Toes_L", "Toes_R"])
    assert all(sk.channels[j] == BANDAI_CHANNELS for j in real)
    assert m.values.shape[1] == 22 * 6 and m.values.shape[0] > 20
    assert m.fps == pytest.approx(30, rel=1e-4)


# ---------------------------------------------------------------------------------------------
# Round trips
# ---------------------------------------------------------------------------------------------

def test_round_trip_small(tmp_path):
    m = bvh.parse_bvh(SMALL)
    path = tmp_path / "small.bvh"
    bvh.write_bvh(path, m)
    back = bvh.read_bvh(path)
    assert_same_motion(back, m, atol=5e-7)
    assert back.frame_time == m.frame_time  # written exactly
    # Writing what was read gives the same text again.
    bvh.write_bvh(tmp_path / "again.bvh", back)
    assert (tmp_path / "again.bvh").read_text() == path.read_text()


def test_round_trip_precision(tmp_path):
    m = bvh.parse_bvh(SMALL)
    m = dataclasses.replace(m, values=m.values + 1.23456789e-3)
    bvh.write_bvh(tmp_path / "p2.bvh", m, precision=2)
    back = bvh.read_bvh(tmp_path / "p2.bvh")
    np.testing.assert_allclose(back.values, m.values, rtol=0, atol=0.005 + 1e-12)
    assert not np.array_equal(back.values, m.values)


@pytest.mark.parametrize("rel", ("cmu/CMU_standard.bvh", "cmu/131_01.bvh") + BANDAI_FILES[:2])
def test_round_trip_real(shared_data, tmp_path, rel):
    m = bvh.read_bvh(shared_data / rel)
    out = tmp_path / "out.bvh"
    bvh.write_bvh(out, m)
    assert_same_motion(bvh.read_bvh(out), m, atol=5e-7 * (1 + 1e-9))
    assert list(tmp_path.iterdir()) == [out]  # no temporary file left behind


# ---------------------------------------------------------------------------------------------
# Malformed files: one test per problem, each checking file, line and problem in the message
# ---------------------------------------------------------------------------------------------

def expect_error(text: str, line: int, *fragments: str) -> bvh.BVHError:
    with pytest.raises(bvh.BVHError) as info:
        bvh.parse_bvh(text, source="bad.bvh")
    msg = str(info.value)
    m = re.match(r"^(.*):(\d+): (.+)$", msg, flags=re.S)
    assert m, msg
    assert m.group(1) == "bad.bvh", msg
    assert int(m.group(2)) == line, msg
    for frag in fragments:
        assert frag.lower() in m.group(3).lower(), msg
    return info.value


def edited(replace: dict[int, str | None] | None = None, insert: dict[int, str] | None = None) -> str:
    """SMALL with 1-based lines replaced (None deletes them) or new lines inserted before them."""
    out = []
    for i, ln in enumerate(SMALL_LINES, start=1):
        if insert and i in insert:
            out.append(insert[i])
        if replace and i in replace:
            if replace[i] is not None:
                out.append(replace[i])
        else:
            out.append(ln)
    return "\n".join(out) + "\n"


def test_bounds_are_checked_before_the_frames_are_read():
    """max_joints counts End Sites; max_frames is the declared count, refused at its line."""
    assert bvh.parse_bvh(SMALL, max_joints=6, max_frames=3).num_frames == 3
    with pytest.raises(bvh.BVHError, match=r"^x\.bvh:23: more than 5 joints \(End Sites included\)"):
        bvh.parse_bvh(SMALL, "x.bvh", max_joints=5)
    with pytest.raises(bvh.BVHError, match=r"^x\.bvh:31: 3 frames; at most 2 are read"):
        bvh.parse_bvh(SMALL, "x.bvh", max_frames=2)
    # a huge declared count with no frames behind it: the bound, not the missing frames
    huge = SMALL.replace("Frames: 3", "Frames: 123456789012")
    with pytest.raises(bvh.BVHError, match=r"123456789012 frames; at most 1000 are read"):
        bvh.parse_bvh(huge, "x.bvh", max_frames=1000)
    assert bvh.decode("é".encode("latin-1")) == "é" and bvh.decode("é".encode()) == "é"


def test_error_is_a_value_error():
    assert issubclass(bvh.BVHError, ValueError)


def test_missing_closing_brace():
    # Drop the root's closing brace (line 29): the root is still open when MOTION (now line 29) comes.
    expect_error(edited(replace={29: None}), 29, "missing '}'", "pelvis")


def test_missing_opening_brace():
    # Drop the '{' after "JOINT leg": the parser meets OFFSET on line 16 (was line 17).
    expect_error(edited(replace={16: None}), 16, "missing '{'", "leg")


def test_extra_closing_brace():
    expect_error(edited(insert={30: "}"}), 30, "unbalanced '}'")


def test_hierarchy_ends_inside_a_joint():
    expect_error("\n".join(SMALL_LINES[:20]), 20, "missing '}'", "foot", "end of file")


def test_frame_line_with_too_few_values():
    bad = " ".join(SMALL_LINES[33].split()[:-1])
    expect_error(edited(replace={34: bad}), 34, "wrong number of values", "expected 18", "found 17")


def test_frame_line_with_too_many_values():
    expect_error(edited(replace={33: SMALL_LINES[32] + " 4"}), 33, "expected 18", "found 19")


def test_truncated_last_frame_line():
    text = SMALL.rstrip("\n")[:-12]
    expect_error(text, 35, "wrong number of values", "expected 18")


def test_non_numeric_value():
    bad = SMALL_LINES[33].replace("11", "1l", 1)
    expect_error(edited(replace={34: bad}), 34, "non-numeric", "'1l'")


def test_python_digit_separator_is_not_a_number():
    bad = SMALL_LINES[34].replace("12", "1_2", 1)
    expect_error(edited(replace={35: bad}), 35, "non-numeric", "'1_2'")


@pytest.mark.parametrize("token", ["nan", "NaN", "inf", "-Infinity"])
def test_nan_or_infinite_value(token):
    bad = SMALL_LINES[33].replace("11", token, 1)
    expect_error(edited(replace={34: bad}), 34, "nan or infinite", repr(token))


def test_non_finite_offset():
    expect_error(edited(replace={21: "\t\t\tOFFSET 0 nan 1"}), 21, "nan or infinite", "offset")


def test_offset_with_two_values():
    expect_error(edited(replace={8: "\t\tOFFSET 0 10"}), 8, "offset needs 3 values", "found 2")


def test_fewer_frames_than_declared():
    expect_error(edited(replace={31: "Frames: 4"}), 31, "fewer frames than declared", "4", "3 frame lines")


def test_more_frames_than_declared():
    expect_error(edited(replace={31: "Frames: 2"}), 35, "more frames than declared", "Frames: 2")


def test_zero_frames():
    text = "\n".join(SMALL_LINES[:30] + ["Frames: 0", "Frame Time: 0.01"]) + "\n"
    expect_error(text, 31, "zero frames")


def test_declared_frames_but_no_frame_lines():
    text = "\n".join(SMALL_LINES[:32]) + "\n"
    expect_error(text, 31, "fewer frames than declared", "0 frame lines")


@pytest.mark.parametrize("count", ["-1", "2.5", "many"])
def test_bad_frame_count(count):
    expect_error(edited(replace={31: f"Frames: {count}"}), 31, "bad frame count")


def test_unknown_channel_name():
    expect_error(edited(replace={9: "\t\tCHANNELS 3 Zrotation Xrot Yrotation"}), 9,
                 "unknown channel name", "'Xrot'")


def test_duplicate_channel_name():
    expect_error(edited(replace={9: "\t\tCHANNELS 3 Zrotation Xrotation Zrotation"}), 9, "duplicate channel")


def test_duplicate_joint_name():
    expect_error(edited(replace={19: "\t\tJOINT spine"}), 19, "duplicate joint name", "'spine'", "line 6")


def test_end_site_name_clash_is_a_duplicate():
    expect_error(edited(replace={19: "\t\tJOINT spine_EndSite"}), 19, "duplicate joint name")


def test_missing_motion():
    expect_error(edited(replace={30: None}), 30, "missing MOTION", "'Frames:'")


def test_missing_motion_at_end_of_file():
    expect_error("\n".join(SMALL_LINES[:29]) + "\n", 29, "missing MOTION")


def test_missing_frames_line():
    expect_error(edited(replace={31: None}), 31, "missing 'Frames:'")


def test_missing_frame_time_line():
    expect_error(edited(replace={32: None}), 32, "missing 'Frame Time:'")


@pytest.mark.parametrize("value", ["0", "-0.01", "0.0e0"])
def test_non_positive_frame_time(value):
    expect_error(edited(replace={32: f"Frame Time: {value}"}), 32, "non-positive frame time")


@pytest.mark.parametrize("value", ["nan", "inf"])
def test_non_finite_frame_time(value):
    expect_error(edited(replace={32: f"Frame Time: {value}"}), 32, "frame time")


@pytest.mark.parametrize(
    "line, fragment",
    [
        ("\t\tCHANNELS 4 Zrotation Xrotation Yrotation", "says 4 but lists 3"),
        ("\t\tCHANNELS 2 Zrotation Xrotation Yrotation", "says 2 but lists 3"),
        ("\t\tCHANNELS x Zrotation Xrotation Yrotation", "'x'"),
        ("\t\tCHANNELS 0", "count 0"),
        ("\t\tCHANNELS 7 Zrotation Xrotation Yrotation Xposition Yposition Zposition Xrotation", "count 7"),
    ],
)
def test_bad_channels_count(line, fragment):
    expect_error(edited(replace={9: line}), 9, "bad CHANNELS count", fragment)


def test_joint_without_channels():
    # foot (CHANNELS was line 22) meets its End Site, now line 22, without CHANNELS.
    expect_error(edited(replace={22: None}), 22, "'foot' needs OFFSET and CHANNELS")
    # A leaf joint without CHANNELS is reported at its closing brace (line 13 was 14).
    leaf = edited(replace={9: None, 10: None, 11: None, 12: None, 13: None})
    expect_error(leaf, 9, "'spine' has no CHANNELS")


def test_end_site_with_channels():
    expect_error(edited(insert={12: "\t\t\tCHANNELS 1 Xrotation"}), 12, "End Site cannot have CHANNELS")


def test_unexpected_keyword():
    expect_error(edited(replace={8: "\t\tOFSET 0 10 0"}), 8, "unexpected 'OFSET'")


def test_empty_text():
    expect_error("", 1, "empty file")
    expect_error("MOTION\n", 1, "expected HIERARCHY")


def test_read_bvh_names_the_file(tmp_path):
    path = tmp_path / "broken.bvh"
    path.write_text(edited(replace={34: "1 2 3"}))
    with pytest.raises(bvh.BVHError, match=rf"^{re.escape(str(path))}:34: wrong number of values"):
        bvh.read_bvh(path)


# ---------------------------------------------------------------------------------------------
# read_bvh_dir
# ---------------------------------------------------------------------------------------------

def make_tree(root):
    bad_count = edited(replace={31: "Frames: 9"})
    bad_channel = edited(replace={9: "\t\tCHANNELS 3 Zrotation Xrot Yrotation"})
    files = {
        "z.bvh": SMALL,
        "a/good1.bvh": SMALL,
        "b/bad_count.bvh": bad_count,
        "b/c/good2.bvh": SMALL.replace("Frame Time: 4.1666667e-2", "Frame Time: 0.01"),
        "b/d_bad_channel.bvh": bad_channel,
        "a/notes.txt": "not a bvh file",
    }
    for rel, text in files.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_text(text)


def test_read_bvh_dir_stops_at_first_bad_file(tmp_path):
    make_tree(tmp_path)
    with pytest.raises(bvh.BVHError) as info:
        bvh.read_bvh_dir(tmp_path)
    assert str(info.value).startswith(f"{tmp_path / 'b' / 'bad_count.bvh'}:31: fewer frames")


def test_read_bvh_dir_skip_bad(tmp_path):
    make_tree(tmp_path)
    motions, errors = bvh.read_bvh_dir(tmp_path, skip_bad=True)
    # Sorted by relative path: a/good1, b/bad_count, b/c/good2, b/d_bad_channel, z.
    assert [m.source for m in motions] == [str(tmp_path / p) for p in ("a/good1.bvh", "b/c/good2.bvh", "z.bvh")]
    assert motions[1].frame_time == 0.01
    assert [str(e).split(":")[0] for e in errors] == [
        str(tmp_path / "b" / "bad_count.bvh"), str(tmp_path / "b" / "d_bad_channel.bvh")]
    assert all(isinstance(e, bvh.BVHError) for e in errors)
    assert "unknown channel name" in str(errors[1])


def test_read_bvh_dir_pattern_and_clean_tree(tmp_path):
    make_tree(tmp_path)
    motions, errors = bvh.read_bvh_dir(tmp_path, pattern="good*.bvh")
    assert len(motions) == 2 and errors == []
    with pytest.raises(NotADirectoryError):
        bvh.read_bvh_dir(tmp_path / "missing")


# ---------------------------------------------------------------------------------------------
# Writer failures leave nothing behind
# ---------------------------------------------------------------------------------------------

def test_write_into_missing_directory(tmp_path):
    target = tmp_path / "no" / "such" / "dir" / "x.bvh"
    with pytest.raises(OSError):
        bvh.write_bvh(target, bvh.parse_bvh(SMALL))
    assert list(tmp_path.iterdir()) == []


def test_write_nan_motion_raises_and_leaves_no_file(tmp_path):
    m = bvh.parse_bvh(SMALL)
    values = m.values.copy()
    values[1, 4] = np.nan
    with pytest.raises(bvh.BVHError, match="NaN or infinite value in frame 2"):
        bvh.write_bvh(tmp_path / "nan.bvh", dataclasses.replace(m, values=values))
    assert list(tmp_path.iterdir()) == []


def test_failed_write_keeps_the_old_file(tmp_path, monkeypatch):
    path = tmp_path / "keep.bvh"
    path.write_text("old contents")
    m = bvh.parse_bvh(SMALL)
    with pytest.raises(bvh.BVHError, match="values have shape"):
        bvh.write_bvh(path, dataclasses.replace(m, values=m.values[:, :5]))

    def broken_replace(src, dst):
        raise OSError("disk full (simulated)")

    monkeypatch.setattr(os, "replace", broken_replace)
    with pytest.raises(OSError, match="simulated"):
        bvh.write_bvh(path, m)
    assert path.read_text() == "old contents"
    assert list(tmp_path.iterdir()) == [path]


@pytest.mark.parametrize("problem", ["frame_time", "zero_frames", "end_site_with_child", "not_dfs", "name"])
def test_write_rejects_unwritable_motions(tmp_path, problem):
    m = bvh.parse_bvh(SMALL)
    sk = m.skeleton
    if problem == "frame_time":
        m = dataclasses.replace(m, frame_time=0.0)
    elif problem == "zero_frames":
        m = dataclasses.replace(m, values=m.values[:0])
    elif problem == "end_site_with_child":
        chans = list(sk.channels)
        chans[1] = ()
        m = dataclasses.replace(m, skeleton=dataclasses.replace(sk, channels=tuple(chans)),
                                values=m.values[:, [c for c in range(18) if not 6 <= c < 9]])
    elif problem == "not_dfs":
        m = dataclasses.replace(m, skeleton=dataclasses.replace(sk, parents=(-1, 0, 0, 1, 3, 4)))
    else:
        m = dataclasses.replace(m, skeleton=dataclasses.replace(sk, names=("a{b",) + sk.names[1:]))
    with pytest.raises(bvh.BVHError, match=re.escape(str(tmp_path / "x.bvh")) + ": "):
        bvh.write_bvh(tmp_path / "x.bvh", m)
    assert list(tmp_path.iterdir()) == []


def test_write_preserves_existing_file_mode(tmp_path):
    path = tmp_path / "mode.bvh"
    path.write_text("x")
    path.chmod(0o640)
    bvh.write_bvh(path, bvh.parse_bvh(SMALL))
    assert path.stat().st_mode & 0o777 == 0o640
    bvh.write_bvh(tmp_path / "new.bvh", bvh.parse_bvh(SMALL))
    assert (tmp_path / "new.bvh").stat().st_mode & 0o777 == 0o644
