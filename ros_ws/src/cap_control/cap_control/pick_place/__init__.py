"""Pick-and-place on the table top: plan (the stages and their checks), executor (over the arm, gripper and
perception ports) and node (the PickPlace action)."""
