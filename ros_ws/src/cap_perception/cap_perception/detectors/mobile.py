"""The mobile domain's detector: the kitchen's objects (cap_mobile.objects) in one frame of the mobile robot's head
RGB-D camera (OpenCV + NumPy, no learning), from the steps every detector shares (cap_perception.rgbd).

1. Deproject every pixel into the world frame and keep the points that stand on a piece of furniture: inside its
   footprint (a margin inside its edges, which leaves out a bin's walls), above its surface
   (cap_mobile.objects.surface_height) and at most a little more than the tallest kind above it. The floor, the
   walls and the robot's base are never kept; the arm, when it reaches over the furniture, has none of the kinds'
   colours.
2. Label the kept pixels with their palette colour and group them per colour into candidates (connected regions,
   joined when close in the world), for the colours of the kitchen's kinds only.
3. Name each candidate by its kind: among the kinds of its colour, the one whose size is nearest to the candidate's
   height above the surface and the long and short sides of its footprint seen from above (the smallest rectangle
   around its points): a red can is twice as tall as an apple, a yellow chips bag twice as wide as a banana.
4. Its position is the middle of that footprint, half the kind's height below the highest point seen (the ground
   truth's centre of the bounding box); an elongated kind's yaw is the footprint's long side.

A candidate cut by the image's edge is measured from the part seen: it is named by its height (its sides only
rule out kinds smaller than the part seen), its centre is moved out across the edge by what the part lacks of the
kind's size, and it is reported only if that centre is in the image, as the simulator's ray test counts an object
in view by its centre. Objects that stand on no furniture (held in the gripper over the base, on the floor) are not
reported; the perception source keeps them as not visible at their last known place.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
from cap_mobile import layout, objects as mobile_objects
from cap_tabletop.palette import rgba
from cap_whiteboard.objects import FRUIT

from cap_perception.objects import PerceivedObject
from cap_perception.rgbd import CameraView, ColorRegionConfig, color_clouds, deproject


@dataclass(frozen=True)
class KindSize:
    """A kind's colour and its extents as it stands [m]: footprint sides (length >= width) and height."""

    name: str
    color_name: str
    length: float
    width: float
    height: float

    @property
    def elongated(self) -> bool:
        return self.length > 1.5 * self.width


def _kind_size(name: str) -> KindSize:
    """The extents of a kind from its shape and size (cap_mobile's kinds, cap_whiteboard's fruit)."""
    if name in mobile_objects.KINDS:
        kind = mobile_objects.KINDS[name]
        if kind.shape == 'cylinder':
            radius, half_height = kind.size[:2]
            return KindSize(name, kind.color_name, 2 * radius, 2 * radius, 2 * half_height)
        x, y, z = (2 * half for half in kind.size)
        return KindSize(name, kind.color_name, max(x, y), min(x, y), z)
    fruit = FRUIT[name]
    if fruit.shape == 'ellipsoid':
        x, y, z = (2 * half for half in fruit.size)
        return KindSize(name, fruit.color_name, max(x, y), min(x, y), z)
    radius, half_length = fruit.size[:2]  # a capsule lying along x
    return KindSize(name, fruit.color_name, 2 * (radius + half_length), 2 * radius, 2 * radius)


KIND_SIZES: dict[str, KindSize] = {name: _kind_size(name) for name in mobile_objects.OBJECT_NAMES}


@dataclass(frozen=True)
class KitchenDetectorConfig(ColorRegionConfig):
    # Regions of one colour this close in the world are one object: less than the table top's, since two kinds of a
    # colour may stand end to end (a chips bag and a banana SPAWN_SEPARATION apart leave a few millimetres) [m].
    join_distance: float = 0.02
    min_pixels: int = 30  # smaller regions are noise or too little of an object to tell its kind
    min_height: float = 0.006  # above the surface [m]; lower points are the furniture's top
    # Above the surface, points higher than the tallest kind (with room for one lying on another) are not objects.
    max_height: float = 1.25 * max(size.height for size in KIND_SIZES.values())
    edge_margin: float = 0.025  # [m] inside a footprint's edges: a bin's walls (1 cm) and the furniture's sides
    # A candidate whose size is farther than this from every kind of its colour (sum of squared relative
    # differences of height, length and width) is not reported.
    max_size_mismatch: float = 1.0


def detect_kitchen(view: CameraView, config: KitchenDetectorConfig = KitchenDetectorConfig()) -> list[PerceivedObject]:
    """Every kitchen object seen standing on the furniture in the view, in the world frame, sorted by name."""
    points, valid = deproject(view)
    kept = _on_furniture(points, valid, config)
    frame = _Frame(view)
    candidates: dict[str, tuple[int, PerceivedObject]] = {}
    for color, cloud in color_clouds(view.rgb, points, kept, config, _KIND_COLORS):
        found = _classify(color, cloud, frame, config)
        # Each kind is in the kitchen once: the larger of two candidates of one kind is the object.
        if found is not None and len(cloud) > candidates.get(found.name, (0, None))[0]:
            candidates[found.name] = (len(cloud), found)
    return sorted((obj for _, obj in candidates.values()), key=lambda obj: obj.name)


_KIND_COLORS = frozenset(size.color_name for size in KIND_SIZES.values())


def _surfaces() -> list[tuple[tuple[float, float, float, float], float]]:
    """(footprint, surface height) of every piece of furniture (what cap_mobile.objects says stands there)."""
    return [(piece.footprint, mobile_objects.surface_height(*piece.centre)) for piece in layout.FURNITURE]


def _on_furniture(points: np.ndarray, valid: np.ndarray, config: KitchenDetectorConfig) -> np.ndarray:
    """The mask of the points standing on a piece of furniture, within an object's height of its surface."""
    surfaces = _surfaces()
    heights = [surface for _, surface in surfaces]
    z = points[..., 2]
    # Test the footprints only on the points within the heights of any surface (the floor is not: a third of them).
    index = np.flatnonzero(valid & (z > min(heights) + config.min_height) & (z < max(heights) + config.max_height))
    x, y, z = (np.take(points[..., axis], index) for axis in range(3))
    on = np.zeros(len(index), dtype=bool)
    margin = config.edge_margin
    for (x_min, y_min, x_max, y_max), surface in surfaces:
        on |= ((x > x_min + margin) & (x < x_max - margin) & (y > y_min + margin) & (y < y_max - margin)
               & (z > surface + config.min_height) & (z < surface + config.max_height))
    kept = np.zeros(valid.size, dtype=bool)
    kept[index[on]] = True
    return kept.reshape(valid.shape)


class _Frame:
    """Where world points fall in the view's image (to tell a candidate cut by the image's edge)."""

    BORDER = 3  # [pixels] a candidate with points this near the image's edge runs out of the image

    def __init__(self, view: CameraView) -> None:
        self.k, self.pose = view.camera_matrix, view.world_from_optical
        self.height, self.width = view.depth.shape

    def pixels(self, points: np.ndarray) -> np.ndarray:
        optical = (np.asarray(points, dtype=float) - self.pose[:3, 3]) @ self.pose[:3, :3]
        z = np.maximum(optical[:, 2], 1e-6)
        return np.stack([self.k[0, 0] * optical[:, 0] / z + self.k[0, 2],
                         self.k[1, 1] * optical[:, 1] / z + self.k[1, 2]], axis=-1)

    def at_edge(self, pixels: np.ndarray) -> np.ndarray:
        """Which pixels are at the image's edge."""
        return self.outward(pixels).any(axis=-1)

    def outward(self, pixels: np.ndarray) -> np.ndarray:
        """(N, 4) whether each pixel is at the image's left, right, top or bottom edge."""
        u, v = pixels[:, 0], pixels[:, 1]
        b = self.BORDER
        return np.stack([u < b, u > self.width - 1 - b, v < b, v > self.height - 1 - b], axis=-1)

    def edge_direction(self, pixels: np.ndarray) -> np.ndarray:
        """The floor's direction (x, y) out of the image across the edge most of `pixels` are at: the camera's
        right, left, up or down as it points over the floor."""
        side = int(np.argmax(self.outward(pixels).sum(axis=0)))
        axis = self.pose[:3, 0] if side < 2 else self.pose[:3, 1]  # optical x to the right, y down
        direction = axis[:2] * (1.0 if side in (1, 3) else -1.0)
        return direction / max(float(np.linalg.norm(direction)), 1e-9)

    def inside(self, points: np.ndarray) -> bool:
        """Whether any of the points is in the image, off its edge (and in front of the camera)."""
        optical = (np.asarray(points, dtype=float) - self.pose[:3, 3]) @ self.pose[:3, :3]
        return bool(np.any((optical[:, 2] > 0) & ~self.at_edge(self.pixels(points))))


def _classify(color: str, cloud: np.ndarray, frame: _Frame, config: KitchenDetectorConfig) -> PerceivedObject | None:
    """The object a candidate of one colour is, or None if no kind of its colour has its size or (cut by the
    image's edge) its centre is out of the image."""
    surface = _surface_under(cloud)
    top = float(np.percentile(cloud[:, 2], 98))
    (cx, cy), (side_a, side_b), angle = cv2.minAreaRect(cloud[:, :2].astype(np.float32))
    # The rectangle's sides as unit vectors, the long one first.
    first = np.array([math.cos(math.radians(angle)), math.sin(math.radians(angle))])
    second = np.array([-first[1], first[0]])
    (length, along), (width, across) = sorted(((side_a, first), (side_b, second)), key=lambda item: -item[0])
    edge = frame.at_edge(frame.pixels(cloud))
    cut = bool(edge.any())
    best = _nearest_kind(color, (top - surface, length, width), cut, config)
    if best is None:
        return None
    if best.elongated:
        centre_xy = np.array([cx, cy])
    else:  # the middle of the points seen from above (a rectangle around a round kind's may turn any way)
        centre_xy = (cloud[:, :2].min(axis=0) + cloud[:, :2].max(axis=0)) / 2
    if cut:
        # The part out of the image lies beyond the edge: move the centre that way by what the seen part lacks of
        # the kind's size in that direction.
        outward = frame.edge_direction(frame.pixels(cloud[edge]))
        if best.elongated:
            for axis, seen, full in ((along, length, best.length), (across, width, best.width)):
                axis = axis if axis @ outward >= 0 else -axis
                centre_xy = centre_xy + axis * max(full - seen, 0.0) / 2 * float(axis @ outward)
        else:
            seen = float(np.ptp(cloud[:, :2] @ outward))
            centre_xy = centre_xy + outward * max(best.length - seen, 0.0) / 2
    centre = (float(centre_xy[0]), float(centre_xy[1]), top - best.height / 2)
    if cut and not frame.inside(np.array([centre, (*centre[:2], top)])):
        return None  # the camera sees its end only: it is in view when its centre is
    yaw = math.atan2(along[1], along[0]) if best.elongated else 0.0
    yaw = yaw - math.pi if yaw > math.pi / 2 else yaw + math.pi if yaw <= -math.pi / 2 else yaw
    c, s = abs(math.cos(yaw)), abs(math.sin(yaw))
    half = (0.5 * (best.length * c + best.width * s), 0.5 * (best.length * s + best.width * c), best.height / 2)
    return PerceivedObject(
        name=best.name, category=best.name, color_name=best.color_name, position=centre,
        bbox_min=tuple(p - h for p, h in zip(centre, half)), bbox_max=tuple(p + h for p, h in zip(centre, half)),
        orientation=(0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)), color_rgba=rgba(best.color_name))


def _surface_under(cloud: np.ndarray) -> float:
    """The surface the points of one candidate stand on (that of the furniture under their middle)."""
    x, y = np.median(cloud[:, :2], axis=0)
    return mobile_objects.surface_height(float(x), float(y))


def _nearest_kind(color: str, measured: tuple[float, float, float], cut: bool,
                  config: KitchenDetectorConfig) -> KindSize | None:
    """The kind of `color` whose (height, length, width) is nearest to the measured ones (relative differences;
    of a candidate cut by the image's edge, only its height is whole: its sides count only where too long)."""
    best, mismatch = None, config.max_size_mismatch
    for size in KIND_SIZES.values():
        if size.color_name != color:
            continue
        error = 0.0
        for index, (seen, full) in enumerate(zip(measured, (size.height, size.length, size.width))):
            difference = (seen - full) / full
            if cut and index > 0:
                difference = max(difference, 0.0)
            error += difference ** 2
        if error < mismatch:
            best, mismatch = size, error
    return best


DETECTOR = detect_kitchen
