"""Motion data: BVH files, forward and inverse kinematics, and the rows G and D work on."""
