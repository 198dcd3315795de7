"""The scenes the simulator knows, by name: one module per domain in this folder, and any other package's.

A scene is the fixed part of a MuJoCo model (the UR5e with its gripper, a table, cameras, lights) plus the rules of
its episodes (which objects a seed gives, where they spawn). The world drives the robot of models/ur5e_gripper.xml,
so every scene must contain it: an MJCF scene includes it with ``<include file="ur5e_gripper.xml"/>``
(`spec_from_mjcf` resolves that include). Objects are added per reset as free bodies (`objects.add_objects`).

A scene is named after its domain and offered as an entry point of the group `cap_ros.scenes` (value: a SceneSpec):
this package's setup.py offers every module of this folder (`scenes/<domain>.py` defining SCENE); another package
adds a line to its own setup.py::

    entry_points={'cap_ros.scenes': ['toy = toy_package.scene:SCENE']}

with ``SCENE = SceneSpec('toy', build=mjcf_builder(TOY_MJCF), camera_names=('top',))``; then
``World('toy', seed, objects)`` or the bridge node's ``scene`` parameter picks it.
"""
from __future__ import annotations

import dataclasses
import pathlib
from typing import Callable, Sequence

import mujoco
from cap_ros_common.plugins import PluginGroup
from cap_tabletop.workspace import REST_JOINTS

from cap_sim_bridge import objects as objects_module
from cap_sim_bridge.ink import InkSpec
from cap_sim_bridge.objects import ObjectSpec

MODELS_DIR = pathlib.Path(__file__).resolve().parents[1] / 'models'
ROBOT_MJCF = 'ur5e_gripper.xml'  # the arm and gripper every scene must contain, by this include file name
GRIPPER_MAX_OPENING = 0.085  # [m], pad to pad, of that gripper
DEFAULT_SCENE = 'tabletop'


@dataclasses.dataclass(frozen=True)
class SceneSpec:
    """One scene. build(objects) returns the uncompiled model with those objects added (the world compiles it).

    default_objects(seed): the objects of a reset that names none. spawn_positions(objects, seed): an (x, y) per
    object (objects with a position keep it), or (x, y, z) with the height of the surface it stands on (otherwise
    surface_z). camera_names: the cameras the bridge publishes by default. visibility_camera: the camera whose view
    decides an object's `visible` flag in the ground truth (by ray tests against the scene); None: every object
    counts as visible.
    """

    name: str
    build: Callable[[Sequence[ObjectSpec]], mujoco.MjSpec]
    default_objects: Callable[[int], list[ObjectSpec]] = lambda seed: []
    spawn_positions: Callable[[Sequence[ObjectSpec], int], list[tuple[float, ...]]] = \
        objects_module.sample_spawn_positions
    camera_names: tuple[str, ...] = ()
    description: str = ''
    surface_z: float = 0.0  # height of the surface objects rest on at reset [m]
    ink: InkSpec | None = None  # a surface the tool draws on (cap_sim_bridge.ink), if the scene has one
    home_gripper_opening: float = GRIPPER_MAX_OPENING  # the fingers' opening at reset [m] (open, by default)
    home_joints: tuple[float, ...] = tuple(REST_JOINTS)  # the arm's joints at reset [rad]
    visibility_camera: str | None = None
    # initialize(model, data, seed): the scene's own seeded start state after the robot and objects are placed
    # (e.g. a cart-pole's initial lean); None: nothing.
    initialize: Callable[[mujoco.MjModel, mujoco.MjData, int], None] | None = None
    # restart_plant(model, data, seed): puts the scene's own joints (a plant a controller drives) back at the start
    # a reset with `seed` gives them, at rest, mid-episode (each controller run starts there); None: the scene's
    # joints have no such start, and a run of them is refused.
    restart_plant: Callable[[mujoco.MjModel, mujoco.MjData, int], None] | None = None


def robot_include() -> dict[str, bytes]:
    """The include files an MJCF scene may name: the robot, by ROBOT_MJCF."""
    return {ROBOT_MJCF: (MODELS_DIR / ROBOT_MJCF).read_bytes()}


def spec_from_mjcf(text: str) -> mujoco.MjSpec:
    """An MjSpec from MJCF text that may ``<include file="ur5e_gripper.xml"/>``."""
    return mujoco.MjSpec.from_string(text, include=robot_include())


def mjcf_builder(text: str) -> Callable[[Sequence[ObjectSpec]], mujoco.MjSpec]:
    """A SceneSpec.build for a scene given as MJCF text: the text plus one body per object (blocks and bowls)."""
    def build(objects: Sequence[ObjectSpec]) -> mujoco.MjSpec:
        return objects_module.add_objects(spec_from_mjcf(text), objects)
    return build


# Every scene, this package's own included, is an entry point of this group (name = the scene's name = its domain's
# name, value = a SceneSpec).
ENTRY_POINT_GROUP = 'cap_ros.scenes'
_scenes: PluginGroup[SceneSpec] = PluginGroup(ENTRY_POINT_GROUP, 'scene', lambda value: isinstance(value, SceneSpec))


def get_scene(name: str) -> SceneSpec:
    """The scene called `name`; ValueError naming the known scenes otherwise."""
    spec = _scenes.get(name)
    if spec.name != name:
        raise ValueError(f'the scene offered as {name!r} calls itself {spec.name!r}')
    return spec


def scene_names() -> list[str]:
    """The names of every scene offered (by this package or another)."""
    return _scenes.names()


def build_model(objects: Sequence[ObjectSpec], scene: str = DEFAULT_SCENE) -> mujoco.MjModel:
    """Compile the named scene with one free body per object."""
    return get_scene(scene).build(objects).compile()
