"""The table-top scene: the UR5e with its gripper over a table, the two table-top cameras, blocks and bowls of the ten
palette colours (cap_tabletop holds every size, colour and camera pose used here; cap_sim_bridge.objects the
blocks' and bowls' bodies)."""
from __future__ import annotations

from typing import Sequence

import mujoco
from cap_tabletop import cameras as tabletop_cameras

from cap_sim_bridge import objects as objects_module
from cap_sim_bridge.objects import ObjectSpec
from cap_sim_bridge.scenes import MODELS_DIR, SceneSpec

NAME = 'tabletop'


def _build(objects: Sequence[ObjectSpec]) -> mujoco.MjSpec:
    spec = mujoco.MjSpec.from_file(str(MODELS_DIR / 'tabletop.xml'))
    # The cameras' poses are table-top facts (perception and control use them too), so they are added here.
    for camera in tabletop_cameras.CAMERAS.values():
        spec.worldbody.add_camera(name=camera.name, pos=list(camera.position), quat=list(camera.orientation),
                                  fovy=camera.fovy)
    return objects_module.add_objects(spec, objects)


SCENE = SceneSpec(NAME, build=_build, default_objects=objects_module.default_objects,
                  spawn_positions=objects_module.sample_spawn_positions, camera_names=tabletop_cameras.CAMERA_NAMES,
                  description='a table with blocks and bowls of the ten palette colours')
