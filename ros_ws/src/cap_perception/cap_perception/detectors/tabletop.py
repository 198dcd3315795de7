"""The table top's detector: the coloured blocks and bowls in one RGB-D image (OpenCV + NumPy, no learning).

1. Deproject every pixel with the depth image, the intrinsics and the camera pose into the world frame and keep
   what stands on the table (above its surface, inside its bounds).
2. Label each kept pixel with the nearest palette colour by chromaticity (cap_perception.rgbd).
3. Per colour, join the labelled pixels into connected regions and regions into objects by distance in the world.
4. Find blocks by their solid top: in a top view of the colour's points (a 2 mm grid of the world xy plane), the
   cells standing higher than a bowl's floor are eroded by most of a block's half width; a bowl's thin rim
   vanishes and each block leaves a core. What is left of the colour, away from its blocks, is a bowl if it spans
   more than a block. So a block beside or inside a bowl of its own colour is told apart from the bowl.

Works best from above (the `top` camera): every block's top face and every bowl's floor is seen. A block hidden
under another is not detected; the perception source keeps it as not visible at its last known place.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from cap_tabletop.objects import BLOCK_SIZE, BOWL_RIM_RADIUS
from cap_tabletop.workspace import TABLE_X_RANGE, TABLE_Y_RANGE

from cap_perception.objects import PerceivedObject
from cap_perception.rgbd import CameraView, ColorRegionConfig, color_clouds, deproject


@dataclass(frozen=True)
class DetectorConfig(ColorRegionConfig):
    block_size: float = BLOCK_SIZE  # cube edge [m]
    bowl_diameter: float = 2 * BOWL_RIM_RADIUS  # across the rim [m]
    table_x: tuple[float, float] = TABLE_X_RANGE
    table_y: tuple[float, float] = TABLE_Y_RANGE
    min_height: float = 0.004  # above the table surface [m]; lower points are table
    max_height: float = 0.22  # higher points are the robot (the tool travels at 0.25), not objects [m]


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


DETECTOR = detect
