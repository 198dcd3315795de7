"""Interchangeable object sources behind the perception services.

Every source answers the same two questions — which objects are there, and what is the state of one of them — from
its latest snapshot. The node decides which source feeds the services; the answers do not depend on that choice.
"""
from __future__ import annotations

import dataclasses
import pathlib
import threading
import time
from typing import Any, Callable, Iterable, Sequence

import yaml
from cap_tabletop.objects import BLOCK_SIZE

from cap_perception.names import UnknownObjectError, resolve_name
from cap_perception.objects import PerceivedObject


class NoObservationError(RuntimeError):
    """Raised when a source has not received any observation yet (e.g. the simulator or camera is not up)."""


class SnapshotSource:
    """Holds the latest full list of objects; fed by whoever observes the world (ground truth, a detector).

    Thread-safe: the node's subscription callbacks update it while service callbacks read it. `refresh`, when
    set, is called before every read: a source that observes on demand (CameraMemory) brings itself up to date there.
    """

    def __init__(self, description: str) -> None:
        self.description = description
        self.refresh: Callable[[], None] | None = None
        self._lock = threading.Lock()
        self._objects: dict[str, PerceivedObject] | None = None
        self._stamp = 0.0

    def update(self, objects: Iterable[PerceivedObject], stamp: float) -> None:
        snapshot = {obj.name: obj for obj in objects}
        with self._lock:
            self._objects, self._stamp = snapshot, stamp

    def clear(self) -> None:
        """Forget everything; answers wait for the next update."""
        with self._lock:
            self._objects, self._stamp = None, 0.0

    @property
    def stamp(self) -> float:
        """Time [s] of the latest observation (simulated time when the graph runs on /clock)."""
        self._refresh()
        with self._lock:
            return self._stamp

    def _refresh(self) -> None:
        if self.refresh is not None:
            self.refresh()

    def _snapshot(self) -> dict[str, PerceivedObject]:
        return self._stamped_snapshot()[0]

    def _stamped_snapshot(self) -> tuple[dict[str, PerceivedObject], float]:
        self._refresh()
        with self._lock:
            objects, stamp = self._objects, self._stamp
        if objects is None:
            raise NoObservationError(f'No objects observed yet from {self.description}; is it running?')
        return objects, stamp

    def names(self, visible_only: bool = False) -> list[str]:
        """Canonical names, sorted."""
        return sorted(name for name, obj in self._snapshot().items() if obj.visible or not visible_only)

    def state(self, name: str) -> PerceivedObject:
        """The object `name` refers to ("the red block", "red_block", ...); UnknownObjectError otherwise."""
        return self.stamped_state(name)[0]

    def stamped_state(self, name: str) -> tuple[PerceivedObject, float]:
        """`state(name)` and the time of the observation it comes from (one snapshot, read at once)."""
        objects, stamp = self._stamped_snapshot()
        return objects[resolve_name(name, objects)], stamp

    def objects(self) -> list[PerceivedObject]:
        """Every object of the latest snapshot (empty before the first observation)."""
        self._refresh()
        with self._lock:
            return list(self._objects.values()) if self._objects else []


def remember_unseen(previous: Iterable[PerceivedObject], seen: Iterable[PerceivedObject]) -> list[PerceivedObject]:
    """What a camera sees now, plus every earlier object it no longer sees (hidden under another, held in the
    gripper, behind the arm), kept at its last known place and marked not visible: objects do not vanish because
    they are occluded. After a scene reset, the node's forget service clears what is remembered."""
    current = {obj.name: obj for obj in seen}
    for obj in previous:
        if obj.name not in current:
            current[obj.name] = dataclasses.replace(obj, visible=False)
    return sorted(current.values(), key=lambda obj: obj.name)


class CameraMemory:
    """Feeds a SnapshotSource from camera frames: each analysed frame's objects plus those it no longer sees.

    Frames are analysed on demand: `offer` keeps the newest frame (cheap, at the camera's rate) and the source's
    readers call `refresh`, which analyses that frame if it is newer than the last one analysed. A detector costs
    several times the physics per frame; analysing every frame of a 10 Hz camera made it the slowest part of the
    graph, while only the frames somebody asks about are needed. Readers therefore always get the newest frame.

    Objects do not vanish when occluded (remember_unseen). `forget()` (after a scene reset) clears them, and must not
    let frames of the old scene back in:
    - a frame received before the forget (still queued when it came) is dropped: `begin` takes the time the frame
      reached this process on the local wall clock, which the forget is compared against;
    - an analysis begun before the forget is dropped (each forget starts a new generation);
    - as a second guard, frames within `settle_s` of frame time after the first accepted one replace the objects
      instead of adding to them.
    The replacing window is bounded in frame time, not in frames, and no frame past it replaces: frames are analysed
    when asked for, so the next one can come at any moment of a task, e.g. while the gripper hides the block it
    holds, and replacing would then drop that block.
    Thread-safe.
    """

    def __init__(self, source: SnapshotSource, settle_s: float = 1.0,
                 wall_clock_ns: Callable[[], int] = time.time_ns,
                 analyse: Callable[[Any], Sequence[PerceivedObject] | None] | None = None) -> None:
        self.source = source
        self.settle_s = settle_s
        self._wall_clock_ns = wall_clock_ns
        self._analyse = analyse
        self._lock = threading.Lock()
        self._analysing = threading.Lock()  # one analysis at a time; readers meanwhile wait for its result
        self._newest: tuple[Any, float, int | None] | None = None  # (frame, stamp, received_ns)
        self._known: list[PerceivedObject] = []
        self._last_stamp = -1.0
        self._generation = 0
        self._forgot_at_ns = 0
        self._replace_until: float | None = None
        if analyse is not None:
            source.refresh = self.refresh

    def offer(self, frame: Any, stamp: float, received_ns: int | None = None) -> None:
        """Keep `frame` (stamped `stamp`, received at local wall time `received_ns`) for the next `refresh`."""
        with self._lock:
            if self._newest is None or stamp > self._newest[1]:
                self._newest = (frame, stamp, received_ns)

    def refresh(self) -> None:
        """Analyse the newest offered frame unless it was analysed already (or is from before a forget)."""
        if self._analyse is None:
            return
        with self._analysing:
            with self._lock:
                newest = self._newest
            if newest is None:
                return
            frame, stamp, received_ns = newest
            token = self.begin(stamp, received_ns)
            if token is None:
                return
            detected = self._analyse(frame)
            if detected is not None:
                self.record(token, stamp, detected)

    def begin(self, stamp: float, received_ns: int | None = None) -> int | None:
        """A token for analysing the frame stamped `stamp` (received at local wall time `received_ns`, if known),
        or None if it is not worth analysing: a frame as new was already taken, or it came before a forget."""
        with self._lock:
            if stamp <= self._last_stamp:
                return None
            if received_ns is not None and received_ns < self._forgot_at_ns:
                return None
            self._last_stamp = stamp
            return self._generation

    def record(self, token: int, stamp: float, detected: Sequence[PerceivedObject]) -> None:
        """The objects detected in the frame begun with `token`."""
        with self._lock:
            if token != self._generation:
                return  # analysed a frame from before a forget
            if self._replace_until is None:
                self._replace_until = stamp + self.settle_s
            if stamp < self._replace_until:
                self._known = list(detected)
            else:
                self._known = remember_unseen(self._known, detected)
            self.source.update(self._known, stamp)

    def forget(self) -> None:
        """Forget every object; answers wait for the next frame received after this call."""
        with self._lock:
            self._generation += 1
            self._forgot_at_ns = self._wall_clock_ns()
            self._replace_until = None
            self._known = []
            self._newest = None
            self.source.clear()


def load_stub_objects(path: str | pathlib.Path) -> list[PerceivedObject]:
    """Objects listed in a YAML file:

        objects:
          - {color: red, category: block, position: [0.1, -0.5, 0.02], size: [0.04, 0.04, 0.04]}
          - {color: blue, category: bowl, position: [-0.1, -0.4, 0.03], size: [0.14, 0.14, 0.06], visible: true}
    """
    path = pathlib.Path(path)
    try:
        document = yaml.safe_load(path.read_text(encoding='utf-8')) or {}
    except (OSError, yaml.YAMLError) as error:
        raise ValueError(f'cannot read the object stub file {path}: {error}') from error
    entries: Sequence = document.get('objects', []) if isinstance(document, dict) else []
    objects = []
    for index, entry in enumerate(entries):
        try:
            objects.append(PerceivedObject.from_fields(
                color_name=entry['color'], category=entry['category'], position=entry['position'],
                size=entry.get('size', (BLOCK_SIZE,) * 3), visible=bool(entry.get('visible', True))))
        except (KeyError, TypeError, ValueError) as error:
            raise ValueError(f'{path}: object #{index + 1} is invalid: {error}') from error
    names = [obj.name for obj in objects]
    duplicates = sorted({name for name in names if names.count(name) > 1})
    if duplicates:
        raise ValueError(f'{path}: object names must be unique; repeated: {", ".join(duplicates)}')
    return objects


__all__ = ['CameraMemory', 'NoObservationError', 'SnapshotSource', 'UnknownObjectError', 'load_stub_objects',
           'remember_unseen']
