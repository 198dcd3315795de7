"""The mobile manipulator of the kitchen (base frame: x forward, y left, z up, origin on the floor under the base's
centre; metres, radians).

A round base that moves on the floor (x, y and yaw, as the joints base_x, base_y and base_yaw of the simulator),
the UR5e with its gripper on top, a little ahead of the centre, and a head RGB-D camera on a mast behind the arm,
looking ahead and down. The footprint's radius and the speed limits are the layout's (cap_mobile.layout).
"""
from __future__ import annotations

import math

from cap_mobile.layout import BASE_RADIUS

BASE_JOINT_NAMES: tuple[str, str, str] = ('base_x', 'base_y', 'base_yaw')
BASE_HEIGHT = 0.6  # [m] top of the base, where the arm stands (high enough to reach down onto a counter)
BASE_CLEARANCE = 0.01  # [m] between the floor and the base's underside (it glides: planar joints)
ARM_MOUNT: tuple[float, float, float] = (0.1, 0.0, BASE_HEIGHT)  # the UR5e's base frame in the base frame

# The arm's joints while the base drives: folded over the base, inside its footprint and under the camera's view.
STOWED_JOINTS: tuple[float, ...] = (math.pi, -2.4, 2.8, -0.5, -math.pi / 2, 0.0)

# Where the tool carries a held object while the base drives (the arm's frame: x ahead, z up from the arm's base):
# over the base, inside its footprint, the object hanging above the base's top. High enough that no part of the arm
# below a countertop's height (0.93 m) reaches past the base's edge: lower (0.45 m), the upper arm stuck out 8 cm
# there, and the base turning away from the counter swept it into the edge (a rehearsal on the twin saw it).
CARRY_TCP: tuple[float, float, float] = (0.2, 0.0, 0.6)

# The head camera: where it is on the base and how far it looks down.
HEAD_CAMERA = 'head'
HEAD_CAMERA_POSITION: tuple[float, float, float] = (-0.2, 0.0, 1.45)
HEAD_CAMERA_PITCH = 0.6  # [rad] below the horizon
HEAD_CAMERA_FOVY = 58.0  # [deg] vertical field of view (a common RGB-D camera's)

# A camera that follows the robot from behind and above at a fixed offset in the room (for videos of a run).
FOLLOW_CAMERA = 'follow'
FOLLOW_CAMERA_OFFSET: tuple[float, float, float] = (-2.2, -2.2, 2.6)  # [m] from the base's centre on the floor
FOLLOW_CAMERA_TARGET_HEIGHT = 0.6  # [m] of the point on the robot it looks at
FOLLOW_CAMERA_FOVY = 60.0  # [deg]

__all__ = ['ARM_MOUNT', 'BASE_CLEARANCE', 'BASE_HEIGHT', 'BASE_JOINT_NAMES', 'BASE_RADIUS', 'CARRY_TCP',
           'FOLLOW_CAMERA', 'FOLLOW_CAMERA_FOVY', 'FOLLOW_CAMERA_OFFSET', 'FOLLOW_CAMERA_TARGET_HEIGHT', 'HEAD_CAMERA',
           'HEAD_CAMERA_FOVY', 'HEAD_CAMERA_PITCH', 'HEAD_CAMERA_POSITION', 'STOWED_JOINTS']
