"""MuJoCo simulation of the cap-ros robots (UR5e table-top) and its ROS 2 bridge node."""
