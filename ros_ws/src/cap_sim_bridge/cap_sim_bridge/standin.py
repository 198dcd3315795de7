"""How a hardware stand-in differs from the graph's own simulator: a second simulator that plays a real robot.

A real cell is never its model: objects are lighter or heavier and slide more or less, the camera hangs a few
millimetres and milliradians off its calibration, and depth is noisy and comes in whole millimetres. The stand-in
(the sim bridge with a hardware profile, `cap standin`) makes the same differences, drawn from a seed:
- each object's sliding friction and mass scaled by factors drawn in `friction_range` and `mass_range`;
- the camera mounted at the calibration's pose moved by `camera_translation_error` [m] and turned by
  `camera_rotation_error` [rad], each about an axis drawn at random (the graph keeps the calibration it was given);
- depth with Gaussian noise of `depth_noise` [m] at 1 m, growing with the square of the distance as a stereo
  camera's does, sent as 16UC1 millimetres like a RealSense's.
Plain Python, NumPy and MuJoCo, no ROS.
"""
from __future__ import annotations

import dataclasses
from typing import Iterable

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from cap_sim_bridge.camera import MUJOCO_FROM_OPTICAL

# The camera driver's part of the chain: camera_link (x forward, z up) -> the colour optical frame (z forward, y
# down), 15 mm to the left of camera_link as a RealSense D435's colour sensor sits: what its driver publishes.
LINK_TO_OPTICAL = np.array([[0.0, 0.0, 1.0, 0.0],
                            [-1.0, 0.0, 0.0, 0.015],
                            [0.0, -1.0, 0.0, 0.0],
                            [0.0, 0.0, 0.0, 1.0]])


@dataclasses.dataclass(frozen=True)
class Perturbation:
    seed: int = 0
    friction_range: tuple[float, float] = (0.7, 1.3)
    mass_range: tuple[float, float] = (0.8, 1.25)
    camera_translation_error: float = 0.004  # [m]
    camera_rotation_error: float = 0.004  # [rad]
    depth_noise: float = 0.002  # [m] standard deviation at 1 m

    def perturb_objects(self, model: mujoco.MjModel, object_bodies: Iterable[int]) -> None:
        """Scale each object's friction and mass (and its inertia with it) in `model`, in place."""
        rng = np.random.default_rng([self.seed, 1])
        for body in object_bodies:
            mass_factor = rng.uniform(*self.mass_range)
            model.body_mass[body] *= mass_factor
            model.body_inertia[body] *= mass_factor
            geoms = np.flatnonzero(model.geom_bodyid == body)
            model.geom_friction[geoms, 0] *= rng.uniform(*self.friction_range)

    def camera_error(self) -> np.ndarray:
        """The 4x4 transform by which the real camera_link sits off its calibration (applied in its own frame)."""
        rng = np.random.default_rng([self.seed, 2])
        error = np.eye(4)
        error[:3, :3] = Rotation.from_rotvec(_unit(rng) * self.camera_rotation_error).as_matrix()
        error[:3, 3] = _unit(rng) * self.camera_translation_error
        return error

    def noisy_depth(self, depth: np.ndarray, frame: int) -> np.ndarray:
        """Depth [m] as the stand-in's camera measures it: noise growing with distance, whole millimetres, 0 where
        nothing was measured (returned as uint16 millimetres)."""
        rng = np.random.default_rng([self.seed, 3, frame])
        valid = np.isfinite(depth) & (depth > 0)
        metres = np.where(valid, depth, 0.0)
        metres = metres + rng.normal(0.0, 1.0, depth.shape) * self.depth_noise * metres ** 2
        return np.where(valid, np.clip(np.round(metres * 1000.0), 1, 65535), 0).astype(np.uint16)


def _unit(rng: np.random.Generator) -> np.ndarray:
    vector = rng.normal(size=3)
    return vector / np.linalg.norm(vector)


def place_camera(model: mujoco.MjModel, camera: str, optical_in_body: np.ndarray) -> None:
    """Put the named MuJoCo camera where its ROS optical frame is `optical_in_body` (4x4, in the frame of the body
    the camera is fixed to), in place."""
    index = model.camera(camera).id
    rotation = optical_in_body[:3, :3] @ MUJOCO_FROM_OPTICAL.T  # MuJoCo's camera axes (-z forward, y up)
    model.cam_pos[index] = optical_in_body[:3, 3]
    x, y, z, w = Rotation.from_matrix(rotation).as_quat()
    model.cam_quat[index] = [w, x, y, z]


__all__ = ['LINK_TO_OPTICAL', 'Perturbation', 'place_camera']
