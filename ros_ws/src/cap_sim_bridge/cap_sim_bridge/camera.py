"""Pinhole camera facts of MuJoCo cameras, in the ROS optical convention (pure NumPy).

MuJoCo cameras look along their -Z axis with +Y up and +X right. The ROS optical frame looks along +Z with +Y
down and +X right, so R_world_optical = R_world_mujoco @ diag(1, -1, -1).
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

# Rotation from the ROS optical frame to the MuJoCo camera frame (a half turn about x).
MUJOCO_FROM_OPTICAL = np.diag([1.0, -1.0, -1.0])


@dataclasses.dataclass(frozen=True)
class CameraIntrinsics:
    """Pinhole intrinsics of a rendered image [pixels], OpenCV/ROS convention (pixel centres at integers)."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    @property
    def matrix(self) -> np.ndarray:
        """The 3x3 camera matrix K."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def project(self, points_optical: np.ndarray) -> np.ndarray:
        """Pixel coordinates (u, v) of points given in the optical frame, shape (..., 3) -> (..., 2)."""
        points = np.asarray(points_optical, dtype=float)
        return np.stack([self.fx * points[..., 0] / points[..., 2] + self.cx,
                         self.fy * points[..., 1] / points[..., 2] + self.cy], axis=-1)


def intrinsics_from_fovy(fovy_degrees: float, width: int, height: int) -> CameraIntrinsics:
    """Intrinsics of MuJoCo's symmetric frustum: fovy spans the image height, pixels are square."""
    focal = 0.5 * height / math.tan(math.radians(fovy_degrees) / 2)
    # The optical axis meets the image at its geometric centre, i.e. between pixels for even sizes.
    return CameraIntrinsics(width, height, focal, focal, (width - 1) / 2.0, (height - 1) / 2.0)


def optical_pose(position: np.ndarray, mujoco_rotation: np.ndarray) -> np.ndarray:
    """4x4 world_T_optical from a MuJoCo camera's world position and rotation matrix."""
    pose = np.eye(4)
    pose[:3, :3] = np.asarray(mujoco_rotation, dtype=float).reshape(3, 3) @ MUJOCO_FROM_OPTICAL
    pose[:3, 3] = position
    return pose
