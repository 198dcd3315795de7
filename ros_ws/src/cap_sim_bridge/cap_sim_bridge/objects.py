"""Objects of a scene and how they become MuJoCo bodies: the object spec, the seed's default episode, spawn sampling.

Objects are added to a scene's MjSpec here, one free body per object, named exactly as the object ("red block",
"blue bowl"). Each category is an ObjectKind (its bodies' geoms and resting height): blocks and bowls are built in,
with the sizes and colours of the table-top facts of cap_tabletop; a scene module registers more
(`register_object_kind`, e.g. the whiteboard's fruit). Which scenes exist (and the fixed part of each: robot,
table, cameras) is cap_sim_bridge.scenes.
"""
from __future__ import annotations

import dataclasses
import math
import threading
from typing import Callable, Iterable, Sequence

import mujoco
import numpy as np
from cap_tabletop import objects as tabletop_objects
from cap_tabletop.objects import (BOWL_BOTTOM_RADIUS, BOWL_BOTTOM_THICKNESS, BOWL_WALL_HEIGHT, BOWL_WALL_SEGMENTS,
                                  BOWL_WALL_THICKNESS, BOWL_WALL_TILT, BLOCK_SIZE, CATEGORY_BLOCK, CATEGORY_BOWL)
from cap_tabletop.palette import PALETTE, rgba
from cap_tabletop.workspace import SPAWN_MIN_SEPARATION, SPAWN_X_RANGE, SPAWN_Y_RANGE

__all__ = ['ObjectKind', 'ObjectSpec', 'add_objects', 'default_objects', 'object_categories', 'object_geom',
           'register_object_kind',
           'resting_height', 'rgba', 'sample_spawn_positions']

# Bodies added per object, physical properties the table-top facts leave to the simulator.
BLOCK_MASS = 0.01  # [kg]
BOWL_MASS = 0.15  # [kg]; heavy enough that a dropped block does not tip it

# Objects start this far above their resting height so that no contact starts in penetration.
SPAWN_CLEARANCE = 0.002

# Contact groups (see models/ur5e_gripper.xml): objects and the table collide with everything.
_OBJECT_CONTYPE = 1
_OBJECT_CONAFFINITY = 3


@dataclasses.dataclass(frozen=True)
class ObjectSpec:
    """One object to place on reset. position: (x, y) on the table [m]; None = sampled from the seed. height: the
    centre's height [m] where it is known (a twin of a perceived scene: a block standing on another), else None (it
    rests on the scene's surface); yaw: its rotation about the vertical [rad]."""

    name: str
    category: str
    color_name: str
    position: tuple[float, float] | None = None
    height: float | None = None
    yaw: float = 0.0
    # False: a ghost, which nothing touches and gravity does not move: a twin's object that perception may have seen
    # twice (it is there to be named; cap_lmp_ros.twin)
    solid: bool = True

    @classmethod
    def from_name(cls, name: str, position: tuple[float, float] | None = None) -> 'ObjectSpec':
        """'red block' -> ObjectSpec('red block', 'block', 'red'); a kind named alone ('apple') takes its colour."""
        text = ' '.join(name.strip().lower().split())
        kind = _kinds.get(text)
        if kind is not None and kind.color_name:
            return cls(text, text, kind.color_name, position)
        color_name, _, category = text.partition(' ')
        return cls(f'{color_name} {category}', category, color_name, position)

    def validate(self) -> None:
        if self.category not in _kinds:
            raise ValueError(f'unknown category {self.category!r} of {self.name!r}; known: '
                             f'{", ".join(object_categories())}')
        if self.color_name not in PALETTE:
            raise ValueError(f'unknown colour {self.color_name!r} of {self.name!r}; known: {", ".join(PALETTE)}')
        if not self.name:
            raise ValueError('an object needs a name')


def default_objects(seed: int) -> list[ObjectSpec]:
    """The scene's default episode for a seed: 3-4 blocks and 3-4 bowls of distinct colours (per category)."""
    rng = np.random.default_rng([seed, 1])
    names = list(PALETTE)
    specs = []
    for category in (CATEGORY_BLOCK, CATEGORY_BOWL):
        count = int(rng.integers(3, 5))
        for color_name in rng.choice(names, size=count, replace=False):
            specs.append(ObjectSpec(f'{color_name} {category}', category, str(color_name)))
    return specs


def sample_spawn_positions(specs: Sequence[ObjectSpec], seed: int, x_range: tuple[float, float] = SPAWN_X_RANGE,
                           y_range: tuple[float, float] = SPAWN_Y_RANGE,
                           min_separation: float = SPAWN_MIN_SEPARATION,
                           max_restarts: int = 200) -> list[tuple[float, float]]:
    """xy for every spec: given ones kept, the others drawn uniformly in the spawn region, pairwise apart.

    Sequential rejection sampling; when an object finds no place (the region is nearly full) the whole draw
    restarts, so a feasible layout is found for any seed the rules allow. Raises ValueError when none is found.
    """
    rng = np.random.default_rng([seed, 2])
    fixed = [(i, spec.position) for i, spec in enumerate(specs) if spec.position is not None]
    free = [i for i, spec in enumerate(specs) if spec.position is None]
    for _ in range(max_restarts):
        placed: dict[int, tuple[float, float]] = {i: (float(p[0]), float(p[1])) for i, p in fixed}
        for i in free:
            for _ in range(100):
                candidate = (float(rng.uniform(*x_range)), float(rng.uniform(*y_range)))
                if all(math.dist(candidate, other) >= min_separation for other in placed.values()):
                    placed[i] = candidate
                    break
            else:
                break
        if len(placed) == len(specs):
            return [placed[i] for i in range(len(specs))]
    raise ValueError(f'no layout of {len(specs)} objects at least {min_separation} m apart fits the spawn region')


def add_objects(spec: mujoco.MjSpec, objects: Iterable[ObjectSpec]) -> mujoco.MjSpec:
    """Add one free body per object to `spec` (body and free joint named after the object); returns `spec`."""
    for obj in objects:
        obj.validate()
        body = spec.worldbody.add_body(name=obj.name, pos=[0.0, 0.0, resting_height(obj.category)])
        body.add_freejoint(name=obj.name)
        first_geom = len(spec.geoms)
        _kinds[obj.category].add_geoms(body, obj)
        if not obj.solid:
            body.gravcomp = 1.0
            for geom in spec.geoms[first_geom:]:
                geom.contype = geom.conaffinity = 0
                geom.rgba[3] = 0.3
    return spec


@dataclasses.dataclass(frozen=True)
class ObjectKind:
    """One category of object: how its body's geoms are made (`add_geoms(body, obj)`, with `object_geom` for the
    collision and colour settings every object shares), and the height of the body's origin above the surface it
    rests on. `color_name`: the colour of a kind named alone ("apple"); empty for kinds named "<colour> <kind>"."""

    category: str
    add_geoms: Callable[[mujoco.MjsBody, 'ObjectSpec'], None]
    resting_height: float
    color_name: str = ''


_kinds: dict[str, ObjectKind] = {}
_kinds_lock = threading.Lock()


def register_object_kind(kind: ObjectKind) -> ObjectKind:
    """Make a category of object known to every scene; ValueError if another kind has its name."""
    with _kinds_lock:
        known = _kinds.get(kind.category)
        if known is not None and known != kind:
            raise ValueError(f'an object kind named {kind.category!r} is registered already')
        _kinds[kind.category] = kind
    return kind


def object_categories() -> list[str]:
    """The categories of object the scenes can hold."""
    with _kinds_lock:
        return sorted(_kinds)


def resting_height(category: str) -> float:
    """z above the surface of the object's origin when it rests there (a cube's centre, a bowl's bottom)."""
    return _kinds[category].resting_height


def object_geom(body: mujoco.MjsBody, obj: ObjectSpec, **kwargs) -> mujoco.MjsGeom:
    """A geom of an object's body, colliding with everything, in the object's palette colour."""
    geom = body.add_geom(contype=_OBJECT_CONTYPE, conaffinity=_OBJECT_CONAFFINITY, rgba=rgba(obj.color_name),
                         friction=[0.9, 0.005, 0.0001], **kwargs)
    return geom


def _add_block_geoms(body: mujoco.MjsBody, obj: ObjectSpec) -> None:
    half = BLOCK_SIZE / 2
    object_geom(body, obj, name=obj.name, type=mujoco.mjtGeom.mjGEOM_BOX, size=[half, half, half],
                 mass=BLOCK_MASS)


def _add_bowl_geoms(body: mujoco.MjsBody, obj: ObjectSpec) -> None:
    # Mass split between the bottom (most, keeps the centre of mass low) and the walls.
    wall_mass = 0.3 * BOWL_MASS / BOWL_WALL_SEGMENTS
    half_bottom = BOWL_BOTTOM_THICKNESS / 2
    object_geom(body, obj, name=f'{obj.name} bottom', type=mujoco.mjtGeom.mjGEOM_CYLINDER,
                 size=[BOWL_BOTTOM_RADIUS, half_bottom, 0.0], pos=[0.0, 0.0, half_bottom], mass=0.7 * BOWL_MASS)
    slant_half_length = BOWL_WALL_HEIGHT / 2 / math.cos(BOWL_WALL_TILT)
    centre_radius = (BOWL_BOTTOM_RADIUS + BOWL_WALL_THICKNESS / 2 + BOWL_WALL_HEIGHT / 2 * math.tan(BOWL_WALL_TILT))
    # Slabs a little wider than the chord they cover, so neighbours overlap and leave no gap.
    half_width = 1.15 * centre_radius * math.tan(math.pi / BOWL_WALL_SEGMENTS)
    for k in range(BOWL_WALL_SEGMENTS):
        azimuth = 2 * math.pi * k / BOWL_WALL_SEGMENTS
        # Slab frame: x tangential, y radial (outward), z along the wall; tilted outward about x.
        rotation = _rot_z(azimuth - math.pi / 2) @ _rot_x(-BOWL_WALL_TILT)
        quat = np.zeros(4)
        mujoco.mju_mat2Quat(quat, rotation.flatten())
        pos = [centre_radius * math.cos(azimuth), centre_radius * math.sin(azimuth),
               BOWL_BOTTOM_THICKNESS + BOWL_WALL_HEIGHT / 2]
        object_geom(body, obj, name=f'{obj.name} wall {k}', type=mujoco.mjtGeom.mjGEOM_BOX,
                     size=[half_width, BOWL_WALL_THICKNESS / 2, slant_half_length], pos=pos, quat=quat,
                     mass=wall_mass)


def _rot_x(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _rot_z(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


register_object_kind(ObjectKind(CATEGORY_BLOCK, _add_block_geoms, tabletop_objects.resting_height(CATEGORY_BLOCK)))
register_object_kind(ObjectKind(CATEGORY_BOWL, _add_bowl_geoms, tabletop_objects.resting_height(CATEGORY_BOWL)))
