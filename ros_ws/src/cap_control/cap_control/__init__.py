"""Control for cap-ros: the robot's skills, each in one shape, over shared kinematics, trajectory timing and ports.

Every skill is a sub-package `cap_control.<skill>` of three modules:
- `plan`: the pure planning and checking logic (no ROS);
- `executor`: the pure executor that carries a goal out over ports (cap_control.ports; no ROS);
- `node`: the thin rclpy node serving the skill's action, with `main()`; setup.py installs it as the executable
  `<skill>` (derived from the folders), its parameters overridden in config/<skill>.yaml.

The skills: `pick_place` (the table top's pick-and-place), `follow_path` (drawing and erasing on the whiteboard),
`navigation` (the mobile base), `mobile_pick_place` (the mobile manipulator's pick-and-place, over navigation and the
table top's plan runner) and `controller` (generated reactive controllers). The controller loop plans nothing: its
`plan` holds what a run may do (a request's checks, the limits, the checks of every tick).

Shared by the skills, at the top: `kinematics` (the UR5e), `trajectory` (timing), `ports` (the ports and the waits
every executor shares); below every node, the ROS plumbing they share: `skill_node` (the goal and arm nodes, the
ports over ROS, main()'s spinning) and `ros_conversions` (messages only). No node imports another.
"""
