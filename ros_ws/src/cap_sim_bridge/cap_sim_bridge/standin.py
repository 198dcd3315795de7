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
from typing import Callable, Iterable

import mujoco
import numpy as np
from cap_hardware.profile import Mount
from cap_ros_common.transforms import TransformBuffer, pose_matrix
from scipy.spatial.transform import Rotation

from cap_sim_bridge.camera import MUJOCO_FROM_OPTICAL
from cap_sim_bridge.robot_state import RobotState
from cap_sim_bridge.urdf import robot_urdf

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


def body_frame(model: mujoco.MjModel, body: int) -> str:
    """The tf frame of a body: its URDF link's name, 'world' for the world body."""
    return 'world' if body == 0 else mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, body)


def standin_adjustment(perturbation: Perturbation, camera: str, mount: Mount) -> Callable[[mujoco.MjModel], None]:
    """What a stand-in does to every model it compiles: the objects perturbed, and the named MuJoCo camera put where
    the calibration's `mount` says camera_link is (moved by the perturbation's camera error), looking as a camera
    driver's optical frame does from there."""
    def adjust(model: mujoco.MjModel) -> None:
        # The objects are the bodies on free joints.
        perturbation.perturb_objects(model, [int(model.jnt_bodyid[joint]) for joint in range(model.njnt)
                                             if model.jnt_type[joint] == mujoco.mjtJoint.mjJNT_FREE])
        # The camera's body in the mount's parent frame, through the robot's fixed tree at zero joints.
        state = RobotState(robot_urdf(model))
        tree = TransformBuffer()
        tree.add(state.fixed_transforms(), static=True)
        tree.add(state.moving_transforms(state.moving_joint_names, [0.0] * len(state.moving_joint_names), 0.0),
                 static=True)
        body = body_frame(model, int(model.cam_bodyid[model.camera(camera).id]))
        body_in_parent = tree.lookup(mount.parent, body) if body != mount.parent else np.eye(4)
        optical = pose_matrix(mount.translation, mount.rotation) @ perturbation.camera_error() @ LINK_TO_OPTICAL
        place_camera(model, camera, np.linalg.inv(body_in_parent) @ optical)
    return adjust


__all__ = ['LINK_TO_OPTICAL', 'Perturbation', 'body_frame', 'place_camera', 'standin_adjustment']
