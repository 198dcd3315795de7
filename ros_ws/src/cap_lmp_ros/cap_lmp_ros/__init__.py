"""The ROS binding of the LMP engine: lmp_node, its command queue, and the domain registry with the table-top
domain (prompts, LMPs, robot API). No rclpy at import: the sandbox process imports domain modules below it."""
