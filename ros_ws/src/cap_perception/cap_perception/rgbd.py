"""What every RGB-D detector of the graph shares (OpenCV + NumPy, no learning): one frame with its geometry, its pixels
deprojected into the world frame, palette labels by chromaticity, and each colour's object candidates as world point
clouds. The domains' detectors (cap_perception.detectors) start from these.

Chromaticity: dividing RGB by its largest channel cancels most of the shading, which scales all channels alike, so
a pixel is labelled with the palette colour (cap_tabletop.palette) nearest by that measure. Per colour, labelled
pixels join into connected regions, and regions into candidates when they lie close together in the world.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Collection, Iterator

import cv2
import numpy as np
from cap_tabletop.palette import PALETTE


@dataclass(frozen=True)
class ColorRegionConfig:
    """How kept pixels become one colour's object candidates (every detector's first steps)."""

    max_color_distance: float = 0.22  # in normalised-RGB units; farther pixels are not an object colour
    min_brightness: int = 35  # darker pixels carry no reliable colour (shadowed sides, the robot)
    min_pixels: int = 25  # smaller regions are noise
    join_distance: float = 0.05  # regions of one colour closer than this in the world are one object [m]


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
