"""The kitchen scene: a room with counters, tables, chairs and bins (cap_mobile.layout) and the mobile manipulator
(cap_mobile.robot): a round base on planar joints with the UR5e and its gripper on top and a head camera.

The base moves as mobile bases in MuJoCo commonly do: slide joints along x and y and a hinge about z, each driven
by a stiff position servo (the world sends references with their velocities, as for the arm's joints), so the base
follows a timed path exactly and stops where it is told; it floats a centimetre above the floor and collides with
the furniture. The arm is models/ur5e_gripper.xml's, included as in every scene; its root body carries the base's
joints and body, so the whole robot moves together.
"""
from __future__ import annotations

import math
from typing import Sequence

import mujoco
import numpy as np
from cap_mobile import layout, objects as mobile_objects, robot

from cap_sim_bridge import objects as objects_module
from cap_sim_bridge.objects import ObjectKind, ObjectSpec, object_geom, register_object_kind
from cap_sim_bridge.scenes import MODELS_DIR, SceneSpec, spec_from_mjcf
# The fruit kinds ("apple", ...) are the whiteboard scene's: importing it registers them.
from cap_sim_bridge.scenes import whiteboard  # noqa: F401

NAME = 'mobile'
BASE_BODY = 'mobile_base'
ROBOT_ROOT_BODY = 'base'  # the UR5e's root body in ur5e_gripper.xml
TABLETOP_PEDESTAL = 'pedestal'  # the geom of ur5e_gripper.xml the arm stands on at the table top

# The base's physics, which the layout's facts leave to the simulator. Servo gains: critically damped for the base's
# mass (and the yaw's inertia, arm folded), stiff enough that a timed path is followed to a few millimetres.
BASE_MASS = 60.0  # [kg]
BASE_XY_SERVO = {'kp': 20000.0, 'kv': 2500.0, 'force': 1500.0}  # [N/m, N s/m, N]
BASE_YAW_SERVO = {'kp': 2000.0, 'kv': 200.0, 'force': 500.0}  # [N m/rad, N m s/rad, N m]

# Furniture and walls collide with everything (as the table top's table); the robot's geoms with them only.
_STATIC = {'contype': 1, 'conaffinity': 3}
_ROBOT = {'contype': 2, 'conaffinity': 0}
_VISUAL = {'contype': 0, 'conaffinity': 0}
_BOX = mujoco.mjtGeom.mjGEOM_BOX
_WOOD, _LEGS, _WALL = [0.72, 0.6, 0.45, 1], [0.3, 0.3, 0.32, 1], [0.9, 0.9, 0.87, 1]
_COLOURS = {'countertop': [0.85, 0.85, 0.82, 1], 'office chair': [0.15, 0.15, 0.18, 1], 'chair': [0.55, 0.4, 0.28, 1],
            'barstool': [0.25, 0.25, 0.27, 1], 'green bin': [0.25, 0.55, 0.25, 1],
            'blue bin': [0.2, 0.35, 0.75, 1], 'grey bin': [0.3, 0.3, 0.3, 1]}


def _box(body: mujoco.MjsBody, name: str, centre: Sequence[float], half: Sequence[float], rgba, **contact) -> None:
    body.add_geom(name=name, type=_BOX, pos=list(centre), size=list(half), rgba=rgba, **(contact or _STATIC))


def _add_walls(spec: mujoco.MjSpec) -> None:
    (x0, x1), (y0, y1), t, height = layout.ROOM_X_RANGE, layout.ROOM_Y_RANGE, layout.WALL_THICKNESS, 1.2
    world = spec.worldbody
    _box(world, 'wall_-x', (x0 - t / 2, 0, height / 2), (t / 2, (y1 - y0) / 2 + t, height / 2), _WALL)
    _box(world, 'wall_+x', (x1 + t / 2, 0, height / 2), (t / 2, (y1 - y0) / 2 + t, height / 2), _WALL)
    _box(world, 'wall_-y', (0, y0 - t / 2, height / 2), ((x1 - x0) / 2, t / 2, height / 2), _WALL)
    _box(world, 'wall_+y', (0, y1 + t / 2, height / 2), ((x1 - x0) / 2, t / 2, height / 2), _WALL)


def _add_piece(spec: mujoco.MjSpec, piece: layout.Furniture) -> None:
    """One piece of furniture as static geoms named after it; its top surface at piece.top over its footprint."""
    world, name = spec.worldbody, piece.name.replace(' ', '_')
    (x, y), (sx, sy, top) = piece.centre, piece.size
    colour = _COLOURS.get(piece.name, _WOOD)
    if piece.kind == 'bin':  # open at the top, so that objects can be dropped in
        wall = 0.01
        _box(world, f'{name}_bottom', (x, y, wall / 2), (sx / 2, sy / 2, wall / 2), colour)
        for side, (dx, dy) in layout.SIDES.items():
            half = (wall / 2, sy / 2, top / 2) if dx else (sx / 2, wall / 2, top / 2)
            _box(world, f'{name}_wall_{side}', (x + dx * (sx - wall) / 2, y + dy * (sy - wall) / 2, top / 2), half,
                 colour)
    elif piece.round:  # a pedestal and a round seat
        world.add_geom(name=f'{name}_seat', type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[sx / 2, 0.03, 0],
                       pos=[x, y, top - 0.03], rgba=colour, **_STATIC)
        world.add_geom(name=f'{name}_post', type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[0.04, (top - 0.06) / 2, 0],
                       pos=[x, y, (top - 0.06) / 2], rgba=_LEGS, **_STATIC)
        world.add_geom(name=f'{name}_foot', type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[sx / 2 - 0.02, 0.01, 0],
                       pos=[x, y, 0.01], rgba=_LEGS, **_STATIC)
    elif piece.kind == 'seat':  # a seat at 0.46 m and a back on the side away from the approach
        seat = 0.46
        _box(world, f'{name}_seat', (x, y, seat - 0.03), (sx / 2, sy / 2, 0.03), colour)
        _box(world, f'{name}_base', (x, y, (seat - 0.06) / 2), (0.05, 0.05, (seat - 0.06) / 2), _LEGS)
        nx, ny = layout.SIDES[piece.approach_side]
        half = (0.03, sy / 2, (top - seat) / 2) if nx else (sx / 2, 0.03, (top - seat) / 2)
        _box(world, f'{name}_back', (x - nx * (sx / 2 - 0.03), y - ny * (sy / 2 - 0.03), (top + seat) / 2), half,
             colour)
    elif piece.name == 'countertop':  # a cabinet under the top
        _box(world, name, (x, y, top - 0.02), (sx / 2, sy / 2, 0.02), colour)
        _box(world, f'{name}_cabinet', (x, y, (top - 0.04) / 2), (sx / 2 - 0.03, sy / 2 - 0.03, (top - 0.04) / 2),
             _WOOD)
    else:  # a table or desk: a top on four legs
        _box(world, name, (x, y, top - 0.02), (sx / 2, sy / 2, 0.02), colour)
        for i, (dx, dy) in enumerate(((-1, -1), (-1, 1), (1, -1), (1, 1))):
            _box(world, f'{name}_leg_{i}', (x + dx * (sx / 2 - 0.04), y + dy * (sy / 2 - 0.04), (top - 0.04) / 2),
                 (0.025, 0.025, (top - 0.04) / 2), _LEGS)


def _add_mobile_base(spec: mujoco.MjSpec) -> None:
    """Make the UR5e's root body the mobile base: the base's joints, body, mast and head camera go on it, and it
    stands ARM_MOUNT ahead of and above the base's centre, about which the base turns."""
    spec.delete(spec.geom(TABLETOP_PEDESTAL))  # the arm stands on the base here
    root = spec.body(ROBOT_ROOT_BODY)
    root.pos = list(robot.ARM_MOUNT)
    centre = [-robot.ARM_MOUNT[0], -robot.ARM_MOUNT[1], 0.0]  # the base's centre in the root body's frame
    joint_x, joint_y, joint_yaw = robot.BASE_JOINT_NAMES
    for name, kind, axis in ((joint_x, mujoco.mjtJoint.mjJNT_SLIDE, [1, 0, 0]),
                             (joint_y, mujoco.mjtJoint.mjJNT_SLIDE, [0, 1, 0]),
                             (joint_yaw, mujoco.mjtJoint.mjJNT_HINGE, [0, 0, 1])):
        # Not the arm's joint defaults (the root body's class): no limits, no armature, no damping.
        root.add_joint(name=name, type=kind, axis=axis, pos=centre, limited=mujoco.mjtLimited.mjLIMITED_FALSE,
                       armature=0.0, damping=0.0)

    def at(x: float, y: float, z: float) -> list[float]:  # base-frame point in the root body's frame
        return [x - robot.ARM_MOUNT[0], y - robot.ARM_MOUNT[1], z - robot.ARM_MOUNT[2]]

    half_height = (robot.BASE_HEIGHT - robot.BASE_CLEARANCE) / 2
    root.add_geom(name='base_body', type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[robot.BASE_RADIUS, half_height, 0],
                  pos=at(0, 0, robot.BASE_CLEARANCE + half_height), mass=BASE_MASS, rgba=[0.85, 0.85, 0.88, 1],
                  **_ROBOT)
    # A stripe on the front, so that pictures show which way the base faces.
    root.add_geom(name='base_front', type=_BOX, size=[0.02, 0.08, 0.03],
                  pos=at(robot.BASE_RADIUS - 0.015, 0, robot.BASE_HEIGHT - 0.06), rgba=[0.9, 0.45, 0.1, 1],
                  mass=0.1, **_VISUAL)
    cam_x, cam_y, cam_z = robot.HEAD_CAMERA_POSITION
    root.add_geom(name='head_mast', type=_BOX, size=[0.02, 0.02, (cam_z - robot.BASE_HEIGHT) / 2],
                  pos=at(cam_x - 0.04, cam_y, (cam_z + robot.BASE_HEIGHT) / 2), rgba=[0.3, 0.3, 0.32, 1], mass=1.0,
                  **_VISUAL)
    root.add_geom(name='head_box', type=_BOX, size=[0.03, 0.09, 0.025], pos=at(cam_x - 0.01, cam_y, cam_z),
                  rgba=[0.1, 0.1, 0.12, 1], mass=0.3, **_VISUAL)
    # A MuJoCo camera looks along its -z with +y up: x axis to the right (-y of the base), y up, tilted down.
    pitch = robot.HEAD_CAMERA_PITCH
    root.add_camera(name=robot.HEAD_CAMERA, pos=at(*robot.HEAD_CAMERA_POSITION),
                    xyaxes=[0, -1, 0, math.sin(pitch), 0, math.cos(pitch)], fovy=robot.HEAD_CAMERA_FOVY)
    # The follow camera keeps its offset in the room and its orientation while the robot moves (MuJoCo's
    # "trackcom" mode), looking at the robot from behind and above.
    forward = -np.array(robot.FOLLOW_CAMERA_OFFSET) + [0, 0, robot.FOLLOW_CAMERA_TARGET_HEIGHT]
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, [0, 0, 1])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    follow = root.add_camera(name=robot.FOLLOW_CAMERA, pos=at(*robot.FOLLOW_CAMERA_OFFSET),
                             xyaxes=[*right, *up], fovy=robot.FOLLOW_CAMERA_FOVY)
    follow.mode = mujoco.mjtCamLight.mjCAMLIGHT_TRACKCOM
    for name, servo in ((joint_x, BASE_XY_SERVO), (joint_y, BASE_XY_SERVO), (joint_yaw, BASE_YAW_SERVO)):
        actuator = spec.add_actuator(name=name, target=name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        actuator.set_to_position(kp=servo['kp'], kv=servo['kv'])
        actuator.forcelimited = True
        actuator.forcerange = [-servo['force'], servo['force']]


def build(objects: Sequence[ObjectSpec]) -> mujoco.MjSpec:
    spec = spec_from_mjcf((MODELS_DIR / 'mobile.xml').read_text(encoding='utf-8'))
    _add_walls(spec)
    for piece in layout.FURNITURE:
        _add_piece(spec, piece)
    _add_mobile_base(spec)
    return objects_module.add_objects(spec, objects)


def _kind_geoms(kind: mobile_objects.KitchenKind):
    def add(body: mujoco.MjsBody, obj: ObjectSpec) -> None:
        if kind.shape == 'cylinder':
            object_geom(body, obj, name=obj.name, type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=list(kind.size),
                        mass=kind.mass)
        else:
            object_geom(body, obj, name=obj.name, type=_BOX, size=list(kind.size), mass=kind.mass)
    return add


for _kind in mobile_objects.KINDS.values():
    register_object_kind(ObjectKind(_kind.name, _kind_geoms(_kind), _kind.resting_height, _kind.color_name))


def default_objects(seed: int) -> list[ObjectSpec]:
    """The seed's episode (cap_mobile.objects.default_objects): snacks, drinks and fruit."""
    return [ObjectSpec.from_name(name) for name in mobile_objects.default_objects(seed)]


def spawn_positions(specs: Sequence[ObjectSpec], seed: int) -> list[tuple[float, float, float]]:
    """(x, y, height of the surface there) for every object: on the furniture tops, or where a spec says."""
    return mobile_objects.spawn_positions(len(specs), seed, [spec.position for spec in specs])


def initialize(model: mujoco.MjModel, data: mujoco.MjData, seed: int) -> None:
    """The base at the layout's start pose (the world's base then holds there)."""
    for name, value in zip(robot.BASE_JOINT_NAMES, layout.START_POSE):
        data.qpos[model.jnt_qposadr[model.joint(name).id]] = value


SCENE = SceneSpec(NAME, build=build, default_objects=default_objects, spawn_positions=spawn_positions,
                  camera_names=(robot.HEAD_CAMERA,), home_joints=robot.STOWED_JOINTS, initialize=initialize,
                  visibility_camera=robot.HEAD_CAMERA,
                  description='a kitchen-office with counters, tables, chairs, bins, snacks, drinks and fruit; the '
                              'UR5e on a mobile base')

__all__ = ['BASE_BODY', 'NAME', 'SCENE', 'build']
