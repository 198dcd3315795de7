"""The scenes the simulator knows, by name: a registry a domain adds its own scene to without editing this module.

A scene is the fixed part of a MuJoCo model (the UR5e with its gripper, a table, cameras, lights) plus the rules of
its episodes (which objects a seed gives, where they spawn). The world drives the robot of models/ur5e_gripper.xml,
so every scene must contain it: an MJCF scene includes it with ``<include file="ur5e_gripper.xml"/>``
(`spec_from_mjcf` resolves that include). Objects are added per reset as free bodies (`scene.add_objects`).

Registering a scene::

    from cap_sim_bridge.scenes import SceneSpec, mjcf_builder, register_scene
    register_scene(SceneSpec('toy', build=mjcf_builder(TOY_MJCF), camera_names=('top',)))

then ``TabletopWorld('toy', seed, objects)`` or the bridge node's ``scene`` parameter picks it.
"""
from __future__ import annotations

import dataclasses
import importlib
import importlib.metadata
import pathlib
import threading
from typing import Callable, Sequence

import mujoco
from cap_tabletop import cameras as tabletop_cameras
from cap_tabletop.workspace import REST_JOINTS

from cap_sim_bridge import scene as objects_module
from cap_sim_bridge.ink import InkSpec
from cap_sim_bridge.scene import ObjectSpec

MODELS_DIR = pathlib.Path(__file__).resolve().parent / 'models'
ROBOT_MJCF = 'ur5e_gripper.xml'  # the arm and gripper every scene must contain, by this include file name
GRIPPER_MAX_OPENING = 0.085  # [m], pad to pad, of that gripper
TABLETOP = 'tabletop'
DEFAULT_SCENE = TABLETOP


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


_registry: dict[str, SceneSpec] = {}
_lock = threading.Lock()


def register_scene(spec: SceneSpec, *, replace: bool = False) -> SceneSpec:
    """Make `spec` known by its name. ValueError if another scene has that name (unless replace)."""
    if not spec.name:
        raise ValueError('a scene needs a name')
    with _lock:
        if spec.name in _registry and not replace and _registry[spec.name] is not spec:
            raise ValueError(f'a scene named {spec.name!r} is already registered')
        _registry[spec.name] = spec
    return spec


def unregister_scene(name: str) -> None:
    """Forget a registered scene (tests that register a toy scene clean up with this)."""
    with _lock:
        _registry.pop(name, None)


# Other packages offer scenes as entry points of this group (name = the scene's name, value = a SceneSpec), so
# that a scene of theirs can be chosen by the bridge's `scene` parameter in any process.
ENTRY_POINT_GROUP = 'cap_ros.scenes'
_entry_points_loaded = False


# Scenes of this package beyond the table top, in modules of their own (imported when a scene is first looked up).
BUILT_IN_SCENE_MODULES = ('cap_sim_bridge.whiteboard_scene', 'cap_sim_bridge.kitchen_scene')


def _load_entry_points() -> None:
    global _entry_points_loaded
    if _entry_points_loaded:
        return
    _entry_points_loaded = True
    for module in BUILT_IN_SCENE_MODULES:
        register_scene(importlib.import_module(module).SCENE)
    for entry in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP):
        spec = entry.load()
        if isinstance(spec, SceneSpec):
            with _lock:
                _registry.setdefault(spec.name, spec)


def get_scene(name: str) -> SceneSpec:
    """The registered scene called `name`; ValueError naming the known scenes otherwise."""
    _load_entry_points()
    with _lock:
        spec = _registry.get(name)
        if spec is None:
            raise ValueError(f'unknown scene {name!r}; known scenes: {", ".join(sorted(_registry)) or "none"}')
        return spec


def scene_names() -> list[str]:
    """The names of every registered scene (built in, registered in this process, or offered by entry points)."""
    _load_entry_points()
    with _lock:
        return sorted(_registry)


def build_model(objects: Sequence[ObjectSpec], scene: str = DEFAULT_SCENE) -> mujoco.MjModel:
    """Compile the named scene with one free body per object."""
    return get_scene(scene).build(objects).compile()


# ------------------------------------------------------------------------------------------- the table top
def _build_tabletop(objects: Sequence[ObjectSpec]) -> mujoco.MjSpec:
    spec = mujoco.MjSpec.from_file(str(MODELS_DIR / 'tabletop.xml'))
    # The cameras' poses are table-top facts (perception and control use them too), so they are added here.
    for camera in tabletop_cameras.CAMERAS.values():
        spec.worldbody.add_camera(name=camera.name, pos=list(camera.position), quat=list(camera.orientation),
                                  fovy=camera.fovy)
    return objects_module.add_objects(spec, objects)


register_scene(SceneSpec(TABLETOP, build=_build_tabletop, default_objects=objects_module.default_objects,
                         spawn_positions=objects_module.sample_spawn_positions,
                         camera_names=tabletop_cameras.CAMERA_NAMES,
                         description='a table with blocks and bowls of the ten palette colours'))
