"""Arm control for cap-ros: UR5e kinematics, trajectory timing, pick-and-place, path following."""
