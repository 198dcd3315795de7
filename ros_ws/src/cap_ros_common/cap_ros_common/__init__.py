"""Small ROS helpers shared by the cap-ros nodes: parameters declared from a config dataclass, time conversions."""
