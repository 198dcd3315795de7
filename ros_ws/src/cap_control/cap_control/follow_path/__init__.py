"""Path following over a work surface (drawing, erasing): plan (the strokes as timed trajectories), executor (over
the arm and the tool's spring) and node (the FollowPath action)."""
