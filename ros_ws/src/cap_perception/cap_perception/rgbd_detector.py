"""Finds the table-top's coloured blocks and bowls in one RGB-D image (OpenCV + NumPy, no learning).

1. Deproject every pixel with the depth image, the intrinsics and the camera pose into the world frame and keep
   what stands on the table (above its surface, inside its bounds).
2. Label each kept pixel with the nearest palette colour by chromaticity: dividing RGB by its largest channel
   cancels most of the shading, which scales all channels alike.
3. Per colour, join the labelled pixels into connected regions and regions into objects by distance in the world.
4. Find blocks by their solid top: in a top view of the colour's points (a 2 mm grid of the world xy plane), the
   cells standing higher than a bowl's floor are eroded by most of a block's half width; a bowl's thin rim
   vanishes and each block leaves a core. What is left of the colour, away from its blocks, is a bowl if it spans
   more than a block. So a block beside or inside a bowl of its own colour is told apart from the bowl.

Works best from above (the `top` camera): every block's top face and every bowl's floor is seen. A block hidden
under another is not detected; the perception source keeps it as not visible at its last known place.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Collection, Iterator

import cv2
import numpy as np

from cap_tabletop.objects import BLOCK_SIZE, BOWL_RIM_RADIUS
from cap_tabletop.palette import PALETTE
from cap_tabletop.workspace import TABLE_X_RANGE, TABLE_Y_RANGE

from cap_perception.objects import PerceivedObject


@dataclass(frozen=True)
class ColorRegionConfig:
    """How kept pixels become one colour's object candidates (steps 2 and 3; the kitchen's detector shares them)."""

    max_color_distance: float = 0.22  # in normalised-RGB units; farther pixels are not an object colour
    min_brightness: int = 35  # darker pixels carry no reliable colour (shadowed sides, the robot)
    min_pixels: int = 25  # smaller regions are noise
    join_distance: float = 0.05  # regions of one colour closer than this in the world are one object [m]


@dataclass(frozen=True)
class DetectorConfig(ColorRegionConfig):
    block_size: float = BLOCK_SIZE  # cube edge [m]
    bowl_diameter: float = 2 * BOWL_RIM_RADIUS  # across the rim [m]
    table_x: tuple[float, float] = TABLE_X_RANGE
    table_y: tuple[float, float] = TABLE_Y_RANGE
    min_height: float = 0.004  # above the table surface [m]; lower points are table
    max_height: float = 0.22  # higher points are the robot (the tool travels at 0.25), not objects [m]


@dataclass(frozen=True)
class CameraView:
    """One RGB-D frame with its geometry."""

    rgb: np.ndarray  # (H, W, 3) uint8
    depth: np.ndarray  # (H, W) float32, metres along the optical axis; 0 or nan = no reading
    camera_matrix: np.ndarray  # 3x3 K
    world_from_optical: np.ndarray  # 4x4 pose of the ROS optical frame in the world frame


def same_view(a: CameraView, b: CameraView) -> bool:
    """Whether two frames show the same pixels from the same pose (so detect gives the same objects)."""
    return (np.array_equal(a.world_from_optical, b.world_from_optical)
            and np.array_equal(a.camera_matrix, b.camera_matrix)
            and np.array_equal(a.rgb, b.rgb) and np.array_equal(a.depth, b.depth, equal_nan=True))


_PALETTE_NAMES = tuple(PALETTE)
_PALETTE_CHROMA = np.array([np.array(rgb, dtype=float) / max(rgb) for rgb in PALETTE.values()])


def deproject(view: CameraView) -> tuple[np.ndarray, np.ndarray]:
    """World points (H, W, 3) of every pixel and the mask of pixels with a valid depth."""
    z = np.nan_to_num(view.depth.astype(np.float32), nan=0.0)
    valid = z > 0
    rays = _world_rays(view.camera_matrix, view.world_from_optical[:3, :3], z.shape)
    return z[..., None] * rays + view.world_from_optical[:3, 3].astype(np.float32), valid


@functools.lru_cache(maxsize=4)
def _optical_rays(k: bytes, shape: tuple[int, int]) -> np.ndarray:
    """Each pixel's ray in the optical frame per metre of depth: the same for every frame, moving camera or not."""
    k_matrix = np.frombuffer(k).reshape(3, 3)
    height, width = shape
    u, v = np.meshgrid(np.arange(width, dtype=np.float32), np.arange(height, dtype=np.float32))
    optical = np.stack([(u - k_matrix[0, 2]) / k_matrix[0, 0], (v - k_matrix[1, 2]) / k_matrix[1, 1],
                        np.ones_like(u)], axis=-1)
    optical.flags.writeable = False
    return optical


@functools.lru_cache(maxsize=4)
def _cached_rays(k: bytes, rotation: bytes, shape: tuple[int, int]) -> np.ndarray:
    rotation_matrix = np.frombuffer(rotation).reshape(3, 3)
    rays = _optical_rays(k, shape) @ rotation_matrix.T.astype(np.float32)
    rays.flags.writeable = False
    return rays


def _world_rays(k: np.ndarray, rotation: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """World direction of each pixel's ray per metre of depth: the same for every frame of a fixed camera."""
    return _cached_rays(np.ascontiguousarray(k, dtype=float).tobytes(),
                        np.ascontiguousarray(rotation, dtype=float).tobytes(), tuple(shape))


def label_colors(pixels: np.ndarray, config: ColorRegionConfig) -> np.ndarray:
    """Index into PALETTE for each RGB pixel (shape (N, 3)), -1 where no palette colour fits."""
    pixels = pixels.astype(np.float32)
    brightest = pixels.max(axis=-1, keepdims=True)
    chroma = pixels / np.maximum(brightest, 1.0)
    difference = chroma[:, None, :] - _PALETTE_CHROMA[None]
    squared = np.einsum('ijk,ijk->ij', difference, difference)  # squared distances: no square root per pixel
    labels = squared.argmin(axis=-1)
    nearest = np.take_along_axis(squared, labels[:, None], axis=-1)[:, 0]
    usable = (nearest <= config.max_color_distance ** 2) & (brightest[:, 0] >= config.min_brightness)
    return np.where(usable, labels, -1)


def detect(view: CameraView, config: DetectorConfig = DetectorConfig()) -> list[PerceivedObject]:
    """Every block and bowl seen in the view, in the world frame, sorted by name."""
    points, valid = deproject(view)
    x, y, z = points[..., 0], points[..., 1], points[..., 2]
    on_table = (valid & (z > config.min_height) & (z < config.max_height)
                & (x > config.table_x[0]) & (x < config.table_x[1])
                & (y > config.table_y[0]) & (y < config.table_y[1]))
    found: list[PerceivedObject] = []
    for color, cluster in color_clouds(view.rgb, points, on_table, config):
        found.extend(_classify(color, cluster, config))
    return sorted(found, key=lambda obj: obj.name)


def color_clouds(rgb: np.ndarray, points: np.ndarray, kept: np.ndarray, config: ColorRegionConfig,
                 colors: Collection[str] = _PALETTE_NAMES) -> Iterator[tuple[str, np.ndarray]]:
    """(palette colour, world points (N, 3)) of every object candidate of `colors` among the `kept` pixels: each
    kept pixel labelled with its nearest palette colour, connected regions per colour, joined when they lie close
    together in the world."""
    # Colour only the kept pixels: a few percent of the image.
    rows, columns = np.nonzero(kept)
    labels = label_colors(rgb[rows, columns], config)
    height, width = kept.shape
    for index, color in enumerate(_PALETTE_NAMES):
        chosen = labels == index
        if color not in colors or np.count_nonzero(chosen) < config.min_pixels:
            continue
        # Work in the window around this colour's pixels (with a margin the 3x3 opening needs), not the image.
        r, c = rows[chosen], columns[chosen]
        top, left = max(int(r.min()) - 2, 0), max(int(c.min()) - 2, 0)
        bottom, right = min(int(r.max()) + 3, height), min(int(c.max()) + 3, width)
        mask = np.zeros((bottom - top, right - left), np.uint8)
        mask[r - top, c - left] = 1
        # Opening removes single stray pixels (edges blending two colours) before grouping.
        mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, _OPENING)
        for cluster in _objects_of_one_color(mask, points[top:bottom, left:right], config):
            yield color, cluster


_OPENING = np.ones((3, 3), np.uint8)


def _objects_of_one_color(mask: np.ndarray, points: np.ndarray,
                          config: ColorRegionConfig) -> list[np.ndarray]:
    """World points per object candidate: connected regions, joined when they lie close together in the world."""
    count, regions, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    groups: list[np.ndarray] = []
    for region in range(1, count):
        if stats[region, cv2.CC_STAT_AREA] < config.min_pixels:
            continue
        left, top, width, height = stats[region, :4]
        window = (slice(top, top + height), slice(left, left + width))
        cloud = points[window][regions[window] == region]
        for i, group in enumerate(groups):
            if _xy_gap(group, cloud) < config.join_distance:
                groups[i] = np.vstack([group, cloud])
                break
        else:
            groups.append(cloud)
    return groups


def _xy_gap(a: np.ndarray, b: np.ndarray) -> float:
    """Distance between the xy bounding boxes of two clouds (0 when they overlap)."""
    low = np.maximum(a[:, :2].min(axis=0), b[:, :2].min(axis=0))
    high = np.minimum(a[:, :2].max(axis=0), b[:, :2].max(axis=0))
    return float(np.linalg.norm(np.maximum(low - high, 0.0)))


_GRID = 0.002  # top-view cell [m]


def _block_cores(cloud: np.ndarray, config: DetectorConfig) -> list[np.ndarray]:
    """Points of each block in a cloud of one colour, found by the solid top a bowl's rim does not have."""
    high = cloud[cloud[:, 2] > 0.6 * config.block_size]
    if len(high) < config.min_pixels:
        return []
    origin = high[:, :2].min(axis=0) - 0.01
    cells = np.floor((high[:, :2] - origin) / _GRID).astype(int)
    shape = cells.max(axis=0) + 3
    grid = np.zeros((shape[1], shape[0]), np.uint8)
    grid[cells[:, 1], cells[:, 0]] = 1
    # Close pixel-sized holes of the sampled top, then erode: a 4 cm top keeps a core, a rim a few mm wide does not.
    grid = cv2.morphologyEx(grid, cv2.MORPH_CLOSE, np.ones((3, 3), np.uint8))
    radius = int(round(0.3 * config.block_size / _GRID))
    core = cv2.erode(grid, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1)))
    count, labels, stats, centroids = cv2.connectedComponentsWithStats(core, connectivity=8)
    blocks = []
    for label in range(1, count):
        centre = origin + (centroids[label] + 0.5) * _GRID
        near = np.max(np.abs(cloud[:, :2] - centre), axis=1) < 0.5 * config.block_size + 0.004
        members = cloud[near & (cloud[:, 2] > 0.6 * config.block_size)]
        if len(members) >= config.min_pixels:
            blocks.append(cloud[near])
    return blocks


def _classify(color: str, cloud: np.ndarray, config: DetectorConfig) -> list[PerceivedObject]:
    found: list[PerceivedObject] = []
    rest = cloud
    for block_points in _block_cores(cloud, config):
        block = _block(color, block_points, config)
        found.append(block)
        away = np.max(np.abs(rest[:, :2] - np.array(block.position[:2])), axis=1) > 0.5 * config.block_size + 0.006
        rest = rest[away]
    if len(rest) >= config.min_pixels and float(np.max(np.ptp(rest[:, :2], axis=0))) > 1.5 * config.block_size:
        found.append(_bowl(color, rest, config))
    return found


def _block(color: str, cloud: np.ndarray, config: DetectorConfig) -> PerceivedObject:
    # The top face is the best-seen part of a cube from above: its centre is the cube's xy, its height the top.
    top = float(np.percentile(cloud[:, 2], 95))
    face = cloud[cloud[:, 2] > top - 0.006]
    centre_xy = (face[:, :2].min(axis=0) + face[:, :2].max(axis=0)) / 2
    half = config.block_size / 2
    return PerceivedObject.from_fields(color, 'block', (centre_xy[0], centre_xy[1], top - half),
                                       (config.block_size,) * 3)


def _bowl(color: str, cloud: np.ndarray, config: DetectorConfig) -> PerceivedObject:
    low, high = cloud[:, :2].min(axis=0), cloud[:, :2].max(axis=0)
    centre_xy = (low + high) / 2
    height = float(np.percentile(cloud[:, 2], 98))
    return PerceivedObject.from_fields(color, 'bowl', (centre_xy[0], centre_xy[1], height / 2),
                                       (high[0] - low[0], high[1] - low[1], height))
