"""A small transform buffer: what the graph needs of tf2 (whose Python binding, tf2_ros, is not on PyPI), no ROS.

Transforms arrive as (parent, child, stamp, translation, rotation) edges, as /tf and /tf_static carry them; the buffer
keeps the static ones for good and each dynamic edge's recent history, and answers `lookup(target, source, stamp)`:
the pose of `source` in `target` (a 4x4 matrix that maps points in `source` to `target`), walking the tree through
the frames' common ancestor. At a stamp between two of an edge's samples it interpolates (linearly for the
translation, slerp for the rotation), as tf2 does; a stamp outside what an edge holds is an error that says so
(extrapolation is refused), except that `stamp=None` takes each edge's latest sample.
"""
from __future__ import annotations

import bisect
import threading
from dataclasses import dataclass
from typing import Iterable, Sequence

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

DEFAULT_HISTORY_S = 10.0  # tf2's default cache length


class TransformError(LookupError):
    """A frame is unknown, not connected to the other, or not known at the stamp asked for."""


@dataclass(frozen=True)
class Transform:
    """One edge: the pose of `child` in `parent` at `stamp` [s]; rotation as a quaternion x, y, z, w."""

    parent: str
    child: str
    stamp: float
    translation: tuple[float, float, float]
    rotation: tuple[float, float, float, float]

    def matrix(self) -> np.ndarray:
        return pose_matrix(self.translation, self.rotation)


def pose_matrix(translation: Sequence[float], rotation_xyzw: Sequence[float]) -> np.ndarray:
    """The 4x4 matrix of a translation and a quaternion (x, y, z, w); ValueError for values that are not a pose."""
    values = np.asarray([*translation, *rotation_xyzw], dtype=float)
    if values.shape != (7,) or not np.all(np.isfinite(values)) or np.linalg.norm(values[3:]) < 1e-9:
        raise ValueError('a transform needs a finite translation and a non-zero quaternion')
    matrix = np.eye(4)
    matrix[:3, :3] = Rotation.from_quat(values[3:]).as_matrix()
    matrix[:3, 3] = values[:3]
    return matrix


def translation_rotation(matrix: np.ndarray) -> tuple[tuple[float, float, float], tuple[float, float, float, float]]:
    """The translation and quaternion (x, y, z, w) of a 4x4 pose matrix."""
    rotation = Rotation.from_matrix(np.asarray(matrix)[:3, :3]).as_quat()
    return tuple(float(v) for v in np.asarray(matrix)[:3, 3]), tuple(float(v) for v in rotation)


class _Edge:
    """One child's samples in its parent, sorted by stamp (a static edge keeps one, valid at every stamp)."""

    def __init__(self, parent: str, static: bool) -> None:
        self.parent, self.static = parent, static
        self.stamps: list[float] = []
        self.samples: list[Transform] = []

    def add(self, transform: Transform, history_s: float) -> None:
        if self.static:
            self.stamps, self.samples = [transform.stamp], [transform]
            return
        index = bisect.bisect_right(self.stamps, transform.stamp)
        if index and self.stamps[index - 1] == transform.stamp:  # the same stamp again: the newer sample wins
            self.samples[index - 1] = transform
        else:
            self.stamps.insert(index, transform.stamp)
            self.samples.insert(index, transform)
        oldest = self.stamps[-1] - history_s
        cut = bisect.bisect_left(self.stamps, oldest)
        if cut:
            del self.stamps[:cut], self.samples[:cut]

    def at(self, stamp: float | None, child: str) -> np.ndarray:
        if self.static or stamp is None:
            return self.samples[-1].matrix()
        first, last = self.stamps[0], self.stamps[-1]
        if not first <= stamp <= last:
            raise TransformError(f'{self.parent} -> {child} is known from {first:.3f} s to {last:.3f} s, not at '
                                 f'{stamp:.3f} s')
        index = bisect.bisect_left(self.stamps, stamp)
        if self.stamps[index] == stamp:
            return self.samples[index].matrix()
        before, after = self.samples[index - 1], self.samples[index]
        fraction = (stamp - before.stamp) / (after.stamp - before.stamp)
        translation = (1 - fraction) * np.asarray(before.translation) + fraction * np.asarray(after.translation)
        rotation = Slerp([0.0, 1.0], Rotation.from_quat([before.rotation, after.rotation]))([fraction])[0]
        return pose_matrix(translation, rotation.as_quat())


class TransformBuffer:
    """The transforms received, by child frame (a frame has one parent, as in tf). Thread-safe."""

    def __init__(self, history_s: float = DEFAULT_HISTORY_S) -> None:
        self.history_s = history_s
        self._edges: dict[str, _Edge] = {}
        self._lock = threading.Lock()

    def add(self, transforms: Iterable[Transform], static: bool = False) -> None:
        """Take transforms as /tf (static False) or /tf_static (True) carries them."""
        with self._lock:
            for transform in transforms:
                if transform.parent == transform.child or not transform.parent or not transform.child:
                    continue  # not an edge of a tree
                edge = self._edges.get(transform.child)
                if edge is None or edge.parent != transform.parent or edge.static != static:
                    edge = self._edges[transform.child] = _Edge(transform.parent, static)
                edge.add(transform, self.history_s)

    def frames(self) -> set[str]:
        """Every frame named so far, parents and children."""
        with self._lock:
            return set(self._edges) | {edge.parent for edge in self._edges.values()}

    def _path_to_root(self, frame: str) -> list[str]:
        path = [frame]
        while path[-1] in self._edges and len(path) <= len(self._edges):
            path.append(self._edges[path[-1]].parent)
        return path

    def _paths(self, target: str, source: str) -> tuple[list[str], list[str]]:
        """The frames from `source` and from `target` up to their common ancestor (excluded): the edges a lookup
        walks. Call with the lock held."""
        known = set(self._edges) | {edge.parent for edge in self._edges.values()}
        for frame in (target, source):
            if frame not in known:
                raise TransformError(f'no transform names the frame {frame!r}')
        up_source, up_target = self._path_to_root(source), self._path_to_root(target)
        common = next((frame for frame in up_source if frame in up_target), None)
        if common is None:
            raise TransformError(f'{source!r} and {target!r} are not connected (their roots are '
                                 f'{up_source[-1]!r} and {up_target[-1]!r})')
        return up_source[:up_source.index(common)], up_target[:up_target.index(common)]

    def lookup(self, target: str, source: str, stamp: float | None = None) -> np.ndarray:
        """The pose of `source` in `target` at `stamp` [s] (None: the latest of every edge): maps points given in
        `source` to `target`. TransformError naming what is missing otherwise."""
        with self._lock:
            from_source, from_target = self._paths(target, source)
            source_in_common, target_in_common = self._chain(from_source, stamp), self._chain(from_target, stamp)
        return np.linalg.inv(target_in_common) @ source_in_common

    def _chain(self, frames: list[str], stamp: float | None) -> np.ndarray:
        """The pose of frames[0] in the parent of frames[-1] (frames listed from a child up)."""
        matrix = np.eye(4)
        for frame in frames:
            matrix = self._edges[frame].at(stamp, frame) @ matrix
        return matrix

    def can_transform(self, target: str, source: str, stamp: float | None = None) -> bool:
        try:
            self.lookup(target, source, stamp)
        except TransformError:
            return False
        return True

    def latest_stamp(self, target: str, source: str) -> float | None:
        """The newest stamp at which `lookup(target, source, stamp)` can answer: the oldest of the latest samples of
        the dynamic edges on the way (None when every edge is static); TransformError when there is no way."""
        with self._lock:
            from_source, from_target = self._paths(target, source)
            dynamic = [self._edges[frame].stamps[-1] for frame in from_source + from_target
                       if not self._edges[frame].static]
        return min(dynamic) if dynamic else None

__all__ = ['DEFAULT_HISTORY_S', 'Transform', 'TransformBuffer', 'TransformError', 'pose_matrix',
           'translation_rotation']
