"""What the robot's head camera would see from given base poses in a kitchen scene, asked before an episode runs
(can it be solved?) of a headless simulator of the kitchen in this process.

The episode's objects are placed and settled as the graph's scene reset places them; for each pose the base's joints
are set there for the ray test only (World.visible_with_base_at: nothing is driven, no time passes) and the answer is
the ray test of the head camera that answers is_obj_visible in the graph. A driven base stops within the navigation
node's goal tolerances of a pose, so a pose counts as showing an object only when the pose and the six poses at the
ends of its tolerances (x, y and yaw, one at a time) all do, and as hiding it only when none of them does; in between
the answer would depend on where the base happened to stop.
"""
from __future__ import annotations

import functools
from typing import Sequence

from cap_control.navigation.executor import NavigationConfig

_CONFIG = NavigationConfig()


@functools.lru_cache(maxsize=1)
def _world():
    """One headless kitchen per process (building it takes about half a second; a reset, milliseconds)."""
    from cap_sim_bridge.world import World
    return World('mobile')


def _poses_within_tolerance(pose: Sequence[float]) -> list[tuple[float, float, float]]:
    """The pose and the extremes of where the navigation node may stop for it."""
    reach, turn = _CONFIG.position_tolerance, _CONFIG.yaw_tolerance
    x, y, yaw = (float(v) for v in pose[:3])
    shifts = [(0.0, 0.0, 0.0), (reach, 0, 0), (-reach, 0, 0), (0, reach, 0), (0, -reach, 0), (0, 0, turn),
              (0, 0, -turn)]
    return [(x + dx, y + dy, yaw + dyaw) for dx, dy, dyaw in shifts]


def sightings(objects: Sequence[tuple[str, tuple[float, float]]], poses: Sequence[Sequence[float]],
              seed: int) -> dict[str, list[bool | None]]:
    """For each object (name, (x, y) on the furniture) and each pose (x, y, yaw): True when the head camera sees it
    from there, False when it does not, None when that depends on where within the goal tolerances the base stops."""
    from cap_sim_bridge.objects import ObjectSpec

    world = _world()
    names = [name for name, _ in objects]
    world.reset(seed, [ObjectSpec.from_name(name, tuple(xy)) for name, xy in objects])
    answers: dict[str, list[bool | None]] = {name: [] for name in names}
    for pose in poses:
        views = [world.visible_with_base_at(near, names) for near in _poses_within_tolerance(pose)]
        for name, seen in zip(names, zip(*views)):
            answers[name].append(True if all(seen) else False if not any(seen) else None)
    return answers


__all__ = ['sightings']
