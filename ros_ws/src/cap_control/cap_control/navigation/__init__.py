"""Navigation of the mobile base: plan (the occupancy grid, paths, the path follower), executor (over the base's
port) and node (the Navigate and NavigateThroughPoses actions, the base's pose and the map)."""
