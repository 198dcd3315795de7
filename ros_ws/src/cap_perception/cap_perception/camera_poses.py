"""Which camera pose a frame is analysed with (plain Python, no ROS).

A fixed camera's pose is sent once (the bridge latches it, again after a reset) and holds for every later frame. A
moving camera's (the mobile base's head camera) comes with each frame, stamped as the frame: a frame is analysed
with the pose of its own stamp only, never the latest one, which may be a later frame's (at the base's 0.5 m/s, one
frame of a 10 Hz camera apart is 5 cm).
"""
from __future__ import annotations

import collections
import threading

import numpy as np


class CameraPoses:
    """The camera's latest poses by stamp [ns]; thread-safe."""

    def __init__(self, moving: bool, keep: int = 64) -> None:
        self.moving = moving
        self._keep = keep
        self._lock = threading.Lock()
        self._poses: collections.OrderedDict[int, np.ndarray] = collections.OrderedDict()

    def add(self, stamp_ns: int, pose: np.ndarray) -> None:
        with self._lock:
            self._poses[stamp_ns] = pose
            self._poses.move_to_end(stamp_ns)
            while len(self._poses) > self._keep:
                self._poses.popitem(last=False)

    def newest_stamp(self) -> int:
        """The stamp [ns] of the newest pose kept, -1 when none is."""
        with self._lock:
            return max(self._poses, default=-1)

    def at(self, stamp_ns: int) -> np.ndarray | None:
        """The pose for the frame stamped `stamp_ns`: a moving camera's of that stamp, a fixed camera's latest;
        None when it has not come (yet)."""
        with self._lock:
            if self.moving:
                return self._poses.get(stamp_ns)
            return next(reversed(self._poses.values()), None)
