"""The robot's URDF, written from the compiled MuJoCo model the simulator runs: one home for its kinematics.

RViz's RobotModel and robot_state_publisher read a robot as URDF. Rather than keep a second description by hand,
this walks the compiled model (ur5e_gripper.xml inside a scene, MuJoCo having resolved default classes, `fromto`
geoms and Euler angles) from the robot's root body down: each body becomes a link at the body's pose in its parent
(its joint's origin), a hinge a revolute joint, a slide a prismatic one, a body without a joint a fixed joint; the
primitive geoms become visuals and collisions (a capsule as a cylinder with two spheres, URDF having no capsule),
the bodies' inertia their inertials. Joint names are the model's, so /joint_states drives the URDF as it is.
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


def _joints(model: mujoco.MjModel, body: int, parent_link: str, child_link: str) -> list[ElementTree.Element]:
    """The URDF joints that connect `child_link` to `parent_link`: one for a body with no joint (fixed) or one joint;
    for a body with several (a mobile base's x, y and yaw), a chain through a massless link per joint, each joint
    placed where MuJoCo puts it (a hinge's `pos` off the body frame included) and the body fixed after the last."""
    if body == model.body_rootid[body] or model.body_parentid[body] == 0:  # the root: where the model puts it
        data = mujoco.MjData(model)
        mujoco.mj_kinematics(model, data)
        position, quaternion = data.xpos[body], data.xquat[body]
    else:
        position, quaternion = model.body_pos[body], model.body_quat[body]
    count = int(model.body_jntnum[body])
    if count == 0:
        joint = ElementTree.Element('joint', name=f'{parent_link}_to_{child_link}', type='fixed')
        _origin(joint, position, quaternion)
        ElementTree.SubElement(joint, 'parent', link=parent_link)
        ElementTree.SubElement(joint, 'child', link=child_link)
        return [joint]
    elements, parent, offset = [], parent_link, np.zeros(3)  # offset: the previous joint's pos in the body frame
    for number in range(count):
        index = model.body_jntadr[body] + number
        kind = int(model.jnt_type[index])
        name = mujoco.mj_id2name(model, _NAME.mjOBJ_JOINT, index)
        if kind not in (_HINGE, _SLIDE):
            raise ValueError(f'the joint {name!r} of body {child_link!r} is neither a hinge nor a slide')
        last = number == count - 1
        link = child_link if last and not np.any(np.abs(model.jnt_pos[index]) > 1e-9) else f'{child_link}_{name}'
        # An unlimited hinge (a mobile base's yaw, which counts whole turns) is a continuous joint.
        joint_type = 'prismatic' if kind == _SLIDE else 'revolute' if model.jnt_limited[index] else 'continuous'
        joint = ElementTree.Element('joint', name=name, type=joint_type)
        pos = np.asarray(model.jnt_pos[index], dtype=float)
        if number == 0:  # the body's pose, then the joint's place in the body frame
            rotation = np.zeros(9)
            mujoco.mju_quat2Mat(rotation, np.asarray(quaternion, dtype=float))
            _origin(joint, np.asarray(position) + rotation.reshape(3, 3) @ pos, quaternion)
        else:  # the frames of one body's joints share its orientation
            _origin(joint, pos - offset, (1.0, 0.0, 0.0, 0.0))
        offset = pos
        ElementTree.SubElement(joint, 'parent', link=parent)
        ElementTree.SubElement(joint, 'child', link=link)
        ElementTree.SubElement(joint, 'axis', xyz=_numbers(model.jnt_axis[index]))
        if kind == _SLIDE and not model.jnt_limited[index]:
            low, high = -100.0, 100.0  # URDF wants limits; an unlimited slide (a mobile base) gets a room's worth
        else:
            low, high = model.jnt_range[index] if model.jnt_limited[index] else (-2 * math.pi, 2 * math.pi)
        actuator_force = [model.actuator_forcerange[a][1] for a in range(model.nu)
                          if model.actuator_trntype[a] == _JOINT_TRANSMISSION and model.actuator_trnid[a][0] == index
                          and model.actuator_forcelimited[a]]
        ElementTree.SubElement(joint, 'limit', lower=f'{low:.6g}', upper=f'{high:.6g}',
                               effort=f'{(actuator_force or [100.0])[0]:.6g}', velocity=f'{math.pi:.6g}')
        elements.append(joint)
        if link != child_link:
            elements.append(ElementTree.Element('link', name=link))
            if last:  # the body itself, back from the last joint's place to the body frame
                fixed = ElementTree.Element('joint', name=f'{link}_to_{child_link}', type='fixed')
                _origin(fixed, -pos, (1.0, 0.0, 0.0, 0.0))
                ElementTree.SubElement(fixed, 'parent', link=link)
                ElementTree.SubElement(fixed, 'child', link=child_link)
                elements.append(fixed)
        parent = link
    return elements


def robot_urdf(model: mujoco.MjModel, root_body: str = ROOT_BODY, robot_name: str = 'ur5e_gripper') -> str:
    """The URDF of the bodies under `root_body` (itself included), fixed in the `world` link where the model puts it."""
    root = mujoco.mj_name2id(model, _NAME.mjOBJ_BODY, root_body)
    if root < 0:
        raise ValueError(f'the model has no body {root_body!r}')
    robot = ElementTree.Element('robot', name=robot_name)
    robot.append(ElementTree.Comment(' Written by cap_sim_bridge.urdf from the MuJoCo model the simulator runs. '))
    robot.append(ElementTree.Element('link', name=WORLD_LINK))
    names = {}
    for body in range(root, model.nbody):
        parent = model.body_parentid[body]
        if body != root and parent not in names:
            continue  # not under the robot's root (an object, a camera mount)
        name = mujoco.mj_id2name(model, _NAME.mjOBJ_BODY, body) or f'body{body}'
        names[body] = name
        robot.append(_link(model, body, name))
        robot.extend(_joints(model, body, WORLD_LINK if body == root else names[parent], name))
    ElementTree.indent(robot)
    return '<?xml version="1.0"?>\n' + ElementTree.tostring(robot, encoding='unicode') + '\n'


__all__ = ['ROOT_BODY', 'WORLD_LINK', 'robot_urdf', 'rpy_of_quaternion']
