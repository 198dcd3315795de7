"""The robot's link poses from its URDF and its joint positions: what robot_state_publisher computes, no ROS.

Each URDF joint places its child link in its parent: the joint's origin (xyz, then roll-pitch-yaw as
Rz(yaw) Ry(pitch) Rx(roll)) followed by its motion (a rotation about the axis for revolute and continuous joints, a
translation along it for prismatic ones). Fixed joints give the transforms /tf_static carries, the others those of
/tf for every /joint_states message.
"""
from __future__ import annotations

import xml.etree.ElementTree as ElementTree
from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np
from cap_ros_common.transforms import Transform, translation_rotation
from scipy.spatial.transform import Rotation

MOVING_TYPES = ('revolute', 'continuous', 'prismatic')


@dataclass(frozen=True)
class UrdfJoint:
    name: str
    kind: str
    parent: str
    child: str
    origin: np.ndarray  # 4x4: the child's frame in the parent's at zero motion
    axis: np.ndarray  # unit vector in the child's frame

    def transform(self, position: float = 0.0) -> np.ndarray:
        """The child's pose in the parent's with the joint at `position` [rad or m]."""
        motion = np.eye(4)
        if self.kind in ('revolute', 'continuous'):
            motion[:3, :3] = Rotation.from_rotvec(self.axis * position).as_matrix()
        elif self.kind == 'prismatic':
            motion[:3, 3] = self.axis * position
        return self.origin @ motion


def _floats(text: str | None, count: int) -> np.ndarray:
    values = np.array([float(v) for v in (text or '').split()] or [0.0] * count)
    if values.shape != (count,):
        raise ValueError(f'expected {count} numbers, got {text!r}')
    return values


def urdf_joints(urdf: str) -> list[UrdfJoint]:
    """Every joint of a URDF document, in document order; ValueError for a joint type it does not model."""
    joints = []
    for element in ElementTree.fromstring(urdf).iter('joint'):
        if element.find('parent') is None:  # a <joint> inside a <transmission>
            continue
        kind = element.get('type', '')
        if kind not in (*MOVING_TYPES, 'fixed'):
            raise ValueError(f'joint {element.get("name")!r}: type {kind!r} is not modelled (fixed, revolute, '
                             'continuous, prismatic)')
        origin = element.find('origin')
        matrix = np.eye(4)
        if origin is not None:
            matrix[:3, :3] = Rotation.from_euler('xyz', _floats(origin.get('rpy'), 3)).as_matrix()
            matrix[:3, 3] = _floats(origin.get('xyz'), 3)
        axis_element = element.find('axis')
        axis = _floats(axis_element.get('xyz') if axis_element is not None else '1 0 0', 3)
        joints.append(UrdfJoint(element.get('name', ''), kind, element.find('parent').get('link'),
                                element.find('child').get('link'), matrix, axis / np.linalg.norm(axis)))
    return joints


class RobotState:
    """The transforms of a robot described by URDF."""

    def __init__(self, urdf: str) -> None:
        self.joints = urdf_joints(urdf)
        self._moving = {joint.name: joint for joint in self.joints if joint.kind in MOVING_TYPES}

    @property
    def moving_joint_names(self) -> list[str]:
        return list(self._moving)

    def fixed_transforms(self, stamp: float = 0.0) -> list[Transform]:
        """The fixed joints' transforms (what /tf_static carries)."""
        return [_transform(joint, joint.transform(), stamp) for joint in self.joints if joint.kind == 'fixed']

    def moving_transforms(self, names: Sequence[str], positions: Sequence[float], stamp: float) -> list[Transform]:
        """The transforms of the moving joints among `names` at `positions`; other names are skipped (a joint
        state may carry more joints than the URDF has)."""
        return [_transform(self._moving[name], self._moving[name].transform(float(position)), stamp)
                for name, position in zip(names, positions) if name in self._moving]

    def link_poses(self, positions: Mapping[str, float], root: str) -> dict[str, np.ndarray]:
        """Every link's pose in `root` with the moving joints at `positions` (missing ones at 0)."""
        poses = {root: np.eye(4)}
        pending = list(self.joints)
        while pending:
            ready = [joint for joint in pending if joint.parent in poses]
            if not ready:
                break  # links not under root
            for joint in ready:
                poses[joint.child] = poses[joint.parent] @ joint.transform(positions.get(joint.name, 0.0))
                pending.remove(joint)
        return poses


def _transform(joint: UrdfJoint, matrix: np.ndarray, stamp: float) -> Transform:
    translation, rotation = translation_rotation(matrix)
    return Transform(joint.parent, joint.child, stamp, translation, rotation)


__all__ = ['MOVING_TYPES', 'RobotState', 'UrdfJoint', 'urdf_joints']
