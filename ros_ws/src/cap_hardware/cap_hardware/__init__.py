"""Hardware profiles of cap-ros: what a real robot offers the graph, its calibration and limits (no ROS)."""
