"""The robot's URDF, written from the compiled MuJoCo model the simulator runs: one home for its kinematics.

RViz's RobotModel and robot_state_publisher read a robot as URDF. Rather than keep a second description by hand,
this walks the compiled model (ur5e_gripper.xml inside a scene, MuJoCo having resolved default classes, `fromto`
geoms and Euler angles) from the robot's root body down: each body becomes a link at the body's pose in its parent
(its joint's origin), a hinge a revolute joint, a slide a prismatic one, a body without a joint a fixed joint; the
primitive geoms become visuals and collisions (a capsule as a cylinder with two spheres, URDF having no capsule),
the bodies' inertia their inertials. Joint names are the model's, so /joint_states drives the URDF as it is.

A fixed robot hangs from the `world` link where the model puts it. A mobile one (a root body with the planar joints
of a mobile base: x, y and a yaw about the base's centre) hangs from `base_link`, the base's centre on the floor
(REP-105): its pose in `odom` is the base joints' values, which the simulator sends as the transform
odom -> base_link, as a base driver does; the planar joints are not in the URDF.
Plain Python and MuJoCo, no ROS.
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ElementTree
from typing import Sequence

import mujoco
import numpy as np

ROOT_BODY = 'base'  # the robot's first body in ur5e_gripper.xml
WORLD_LINK = 'world'  # the frame every cap-ros pose is given in (markers, perception, the robot base)
BASE_LINK = 'base_link'  # a mobile robot's base frame: its centre on the floor, x forward (REP-105)
_NAME = mujoco.mjtObj
# The model's type fields are NumPy integers, which MuJoCo's enum members do not compare equal to.
_BOX, _SPHERE, _CYLINDER, _CAPSULE = (int(kind) for kind in (
    mujoco.mjtGeom.mjGEOM_BOX, mujoco.mjtGeom.mjGEOM_SPHERE, mujoco.mjtGeom.mjGEOM_CYLINDER,
    mujoco.mjtGeom.mjGEOM_CAPSULE))
_HINGE, _SLIDE = int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE)
_JOINT_TRANSMISSION = int(mujoco.mjtTrn.mjTRN_JOINT)  # an actuator on a joint (the gripper's is on a tendon)


def _numbers(values: Sequence[float]) -> str:
    return ' '.join(f'{float(value) + 0.0:.6g}' for value in values)  # + 0.0: no "-0"


def rpy_of_quaternion(quaternion: Sequence[float]) -> tuple[float, float, float]:
    """URDF roll, pitch, yaw (R = Rz(yaw) Ry(pitch) Rx(roll)) of a MuJoCo quaternion (w, x, y, z)."""
    matrix = np.zeros(9)
    mujoco.mju_quat2Mat(matrix, np.asarray(quaternion, dtype=float))
    r = matrix.reshape(3, 3)
    pitch = math.asin(max(-1.0, min(1.0, -r[2, 0])))
    if abs(r[2, 0]) < 1.0 - 1e-9:
        roll, yaw = math.atan2(r[2, 1], r[2, 2]), math.atan2(r[1, 0], r[0, 0])
    else:  # gimbal lock: the yaw alone carries the rotation about z
        roll, yaw = 0.0, math.atan2(-r[0, 1], r[1, 1])
    return roll, pitch, yaw


def _origin(parent: ElementTree.Element, position: Sequence[float], quaternion: Sequence[float]) -> None:
    ElementTree.SubElement(parent, 'origin', xyz=_numbers(position), rpy=_numbers(rpy_of_quaternion(quaternion)))


def _shapes(model: mujoco.MjModel, geom: int) -> list[tuple[ElementTree.Element, np.ndarray, np.ndarray]]:
    """(URDF geometry, position, quaternion) of one MuJoCo geom, in its body's frame; empty for other types."""
    kind, size = int(model.geom_type[geom]), model.geom_size[geom]
    position, quaternion = model.geom_pos[geom].copy(), model.geom_quat[geom].copy()
    shape = ElementTree.Element('geometry')
    if kind == _BOX:
        ElementTree.SubElement(shape, 'box', size=_numbers(2 * size))
    elif kind == _SPHERE:
        ElementTree.SubElement(shape, 'sphere', radius=f'{size[0]:.6g}')
    elif kind == _CYLINDER:
        ElementTree.SubElement(shape, 'cylinder', radius=f'{size[0]:.6g}', length=f'{2 * size[1]:.6g}')
    elif kind == _CAPSULE:
        ElementTree.SubElement(shape, 'cylinder', radius=f'{size[0]:.6g}', length=f'{2 * size[1]:.6g}')
        axis = np.zeros(9)
        mujoco.mju_quat2Mat(axis, quaternion)
        along = axis.reshape(3, 3)[:, 2] * size[1]  # the capsule's axis is its frame's z
        caps = []
        for end in (position + along, position - along):
            cap = ElementTree.Element('geometry')
            ElementTree.SubElement(cap, 'sphere', radius=f'{size[0]:.6g}')
            caps.append((cap, end, np.array([1.0, 0.0, 0.0, 0.0])))
        return [(shape, position, quaternion), *caps]
    else:
        return []
    return [(shape, position, quaternion)]


def _color(model: mujoco.MjModel, geom: int) -> np.ndarray:
    material = model.geom_matid[geom]
    return model.mat_rgba[material] if material >= 0 else model.geom_rgba[geom]


def _link(model: mujoco.MjModel, body: int, name: str) -> ElementTree.Element:
    link = ElementTree.Element('link', name=name)
    if model.body_mass[body] > 0:
        inertial = ElementTree.SubElement(link, 'inertial')
        _origin(inertial, model.body_ipos[body], model.body_iquat[body])
        ElementTree.SubElement(inertial, 'mass', value=f'{model.body_mass[body]:.6g}')
        ixx, iyy, izz = model.body_inertia[body]  # principal axes, in the inertial frame above
        ElementTree.SubElement(inertial, 'inertia', ixx=f'{ixx:.6g}', iyy=f'{iyy:.6g}', izz=f'{izz:.6g}',
                               ixy='0', ixz='0', iyz='0')
    for geom in range(model.ngeom):
        if model.geom_bodyid[geom] != body:
            continue
        for number, (shape, position, quaternion) in enumerate(_shapes(model, geom)):
            geom_name = mujoco.mj_id2name(model, _NAME.mjOBJ_GEOM, geom) or f'{name}_geom{geom}'
            visual = ElementTree.SubElement(link, 'visual', name=f'{geom_name}_{number}' if number else geom_name)
            _origin(visual, position, quaternion)
            visual.append(shape)
            material = ElementTree.SubElement(visual, 'material', name=f'{geom_name}_color')
            ElementTree.SubElement(material, 'color', rgba=_numbers(_color(model, geom)))
            collision = ElementTree.SubElement(link, 'collision')
            _origin(collision, position, quaternion)
            collision.append(shape)
    return link


def _fixed(name: str, parent: str, child: str, position: Sequence[float],
           quaternion: Sequence[float]) -> ElementTree.Element:
    joint = ElementTree.Element('joint', name=name, type='fixed')
    _origin(joint, position, quaternion)
    ElementTree.SubElement(joint, 'parent', link=parent)
    ElementTree.SubElement(joint, 'child', link=child)
    return joint


def _joint(model: mujoco.MjModel, body: int, parent_link: str, child_link: str) -> ElementTree.Element:
    """The URDF joint that connects `child_link` to `parent_link`: fixed for a body without a joint, else its one
    hinge (revolute) or slide (prismatic) at the joint's place in the body."""
    if body == model.body_rootid[body] or model.body_parentid[body] == 0:  # the root: where the model puts it
        data = mujoco.MjData(model)
        mujoco.mj_kinematics(model, data)
        position, quaternion = data.xpos[body], data.xquat[body]
    else:
        position, quaternion = model.body_pos[body], model.body_quat[body]
    count = int(model.body_jntnum[body])
    if count == 0:
        return _fixed(f'{parent_link}_to_{child_link}', parent_link, child_link, position, quaternion)
    index = model.body_jntadr[body]
    name = mujoco.mj_id2name(model, _NAME.mjOBJ_JOINT, index)
    kind = int(model.jnt_type[index])
    if count > 1 or kind not in (_HINGE, _SLIDE) or np.any(np.abs(model.jnt_pos[index]) > 1e-9):
        raise ValueError(f'body {child_link!r}: only one hinge or slide at the body frame is written as URDF')
    joint = ElementTree.Element('joint', name=name, type='prismatic' if kind == _SLIDE else 'revolute')
    _origin(joint, position, quaternion)
    ElementTree.SubElement(joint, 'parent', link=parent_link)
    ElementTree.SubElement(joint, 'child', link=child_link)
    ElementTree.SubElement(joint, 'axis', xyz=_numbers(model.jnt_axis[index]))
    low, high = model.jnt_range[index] if model.jnt_limited[index] else (-2 * math.pi, 2 * math.pi)
    actuator_force = [model.actuator_forcerange[a][1] for a in range(model.nu)
                      if model.actuator_trntype[a] == _JOINT_TRANSMISSION and model.actuator_trnid[a][0] == index
                      and model.actuator_forcelimited[a]]
    ElementTree.SubElement(joint, 'limit', lower=f'{low:.6g}', upper=f'{high:.6g}',
                           effort=f'{(actuator_force or [100.0])[0]:.6g}', velocity=f'{math.pi:.6g}')
    return joint


def _mobile_mount(model: mujoco.MjModel, root: int, child_link: str) -> ElementTree.Element:
    """base_link -> the root body, fixed: the root body's pose with the base's joints at zero (the base's centre at
    the origin, facing +x), where base_link is."""
    data = mujoco.MjData(model)
    for number in range(int(model.body_jntnum[root])):
        data.qpos[model.jnt_qposadr[model.body_jntadr[root] + number]] = 0.0
    mujoco.mj_kinematics(model, data)
    return _fixed(f'{BASE_LINK}_to_{child_link}', BASE_LINK, child_link, data.xpos[root], data.xquat[root])


def base_joint_names(model: mujoco.MjModel, root_body: str = ROOT_BODY) -> tuple[str, ...]:
    """The mobile base's planar joints on the robot's root body (x, y, yaw), or () for a fixed robot."""
    root = mujoco.mj_name2id(model, _NAME.mjOBJ_BODY, root_body)
    count = int(model.body_jntnum[root]) if root >= 0 else 0
    if count < 2:
        return ()
    return tuple(mujoco.mj_id2name(model, _NAME.mjOBJ_JOINT, model.body_jntadr[root] + number)
                 for number in range(count))


def robot_urdf(model: mujoco.MjModel, root_body: str = ROOT_BODY, robot_name: str = 'ur5e_gripper') -> str:
    """The URDF of the bodies under `root_body` (itself included): fixed in the `world` link where the model puts
    it, or, for a mobile robot (base joints on the root body), on `base_link`."""
    root = mujoco.mj_name2id(model, _NAME.mjOBJ_BODY, root_body)
    if root < 0:
        raise ValueError(f'the model has no body {root_body!r}')
    mobile = bool(base_joint_names(model, root_body))
    robot = ElementTree.Element('robot', name=robot_name)
    robot.append(ElementTree.Comment(' Written by cap_sim_bridge.urdf from the MuJoCo model the simulator runs. '))
    robot.append(ElementTree.Element('link', name=BASE_LINK if mobile else WORLD_LINK))
    names = {}
    for body in range(root, model.nbody):
        parent = model.body_parentid[body]
        if body != root and parent not in names:
            continue  # not under the robot's root (an object, a camera mount)
        name = mujoco.mj_id2name(model, _NAME.mjOBJ_BODY, body) or f'body{body}'
        names[body] = name
        robot.append(_link(model, body, name))
        if body == root and mobile:
            robot.append(_mobile_mount(model, root, name))
        else:
            robot.append(_joint(model, body, WORLD_LINK if body == root else names[parent], name))
    ElementTree.indent(robot)
    return '<?xml version="1.0"?>\n' + ElementTree.tostring(robot, encoding='unicode') + '\n'


__all__ = ['BASE_LINK', 'ROOT_BODY', 'WORLD_LINK', 'base_joint_names', 'robot_urdf', 'rpy_of_quaternion']
