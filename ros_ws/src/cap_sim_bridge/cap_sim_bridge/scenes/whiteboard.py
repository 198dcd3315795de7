"""The whiteboard scene: the table top with a whiteboard lying on it, a drawing tool on the UR5e, and blocks and fruit
standing on the board (cap_whiteboard holds every size and place used here).

The tool is part of the robot in this scene: a spring-loaded marker along the flange's axis and a sprung felt
eraser on its side (cap_whiteboard.tool), attached to the gripper's body, so it moves rigidly with the wrist. Ink is
laid and wiped by the tool's contacts with the board (cap_sim_bridge.ink); a texture on the board shows it in
the cameras' renders. Fruit are object kinds of their own ("apple", "lemon", ...), registered here.
"""
from __future__ import annotations

import math
from typing import Sequence

import mujoco
from cap_tabletop import cameras as tabletop_cameras
from cap_whiteboard import board, objects as board_objects, tool

from cap_sim_bridge import objects as objects_module
from cap_sim_bridge.ink import InkSpec
from cap_sim_bridge.objects import ObjectKind, ObjectSpec, object_geom, register_object_kind
from cap_sim_bridge.scenes import MODELS_DIR, SceneSpec

NAME = 'whiteboard'
BOARD_GEOM = 'whiteboard'
INK_GEOM = 'whiteboard_ink'
INK_TEXTURE = 'whiteboard_ink'
MARKER_TIP_GEOM = 'marker_tip'
ERASER_PAD_GEOM = 'eraser_pad'
MARKER_JOINT = tool.MARKER_JOINT
ERASER_JOINT = tool.ERASER_JOINT
TOOL_PARENT_BODY = 'gripper_base'  # of ur5e_gripper.xml

# Robot geoms collide with the board and the objects but not with the rest of the robot (ur5e_gripper.xml).
_ROBOT_CONTACT = {'contype': 2, 'conaffinity': 0}
_MARKER_MASS = 0.02  # [kg]
_ERASER_MASS = 0.03
# The tool springs push their slides against a stop; a stiff stop (time constant of two 2 ms steps, the least that
# stays stable) keeps the tip where the facts say, instead of sinking into MuJoCo's default soft limit.
_STOP_SOLREF = [0.004, 1.0]

INK = InkSpec(surface_geom=BOARD_GEOM, marker_geom=MARKER_TIP_GEOM, eraser_geom=ERASER_PAD_GEOM,
              x_range=board.X_RANGE, y_range=board.Y_RANGE, resolution=board.INK_RESOLUTION,
              tip_width=tool.MARKER_TIP_WIDTH, texture=INK_TEXTURE)


def _add_board(spec: mujoco.MjSpec) -> None:
    (x0, x1), (y0, y1) = board.X_RANGE, board.Y_RANGE
    centre = [(x0 + x1) / 2, (y0 + y1) / 2]
    # Low friction: a marker glides on a whiteboard.
    spec.worldbody.add_geom(name=BOARD_GEOM, type=mujoco.mjtGeom.mjGEOM_BOX,
                            size=[(x1 - x0) / 2, (y1 - y0) / 2, board.THICKNESS / 2],
                            pos=centre + [board.THICKNESS / 2], rgba=[0.93, 0.93, 0.9, 1], contype=1,
                            conaffinity=3, friction=[0.3, 0.005, 0.0001])
    rows, cols = INK.shape
    spec.add_texture(name=INK_TEXTURE, type=mujoco.mjtTexture.mjTEXTURE_2D, builtin=mujoco.mjtBuiltin.mjBUILTIN_FLAT,
                     width=cols, height=rows, rgb1=[c / 255 for c in INK.board_rgb],
                     rgb2=[c / 255 for c in INK.board_rgb])
    material = spec.add_material(name=INK_TEXTURE, texrepeat=[1, 1], texuniform=False)
    material.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = INK_TEXTURE
    # The ink is drawn on a plane a hair above the board's surface (visual only; the board's box takes contacts).
    spec.worldbody.add_geom(name=INK_GEOM, type=mujoco.mjtGeom.mjGEOM_PLANE,
                            size=[(x1 - x0) / 2, (y1 - y0) / 2, 0.01], pos=centre + [board.SURFACE_Z + 0.0003],
                            material=INK_TEXTURE, contype=0, conaffinity=0)


def _add_tool(spec: mujoco.MjSpec) -> None:
    parent = spec.body(TOOL_PARENT_BODY)
    # Marker: a pen on a preloaded spring along the flange's +z; its tip sphere is what touches the board.
    marker = parent.add_body(name='marker', gravcomp=1)
    marker.add_joint(name=MARKER_JOINT, type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[0, 0, 1],
                     range=[-tool.MARKER_TRAVEL, 0.0], stiffness=tool.MARKER_STIFFNESS,
                     springref=tool.MARKER_PRELOAD / tool.MARKER_STIFFNESS,
                     damping=2 * math.sqrt(tool.MARKER_STIFFNESS * _MARKER_MASS), armature=0.005,
                     solref_limit=_STOP_SOLREF)
    tip_radius = tool.MARKER_TIP_WIDTH / 2
    barrel_end = tool.MARKER_TIP_OFFSET - 0.015
    marker.add_geom(name='marker_barrel', type=mujoco.mjtGeom.mjGEOM_CAPSULE, size=[tool.MARKER_RADIUS, 0, 0],
                    fromto=[0, 0, 0.09, 0, 0, barrel_end], rgba=[0.1, 0.2, 0.55, 1], mass=_MARKER_MASS * 0.9,
                    **_ROBOT_CONTACT)
    marker.add_geom(name='marker_nib', type=mujoco.mjtGeom.mjGEOM_CAPSULE, size=[tip_radius, 0, 0],
                    fromto=[0, 0, barrel_end, 0, 0, tool.MARKER_TIP_OFFSET - 2 * tip_radius],
                    rgba=[0.08, 0.15, 0.45, 1], mass=_MARKER_MASS * 0.05, **_ROBOT_CONTACT)
    marker.add_geom(name=MARKER_TIP_GEOM, type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[tip_radius, 0, 0],
                    pos=[0, 0, tool.MARKER_TIP_OFFSET - tip_radius], rgba=[0.08, 0.15, 0.45, 1],
                    mass=_MARKER_MASS * 0.05, friction=[0.2, 0.005, 0.0001], **_ROBOT_CONTACT)
    # Eraser: a felt pad on a preloaded spring along the flange's +x, on a bracket beside the palm.
    pad_along_z, pad_along_y = tool.ERASER_PAD_SIZE
    pad_centre_x = tool.ERASER_FACE_OFFSET - tool.ERASER_THICKNESS / 2
    bracket_end = pad_centre_x - tool.ERASER_THICKNESS / 2 - tool.ERASER_TRAVEL
    parent.add_geom(name='eraser_bracket', type=mujoco.mjtGeom.mjGEOM_BOX,
                    size=[(bracket_end - 0.03) / 2, 0.012, 0.012],
                    pos=[(bracket_end + 0.03) / 2, 0, tool.ERASER_FACE_HEIGHT], rgba=[0.3, 0.3, 0.32, 1],
                    mass=0.02, contype=0, conaffinity=0)
    eraser = parent.add_body(name='eraser', gravcomp=1)
    eraser.add_joint(name=ERASER_JOINT, type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[1, 0, 0],
                     range=[-tool.ERASER_TRAVEL, 0.0], stiffness=tool.ERASER_STIFFNESS,
                     springref=tool.ERASER_PRELOAD / tool.ERASER_STIFFNESS,
                     damping=2 * math.sqrt(tool.ERASER_STIFFNESS * _ERASER_MASS), armature=0.005,
                     solref_limit=_STOP_SOLREF)
    eraser.add_geom(name=ERASER_PAD_GEOM, type=mujoco.mjtGeom.mjGEOM_BOX,
                    size=[tool.ERASER_THICKNESS / 2, pad_along_y / 2, pad_along_z / 2],
                    pos=[pad_centre_x, 0, tool.ERASER_FACE_HEIGHT], rgba=[0.55, 0.55, 0.58, 1], mass=_ERASER_MASS,
                    friction=[0.5, 0.005, 0.0001], **_ROBOT_CONTACT)


def _build(objects: Sequence[ObjectSpec]) -> mujoco.MjSpec:
    spec = mujoco.MjSpec.from_file(str(MODELS_DIR / 'tabletop.xml'))
    spec.modelname = 'cap_whiteboard'
    for camera in tabletop_cameras.CAMERAS.values():
        spec.worldbody.add_camera(name=camera.name, pos=list(camera.position), quat=list(camera.orientation),
                                  fovy=camera.fovy)
    _add_board(spec)
    _add_tool(spec)
    return objects_module.add_objects(spec, objects)


def _fruit_geoms(kind: board_objects.FruitKind):
    def add(body: mujoco.MjsBody, obj: ObjectSpec) -> None:
        if kind.shape == 'ellipsoid':
            object_geom(body, obj, name=obj.name, type=mujoco.mjtGeom.mjGEOM_ELLIPSOID, size=list(kind.size),
                        mass=kind.mass)
        else:  # a capsule lying along x
            radius, half_length, _ = kind.size
            object_geom(body, obj, name=obj.name, type=mujoco.mjtGeom.mjGEOM_CAPSULE, size=[radius, 0, 0],
                        fromto=[-half_length, 0, 0, half_length, 0, 0], mass=kind.mass)
    return add


for _kind in board_objects.FRUIT.values():
    register_object_kind(ObjectKind(_kind.name, _fruit_geoms(_kind), _kind.resting_height, _kind.color_name))


def default_objects(seed: int) -> list[ObjectSpec]:
    """The seed's default episode: two blocks and two fruit (cap_whiteboard.objects)."""
    return [ObjectSpec(name, category, colour) for name, category, colour in board_objects.default_objects(seed)]


def spawn_positions(specs: Sequence[ObjectSpec], seed: int) -> list[tuple[float, float]]:
    """xy for every object on the board, at least SPAWN_MIN_SEPARATION apart."""
    return objects_module.sample_spawn_positions(specs, seed, board_objects.SPAWN_X_RANGE,
                                                 board_objects.SPAWN_Y_RANGE, board_objects.SPAWN_MIN_SEPARATION)


SCENE = SceneSpec(NAME, build=_build, default_objects=default_objects, spawn_positions=spawn_positions,
                  camera_names=tabletop_cameras.CAMERA_NAMES, surface_z=board.SURFACE_Z, ink=INK,
                  home_gripper_opening=tool.GRIP_OPENING,
                  description='a whiteboard on the table, a marker and an eraser on the arm, blocks and fruit')

__all__ = ['ERASER_JOINT', 'ERASER_PAD_GEOM', 'INK', 'MARKER_JOINT', 'MARKER_TIP_GEOM', 'NAME', 'SCENE',
           'default_objects', 'spawn_positions']
