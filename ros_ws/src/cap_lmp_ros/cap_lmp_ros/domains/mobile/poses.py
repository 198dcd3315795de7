"""What the mobile robot API makes of the values a program passes (plain Python, no rclpy): floor points, headings,
the poses of a trajectory. Every bad value is a RobotApiError that says what was expected."""
from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np
from cap_mobile import layout

from cap_lmp.errors import RobotApiError

MAX_TRAJ_POINTS = 200  # of one follow_traj (each is a stop of the base)
MIN_LEG = 0.02  # [m] points closer than this to the one before are dropped (no heading between them)


def floor_point(pos: Any, what: str = 'a position') -> np.ndarray:
    """np.array([x, y]) of `pos` ([x, y], or [x, y, ...] of which x and y are taken)."""
    try:
        point = np.asarray(pos, dtype=float).reshape(-1)
    except (TypeError, ValueError, OverflowError):
        raise RobotApiError(f'{what} must be [x, y] in metres, not {type(pos).__name__}') from None
    if point.size < 2 or point.size > 3:
        raise RobotApiError(f'{what} must be [x, y] in metres, not {point.size} numbers')
    if not np.all(np.isfinite(point)):
        raise RobotApiError(f'{what} has a value that is not a number')
    return point[:2]


def heading(angle: Any) -> float:
    """A finite angle in radians, or a RobotApiError."""
    try:
        value = float(angle)
    except (TypeError, ValueError, OverflowError):
        raise RobotApiError(f'an angle must be a number of radians, not {type(angle).__name__}') from None
    if not math.isfinite(value):
        raise RobotApiError('an angle must be a finite number of radians')
    return value


def location_name(name: Any) -> str:
    """The kitchen's name for a location the program named ("the Table" -> 'table'), or an error naming them all."""
    if not isinstance(name, str):
        raise RobotApiError(f'a location name must be text like "table", not {type(name).__name__}')
    try:
        return layout.location(name[:200]).name
    except layout.UnknownLocationError as error:
        raise RobotApiError(str(error)) from None


def traj_poses(pts: Any, start: Sequence[float]) -> list[tuple[float, float, float]]:
    """(x, y, yaw) for each point of a trajectory: each faces the leg that leads to it (the first, the leg from
    `start`), so the base drives forward along the trajectory; points on top of the one before are dropped."""
    try:
        points = np.asarray(pts, dtype=float)
    except (TypeError, ValueError, OverflowError):
        raise RobotApiError(f'a trajectory must be rows of [x, y] in metres, not {type(pts).__name__}') from None
    if points.ndim != 2 or points.shape[1] not in (2, 3) or len(points) == 0:
        raise RobotApiError(f'a trajectory must be rows of [x, y] in metres, not an array of shape '
                            f'{tuple(points.shape)}')
    if len(points) > MAX_TRAJ_POINTS:
        raise RobotApiError(f'a trajectory takes at most {MAX_TRAJ_POINTS} points, not {len(points)}')
    if not np.all(np.isfinite(points)):
        raise RobotApiError('a trajectory has a point that is not a number')
    poses, previous = [], np.asarray(start[:2], dtype=float)
    yaw = float(start[2]) if len(start) > 2 else 0.0
    for x, y in points[:, :2]:
        if math.hypot(x - previous[0], y - previous[1]) < MIN_LEG:
            continue
        yaw = math.atan2(y - previous[1], x - previous[0])
        poses.append((float(x), float(y), yaw))
        previous = np.array([x, y])
    return poses


__all__ = ['MAX_TRAJ_POINTS', 'floor_point', 'heading', 'location_name', 'traj_poses']
