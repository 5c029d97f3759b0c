"""Expected values of the reference implementation (docs/DESIGN.md §2.2), written out by hand, shared by tests."""

# Depth-first joint order of the CMU skeleton (the reference renames the root "Root").
CMU_NAMES = (
    "Hips", "LHipJoint", "LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToeBase", "LeftToeBase_EndSite",
    "RHipJoint", "RightUpLeg", "RightLeg", "RightFoot", "RightToeBase", "RightToeBase_EndSite",
    "LowerBack", "Spine", "Spine1", "Neck", "Neck1", "Head", "Head_EndSite",
    "LeftShoulder", "LeftArm", "LeftForeArm", "LeftHand", "LeftFingerBase", "LeftHandIndex1",
    "LeftHandIndex1_EndSite", "LThumb", "LThumb_EndSite",
    "RightShoulder", "RightArm", "RightForeArm", "RightHand", "RightFingerBase", "RightHandIndex1",
    "RightHandIndex1_EndSite", "RThumb", "RThumb_EndSite",
)

# The paper's 28 kept joints, in order (DESIGN.md §2.2).
PAPER_JOINTS = (
    "Hips", "LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToeBase", "LeftToeBase_EndSite",
    "RightUpLeg", "RightLeg", "RightFoot", "RightToeBase", "RightToeBase_EndSite",
    "Spine", "Spine1", "Neck1", "Head", "Head_EndSite",
    "LeftArm", "LeftForeArm", "LeftHand", "LeftHandIndex1", "LeftHandIndex1_EndSite", "LThumb_EndSite",
    "RightArm", "RightForeArm", "RightHand", "RightHandIndex1", "RightHandIndex1_EndSite", "RThumb_EndSite",
)
# The 27 bone pairs of the bone loss (DESIGN.md §2.2).
PAPER_BONES = {
    (0, 11), (11, 12), (12, 22), (22, 23), (23, 24), (24, 27), (24, 25), (25, 26),
    (12, 16), (16, 17), (17, 18), (18, 21), (18, 19), (19, 20),
    (12, 13), (13, 14), (14, 15),
    (0, 6), (6, 7), (7, 8), (8, 9), (9, 10),
    (0, 1), (1, 2), (2, 3), (3, 4), (4, 5),
}
