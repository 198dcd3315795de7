"""The named cameras that watch the table: pose in the world frame and vertical field of view.

`orientation` is the quaternion (w, x, y, z) of the camera body frame as MuJoCo defines it: the camera looks
along its -z axis, image right is +x and image up is +y. The ROS optical frame (+z forward, +y down, +x right) is
that frame turned half a turn about its x axis; `optical_orientation_xyzw` gives it in ROS order (x, y, z, w).
"""
from __future__ import annotations

import dataclasses
import math


@dataclasses.dataclass(frozen=True)
class CameraPose:
    name: str
    position: tuple[float, float, float]  # [m], world frame
    orientation: tuple[float, float, float, float]  # w, x, y, z (MuJoCo camera frame)
    fovy: float  # vertical field of view [deg]


def _about_x(angle: float) -> tuple[float, float, float, float]:
    return (math.cos(angle / 2), math.sin(angle / 2), 0.0, 0.0)


# Front camera: beyond the table's bottom (-y) edge, looking back at the table and the robot; tilted about x so its
# view axis points at (0, -0.42, 0.12), just above the table centre. Image right = world +x.
FRONT = CameraPose('front', (0.0, -1.3, 0.75), _about_x(math.atan2(0.8131, 0.5821)), 55.0)
# Top-down camera over the table centre: image right = +x, image up = +y (the table's top).
TOP = CameraPose('top', (0.0, -0.5, 0.85), (1.0, 0.0, 0.0, 0.0), 45.0)

CAMERAS: dict[str, CameraPose] = {camera.name: camera for camera in (FRONT, TOP)}
CAMERA_NAMES: tuple[str, ...] = tuple(CAMERAS)
# The camera camera-based perception reads by default.
DEFAULT_CAMERA = TOP.name


def optical_orientation_xyzw(camera: CameraPose) -> tuple[float, float, float, float]:
    """The camera's ROS optical frame orientation in the world frame, quaternion x, y, z, w."""
    w, x, y, z = camera.orientation
    # q * (0, 1, 0, 0): half a turn about the camera's own x axis.
    qw, qx, qy, qz = -x, w, z, -y
    return (qx + 0.0, qy + 0.0, qz + 0.0, qw + 0.0)  # + 0.0: no negative zeros
