"""Ink on a drawing surface, laid and wiped by contacts in the physics (no ROS here).

`InkCanvas` is the ink as an image of the surface (uint8, 255 where there is ink), with the geometry that maps the
world's x, y onto it. `InkSurface` watches one model's contacts after each physics step: where the marker's tip
touches the surface it draws a stroke of the tip's width from where it touched at the previous step; where the
eraser's pad touches, it wipes the pad's footprint. Nothing here reads a commanded path: ink is where the tool
really was, as MuJoCo's contacts say, so tracking errors, a bounce or a tip lifted too early show in the ink.

An InkSurface also keeps a texture of the model in step with the canvas, so the cameras' renders show the ink
(`texture_rgb` is what the world uploads when `version` changed).
"""
from __future__ import annotations

import dataclasses
import threading

import cv2
import mujoco
import numpy as np

_SUBPIXEL_BITS = 4  # cv2 fills polygons with 1/16-pixel coordinates
_SUBPIXEL = 1 << _SUBPIXEL_BITS


@dataclasses.dataclass(frozen=True)
class InkSpec:
    """Where a scene's ink lives: the surface geom, the geoms that draw and wipe, the image's extent [m].

    Image row 0 is the surface's largest y, column 0 its smallest x; `resolution` metres per pixel. `texture` names
    the model texture (2-D, RGB, width x height pixels) that shows the ink on the surface in renders ('' for none).
    """

    surface_geom: str
    marker_geom: str
    eraser_geom: str
    x_range: tuple[float, float]
    y_range: tuple[float, float]
    resolution: float
    tip_width: float
    texture: str = ''
    ink_rgb: tuple[int, int, int] = (20, 40, 120)
    board_rgb: tuple[int, int, int] = (246, 246, 242)

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, columns) of the ink image."""
        return (int(round((self.y_range[1] - self.y_range[0]) / self.resolution)),
                int(round((self.x_range[1] - self.x_range[0]) / self.resolution)))


class InkCanvas:
    """The ink of one surface as an image. Thread-safe: the physics thread draws, others read."""

    def __init__(self, spec: InkSpec) -> None:
        self.spec = spec
        self._image = np.zeros(spec.shape, dtype=np.uint8)
        self._lock = threading.Lock()
        self.version = 0  # counts changes, so a reader can tell whether the ink changed since it last looked

    def to_pixels(self, xy: np.ndarray) -> np.ndarray:
        """(..., 2) world x, y -> (..., 2) fractional (column, row) pixel coordinates (pixel centres at integers)."""
        xy = np.asarray(xy, dtype=float)
        col = (xy[..., 0] - self.spec.x_range[0]) / self.spec.resolution - 0.5
        row = (self.spec.y_range[1] - xy[..., 1]) / self.spec.resolution - 0.5
        return np.stack([col, row], axis=-1)

    def draw_stroke(self, start: np.ndarray, end: np.ndarray) -> None:
        """Ink every pixel whose centre lies within half the tip's width of the segment `start`-`end` (world x, y):
        a stroke of the tip's width, round at both ends."""
        a, b = self.to_pixels(np.asarray(start, dtype=float)), self.to_pixels(np.asarray(end, dtype=float))
        radius = self.spec.tip_width / self.spec.resolution / 2
        rows, cols = self.spec.shape
        c0 = max(0, int(np.floor(min(a[0], b[0]) - radius)))
        c1 = min(cols - 1, int(np.ceil(max(a[0], b[0]) + radius)))
        r0 = max(0, int(np.floor(min(a[1], b[1]) - radius)))
        r1 = min(rows - 1, int(np.ceil(max(a[1], b[1]) + radius)))
        if c0 > c1 or r0 > r1:
            return  # off the image
        grid_c, grid_r = np.meshgrid(np.arange(c0, c1 + 1), np.arange(r0, r1 + 1))
        points = np.stack([grid_c, grid_r], axis=-1).astype(float)
        segment = b - a
        length_sq = float(segment @ segment)
        t = np.zeros(points.shape[:2]) if length_sq == 0 else np.clip(((points - a) @ segment) / length_sq, 0, 1)
        inside = np.linalg.norm(points - (a + t[..., None] * segment), axis=-1) <= radius
        with self._lock:
            self._image[r0:r1 + 1, c0:c1 + 1][inside] = 255
            self.version += 1

    def wipe(self, polygon: np.ndarray) -> None:
        """Remove the ink inside a convex polygon (N, 2) of world x, y."""
        points = np.round(self.to_pixels(polygon) * _SUBPIXEL).astype(np.int32)
        with self._lock:
            cv2.fillConvexPoly(self._image, points, 0, cv2.LINE_8, _SUBPIXEL_BITS)
            self.version += 1

    def clear(self) -> None:
        with self._lock:
            self._image[:] = 0
            self.version += 1

    def image(self) -> np.ndarray:
        """A copy of the ink image (rows x columns, uint8, 255 = ink)."""
        with self._lock:
            return self._image.copy()

    def snapshot(self) -> tuple[np.ndarray, int]:
        """(image copy, version) taken together."""
        with self._lock:
            return self._image.copy(), self.version

    def png(self) -> bytes:
        """The ink image as a PNG (8-bit grey, 255 = ink)."""
        ok, encoded = cv2.imencode('.png', self.image())
        if not ok:
            raise RuntimeError('could not encode the ink image as PNG')
        return encoded.tobytes()

    def texture_rgb(self, image: np.ndarray | None = None) -> np.ndarray:
        """The ink as the surface's RGB texture (rows x columns x 3): board colour, ink colour where inked."""
        image = self.image() if image is None else image
        board = np.array(self.spec.board_rgb, dtype=np.float32)
        ink = np.array(self.spec.ink_rgb, dtype=np.float32)
        alpha = image[..., None].astype(np.float32) / 255.0
        return (board * (1.0 - alpha) + ink * alpha).astype(np.uint8)


class InkSurface:
    """Lays and wipes the ink of one model's surface from its contacts (call `update` after physics steps)."""

    # A tip that jumped further than this between two updates left the surface in between: no stroke joins them.
    MAX_STROKE_STEP = 0.01  # [m]
    # The pad wipes again once it moved this far (or turned) since its last wipe.
    WIPE_STEP = 0.0005  # [m]

    def __init__(self, model: mujoco.MjModel, spec: InkSpec, canvas: InkCanvas | None = None) -> None:
        self.spec = spec
        self.canvas = canvas or InkCanvas(spec)
        self._surface = model.geom(spec.surface_geom).id
        self._marker = model.geom(spec.marker_geom).id
        self._eraser = model.geom(spec.eraser_geom).id
        self._eraser_half = model.geom_size[self._eraser].copy()
        self.texture_id = model.texture(spec.texture).id if spec.texture else -1
        self._last_tip: np.ndarray | None = None
        self._last_wipe: np.ndarray | None = None

    def reset(self) -> None:
        """Clear the ink and forget where the tools touched."""
        self.canvas.clear()
        self._last_tip = self._last_wipe = None

    def update(self, data: mujoco.MjData) -> None:
        """Ink and wipe according to the contacts of the last physics step."""
        tip, wiping = None, False
        ncon = data.ncon
        if ncon:
            geoms = data.contact.geom[:ncon]
            touching_surface = (geoms == self._surface).any(axis=1)
            for index in np.flatnonzero(touching_surface & (geoms == self._marker).any(axis=1)):
                tip = data.contact.pos[index, :2].copy()
            wiping = bool((touching_surface & (geoms == self._eraser).any(axis=1)).any())
        self._ink(tip)
        self._wipe(data if wiping else None)

    def _ink(self, tip: np.ndarray | None) -> None:
        if tip is None:
            self._last_tip = None
            return
        last = self._last_tip
        if last is not None and np.linalg.norm(tip - last) < 0.25 * self.spec.resolution:
            return  # not moved by a quarter pixel: nothing new to ink
        start = last if last is not None and np.linalg.norm(tip - last) <= self.MAX_STROKE_STEP else tip
        self.canvas.draw_stroke(start, tip)
        self._last_tip = tip

    def _wipe(self, data: mujoco.MjData | None) -> None:
        if data is None:
            self._last_wipe = None
            return
        corners = self._pad_footprint(data)
        if self._last_wipe is not None and np.max(np.abs(corners - self._last_wipe)) < self.WIPE_STEP:
            return
        self.canvas.wipe(corners)
        self._last_wipe = corners

    def _pad_footprint(self, data: mujoco.MjData) -> np.ndarray:
        """(4, 2) world x, y of the pad face nearest the surface (the face whose normal points most downward)."""
        rotation = data.geom_xmat[self._eraser].reshape(3, 3)
        centre = data.geom_xpos[self._eraser]
        axis = int(np.argmax(np.abs(rotation[2])))  # the pad's local axis closest to vertical
        sign = -np.sign(rotation[2, axis])  # towards the surface below
        others = [i for i in range(3) if i != axis]
        face = centre + sign * self._eraser_half[axis] * rotation[:, axis]
        u = self._eraser_half[others[0]] * rotation[:, others[0]]
        v = self._eraser_half[others[1]] * rotation[:, others[1]]
        return np.array([face + u + v, face + u - v, face - u - v, face - u + v])[:, :2]


__all__ = ['InkCanvas', 'InkSpec', 'InkSurface']
