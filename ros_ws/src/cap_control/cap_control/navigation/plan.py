"""Navigation of a mobile base on the floor (plain Python, no ROS): an occupancy grid from the scene's static
geometry, a grid planner, and a path follower with speed and acceleration limits.

- `OccupancyGrid.from_boxes` rasterises footprints (furniture, walls) and `inflated` grows them by the base's
  radius, so the base's centre may stand on every free cell.
- `plan_path` finds the shortest 8-connected path with pyastar2d (a small, well-kept A* written in C++ with a
  NumPy interface, rather than one written here), then shortens it to the corners that see each other on the
  inflated grid. A goal in an obstacle, or out of reach, is `UNREACHABLE`.
- `PathFollower` drives along the path by pure pursuit (a look-ahead point on the path, the arc to it), slows down
  within its stopping distance, then turns on the spot to the goal's heading; speeds and accelerations never exceed
  the limits. It stops within `position_tolerance` and `yaw_tolerance` (nav2's defaults are 0.25 m and 0.25 rad).
"""
from __future__ import annotations

import dataclasses
import enum
import math
from typing import Iterable, Sequence

import numpy as np
# pyastar2d: A* over a weight grid (pinned in requirements-runtime.txt); weights of inf are walls.
import pyastar2d
from scipy import ndimage


class NavigateErrorCode(enum.IntEnum):
    """The navigation's error codes, in nav2's terms: nav2 reports the code of the server that failed (the planner's
    from 200, its navigator's from 9000); this project's own from 9100."""

    NONE = 0
    UNREACHABLE = 208  # nav2's planner: NO_VALID_PATH
    UNKNOWN = 9000
    TF_ERROR = 9002
    TIMEOUT = 9003
    UNKNOWN_LOCATION = 9100  # a location name the executor was asked for is not the kitchen's
    CANCELLED = 9102  # stopped (cap/stop): the base holds where it is


class NavigationError(Exception):
    def __init__(self, code: NavigateErrorCode, message: str) -> None:
        super().__init__(message)
        self.code = code


Box = tuple[float, float, float, float]  # x_min, y_min, x_max, y_max [m]


@dataclasses.dataclass(frozen=True)
class OccupancyGrid:
    """Cells of `resolution` metres; cell (row, column) covers x from origin[0] + column * resolution, y likewise
    with the row. `occupied[row, column]` is True where the base's centre may not be."""

    occupied: np.ndarray  # (rows, columns) bool
    origin: tuple[float, float]
    resolution: float

    @classmethod
    def from_boxes(cls, boxes: Iterable[Box], x_range: tuple[float, float], y_range: tuple[float, float],
                   resolution: float = 0.05) -> 'OccupancyGrid':
        """The area x_range x y_range with every cell a box touches occupied; the border cells are occupied too
        (the area is closed)."""
        columns = int(math.ceil((x_range[1] - x_range[0]) / resolution))
        rows = int(math.ceil((y_range[1] - y_range[0]) / resolution))
        occupied = np.zeros((rows, columns), dtype=bool)
        for x_min, y_min, x_max, y_max in boxes:
            c0 = max(int(math.floor((x_min - x_range[0]) / resolution)), 0)
            c1 = min(int(math.ceil((x_max - x_range[0]) / resolution)), columns)
            r0 = max(int(math.floor((y_min - y_range[0]) / resolution)), 0)
            r1 = min(int(math.ceil((y_max - y_range[0]) / resolution)), rows)
            occupied[r0:r1, c0:c1] = True
        occupied[[0, -1], :] = True
        occupied[:, [0, -1]] = True
        return cls(occupied, (x_range[0], y_range[0]), resolution)

    def inflated(self, radius: float) -> 'OccupancyGrid':
        """Every cell whose centre is within `radius` of an occupied cell's centre occupied too."""
        distance = ndimage.distance_transform_edt(~self.occupied) * self.resolution
        return dataclasses.replace(self, occupied=distance <= radius)

    def cell(self, xy: Sequence[float]) -> tuple[int, int]:
        """(row, column) of the cell holding the point (clamped to the grid)."""
        rows, columns = self.occupied.shape
        column = int(math.floor((xy[0] - self.origin[0]) / self.resolution))
        row = int(math.floor((xy[1] - self.origin[1]) / self.resolution))
        return min(max(row, 0), rows - 1), min(max(column, 0), columns - 1)

    def point(self, row: float, column: float) -> np.ndarray:
        """The centre of a cell, in metres."""
        return np.array([self.origin[0] + (column + 0.5) * self.resolution,
                         self.origin[1] + (row + 0.5) * self.resolution])

    def contains(self, xy: Sequence[float]) -> bool:
        rows, columns = self.occupied.shape
        return (0 <= xy[0] - self.origin[0] < columns * self.resolution
                and 0 <= xy[1] - self.origin[1] < rows * self.resolution)

    def is_free(self, xy: Sequence[float]) -> bool:
        return self.contains(xy) and not bool(self.occupied[self.cell(xy)])

    def segment_is_free(self, a: Sequence[float], b: Sequence[float]) -> bool:
        """Whether every cell along the straight segment a-b is free (sampled at a quarter cell)."""
        a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
        samples = max(2, int(math.ceil(np.linalg.norm(b - a) / (self.resolution / 4))) + 1)
        points = a + np.linspace(0.0, 1.0, samples)[:, None] * (b - a)
        columns = np.floor((points[:, 0] - self.origin[0]) / self.resolution).astype(int)
        rows = np.floor((points[:, 1] - self.origin[1]) / self.resolution).astype(int)
        inside = (rows >= 0) & (rows < self.occupied.shape[0]) & (columns >= 0) & (columns < self.occupied.shape[1])
        return bool(inside.all()) and not bool(self.occupied[rows, columns].any())


def plan_path(grid: OccupancyGrid, start: Sequence[float], goal: Sequence[float]) -> np.ndarray:
    """The shortest free path from start to goal as corner points (N, 2), start and goal included.

    NavigationError UNREACHABLE when the goal is not free (inside an obstacle or too close to one for the base)
    or no free path leads there. A start inside an inflated obstacle (the base pushed close to furniture) leaves
    by the nearest free cell.
    """
    start, goal = np.asarray(start[:2], dtype=float), np.asarray(goal[:2], dtype=float)
    if not grid.is_free(goal):
        raise NavigationError(NavigateErrorCode.UNREACHABLE,
                              f'the goal ({goal[0]:.2f}, {goal[1]:.2f}) is inside an obstacle or closer to one '
                              f'than the base allows')
    start_cell = grid.cell(start)
    free_start = start_cell if not grid.occupied[start_cell] else _nearest_free(grid, start_cell)
    weights = np.where(grid.occupied, np.inf, 1.0).astype(np.float32)
    cells = pyastar2d.astar_path(weights, free_start, grid.cell(goal), allow_diagonal=True)
    if cells is None:
        raise NavigationError(NavigateErrorCode.UNREACHABLE,
                              f'no free path leads to ({goal[0]:.2f}, {goal[1]:.2f})')
    points = [start] + [grid.point(row, column) for row, column in cells[1:-1]] + [goal]
    return shortcut(grid, np.array(points))


def _nearest_free(grid: OccupancyGrid, cell: tuple[int, int]) -> tuple[int, int]:
    free = np.argwhere(~grid.occupied)
    if len(free) == 0:
        raise NavigationError(NavigateErrorCode.UNREACHABLE, 'the map has no free cell')
    nearest = free[np.argmin(np.sum((free - np.array(cell)) ** 2, axis=1))]
    return int(nearest[0]), int(nearest[1])


def shortcut(grid: OccupancyGrid, points: np.ndarray) -> np.ndarray:
    """The path through as few of its points as keep every leg free: from each kept point, the farthest later
    point it sees in a straight line."""
    kept = [0]
    while kept[-1] < len(points) - 1:
        here = kept[-1]
        farthest = here + 1
        for later in range(len(points) - 1, here + 1, -1):
            if grid.segment_is_free(points[here], points[later]):
                farthest = later
                break
        kept.append(farthest)
    return points[kept]


def path_length(points: np.ndarray) -> float:
    return float(np.sum(np.linalg.norm(np.diff(points, axis=0), axis=1))) if len(points) > 1 else 0.0


def wrap_angle(angle: float) -> float:
    return (angle + math.pi) % (2 * math.pi) - math.pi


@dataclasses.dataclass(frozen=True)
class FollowerLimits:
    max_speed: float = 0.5  # [m/s]
    max_acceleration: float = 0.5  # [m/s^2]
    max_yaw_rate: float = 1.2  # [rad/s]
    max_yaw_acceleration: float = 2.0  # [rad/s^2]
    look_ahead: float = 0.4  # [m] pure pursuit's look-ahead distance
    position_tolerance: float = 0.05  # [m]
    yaw_tolerance: float = 0.05  # [rad]


@dataclasses.dataclass
class Command:
    speed: float  # forward [m/s]
    yaw_rate: float  # [rad/s]
    done: bool = False


class PathFollower:
    """Pure pursuit along `path` to the goal heading `goal_yaw`; `step(pose, dt)` gives the next command.

    The commanded speed and yaw rate change by at most the accelerations times dt per step; the speed is at most
    what stops the base at the goal (v^2 <= 2 a d), and the yaw rate what stops it at the goal heading.
    """

    def __init__(self, path: np.ndarray, goal_yaw: float, limits: FollowerLimits = FollowerLimits()) -> None:
        self.path = np.asarray(path, dtype=float)
        self.goal_yaw = goal_yaw
        self.limits = limits
        self.speed = 0.0
        self.yaw_rate = 0.0
        self._segment = 0  # the path segment the base is along
        self._arrived = len(self.path) < 2  # at the goal point: only the heading is left

    def remaining_distance(self, xy: Sequence[float]) -> float:
        """Along the path from the point nearest `xy` on the current segment to the goal."""
        xy = np.asarray(xy[:2], dtype=float)
        if self._arrived or len(self.path) < 2:
            return float(np.linalg.norm(self.path[-1] - xy))
        a, b = self.path[self._segment], self.path[self._segment + 1]
        projected = a + _along(a, b, xy) * (b - a)
        return float(np.linalg.norm(b - projected)) + path_length(self.path[self._segment + 1:])

    def step(self, pose: Sequence[float], dt: float) -> Command:
        x, y, yaw = pose
        limits = self.limits
        goal = self.path[-1]
        to_goal = float(np.hypot(goal[0] - x, goal[1] - y))
        # Arrived: near enough that the braking still under way ends within the tolerance.
        if not self._arrived and (to_goal <= limits.position_tolerance / 2 or (
                to_goal <= limits.position_tolerance and self.speed <= limits.max_acceleration * dt)):
            self._arrived = True
        if self._arrived:
            heading_error = wrap_angle(self.goal_yaw - yaw)
            if abs(heading_error) <= limits.yaw_tolerance and abs(self.yaw_rate) <= limits.max_yaw_acceleration * dt:
                self.speed = self.yaw_rate = 0.0
                return Command(0.0, 0.0, done=True)
            return self._command(0.0, self._turn_rate(heading_error), dt)
        self._advance((x, y))
        target = self._look_ahead_point((x, y))
        heading_error = wrap_angle(math.atan2(target[1] - y, target[0] - x) - yaw)
        # Brake for the nearer of the path's rest and the goal in a straight line (cutting the last corner, the base
        # is nearer the goal than its projection on the path says).
        stopping = math.sqrt(2 * limits.max_acceleration * min(self.remaining_distance((x, y)), to_goal))
        if abs(heading_error) > math.pi / 3:  # facing away from the path: turn on the spot first
            return self._command(0.0, self._turn_rate(heading_error), dt)
        distance = max(float(np.hypot(target[0] - x, target[1] - y)), 1e-6)
        speed = min(limits.max_speed, stopping) * max(math.cos(heading_error), 0.0)
        # Pure pursuit: the arc through the look-ahead point has curvature 2 sin(error) / distance.
        yaw_rate = speed * 2 * math.sin(heading_error) / distance
        if abs(yaw_rate) > limits.max_yaw_rate:  # too tight a turn at this speed: slow down along the same arc
            speed *= limits.max_yaw_rate / abs(yaw_rate)
            yaw_rate = math.copysign(limits.max_yaw_rate, yaw_rate)
        return self._command(speed, yaw_rate, dt)

    def _turn_rate(self, heading_error: float) -> float:
        limits = self.limits
        stopping = math.sqrt(2 * limits.max_yaw_acceleration * abs(heading_error))
        return math.copysign(min(limits.max_yaw_rate, stopping), heading_error)

    def _command(self, speed: float, yaw_rate: float, dt: float) -> Command:
        limits = self.limits
        self.speed += float(np.clip(speed - self.speed, -limits.max_acceleration * dt, limits.max_acceleration * dt))
        self.yaw_rate += float(np.clip(yaw_rate - self.yaw_rate, -limits.max_yaw_acceleration * dt,
                                       limits.max_yaw_acceleration * dt))
        return Command(self.speed, self.yaw_rate)

    def _advance(self, xy: tuple[float, float]) -> None:
        """Move on to the next segment once the base is past the current one's end."""
        while self._segment < len(self.path) - 2:
            a, b = self.path[self._segment], self.path[self._segment + 1]
            if _along(a, b, xy) < 1.0:
                break
            self._segment += 1

    def _look_ahead_point(self, xy: tuple[float, float]) -> np.ndarray:
        """The point `look_ahead` further along the path than the base's projection on it (the goal at most)."""
        a, b = self.path[self._segment], self.path[self._segment + 1]
        left = self.limits.look_ahead + _along(a, b, xy) * float(np.linalg.norm(b - a))
        for i in range(self._segment, len(self.path) - 1):
            a, b = self.path[i], self.path[i + 1]
            length = float(np.linalg.norm(b - a))
            if left <= length:
                return a + (b - a) * (left / max(length, 1e-9))
            left -= length
        return self.path[-1]


def follow_on_ideal_base(follower: PathFollower, pose: Sequence[float], dt: float = 0.01,
                         limit_s: float = 180.0) -> tuple[np.ndarray, list[Command]]:
    """The poses (N, 3) of a base that moves exactly as commanded (no wheels, no physics) under the follower, from
    `pose` until it is done or `limit_s` passed, and the commands: what the planner and follower alone do."""
    x, y, yaw = (float(v) for v in pose)
    poses, commands = [(x, y, yaw)], []
    for _ in range(int(limit_s / dt)):
        command = follower.step((x, y, yaw), dt)
        commands.append(command)
        if command.done:
            break
        x += command.speed * math.cos(yaw) * dt
        y += command.speed * math.sin(yaw) * dt
        yaw = wrap_angle(yaw + command.yaw_rate * dt)
        poses.append((x, y, yaw))
    return np.array(poses), commands


def base_trajectory(poses: np.ndarray, commands: Sequence[Command], dt: float, start_yaw: float,
                    period: float = 0.1) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The timed trajectory of the base's joints (x, y, yaw) that drives `poses` (an ideal base's, every `dt`, under
    `commands`, as follow_on_ideal_base gives them): (times from 0 (N,), positions (N, 3), velocities (N, 3)), a
    point every `period` and the last one.

    The yaw is continuous and starts at `start_yaw`, the base joint's value (which counts whole turns), so the
    base turns the way the follower did and never the long way round through a wrap at pi.
    """
    poses = np.asarray(poses, dtype=float)
    yaw = np.unwrap(poses[:, 2])
    yaw += start_yaw - yaw[0]
    velocities = np.zeros_like(poses)
    for k, command in enumerate(commands[:len(poses) - 1]):  # command k moves pose k to pose k + 1
        velocities[k] = (command.speed * math.cos(poses[k, 2]), command.speed * math.sin(poses[k, 2]),
                         command.yaw_rate)
    every = max(1, int(round(period / dt)))
    keep = list(range(0, len(poses), every))
    if keep[-1] != len(poses) - 1:
        keep.append(len(poses) - 1)
    positions = np.column_stack([poses[:, 0], poses[:, 1], yaw])[keep]
    return np.asarray(keep, dtype=float) * dt, positions, velocities[keep]


def _along(a: np.ndarray, b: np.ndarray, xy: Sequence[float]) -> float:
    """Where the point projects on segment a-b, as a fraction of it (clamped at 0, not at 1)."""
    ab = b - a
    length2 = float(ab @ ab)
    if length2 < 1e-12:
        return 1.0
    return max(0.0, float((np.asarray(xy) - a) @ ab) / length2)
