"""Reading a FollowJointTrajectory goal (control_msgs semantics) into arrays the world can follow; no rclpy.

Semantics kept from control_msgs / ros2_control's joint trajectory controller:
- joint_names may be any subset of the arm's joints in any order; joints left out hold their current reference;
- time_from_start is relative to the moment the goal starts (header.stamp is not used for delayed starts);
- a tolerance of 0 means the default, a negative one means "not checked";
- joints with several axes (multi_dof_trajectory, component tolerances) are refused: this arm has none.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Sequence

import numpy as np
from cap_ros_common.time import to_seconds

# control_msgs/FollowJointTrajectory's result codes.
SUCCESSFUL = 0
INVALID_GOAL = -1
INVALID_JOINTS = -2
PATH_TOLERANCE_VIOLATED = -4
GOAL_TOLERANCE_VIOLATED = -5

DEFAULT_GOAL_TOLERANCE = 0.002  # [rad] per joint: about 2 mm at the tool of a stretched UR5e
DEFAULT_GOAL_TIME_TOLERANCE = 1.0  # [s] after the last point for the goal tolerance to be met


class GoalError(ValueError):
    """A goal that cannot be followed; code is the result error_code to report."""

    def __init__(self, code: int, message: str) -> None:
        super().__init__(message)
        self.code = code


@dataclasses.dataclass(frozen=True)
class TrajectoryPlan:
    """A goal in the arm's joint order. Tolerances are per joint [rad, rad/s]; inf = not checked."""

    times: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray | None
    goal_position_tolerance: np.ndarray
    goal_velocity_tolerance: np.ndarray
    path_position_tolerance: np.ndarray
    goal_time_tolerance: float

    @property
    def final_positions(self) -> np.ndarray:
        return self.positions[-1]

    def path_violation(self, actual: np.ndarray, desired: np.ndarray, joint_names: Sequence[str]) -> str | None:
        """A message naming the joints whose tracking error exceeds the path tolerance, or None."""
        over = np.abs(actual - desired) > self.path_position_tolerance
        if not np.any(over):
            return None
        return 'path tolerance exceeded by ' + ', '.join(
            f'{name} ({abs(a - d):.4f} rad)' for name, a, d, o in zip(joint_names, actual, desired, over) if o)

    def goal_reached(self, positions: np.ndarray, velocities: np.ndarray) -> bool:
        return bool(np.all(np.abs(positions - self.final_positions) <= self.goal_position_tolerance)
                    and np.all(np.abs(velocities) <= self.goal_velocity_tolerance))

    def goal_errors(self, positions: np.ndarray, joint_names: Sequence[str]) -> str:
        errors = positions - self.final_positions
        return ', '.join(f'{name} {error:+.4f} rad' for name, error in zip(joint_names, errors))


def _tolerances(entries, arm_joint_names: Sequence[str], field: str, default: float) -> np.ndarray:
    values = np.full(len(arm_joint_names), default)
    for entry in entries:
        if entry.name not in arm_joint_names:
            raise GoalError(INVALID_JOINTS, f'tolerance for unknown joint {entry.name!r}')
        value = getattr(entry, field)
        index = arm_joint_names.index(entry.name)
        values[index] = math.inf if value < 0 else (default if value == 0 else value)
    return values


def plan_from_goal(goal, arm_joint_names: Sequence[str], hold_positions: np.ndarray,
                   default_goal_tolerance: float = DEFAULT_GOAL_TOLERANCE,
                   default_goal_time_tolerance: float = DEFAULT_GOAL_TIME_TOLERANCE) -> TrajectoryPlan:
    """Check a FollowJointTrajectory goal and express it in the arm's joint order. Raises GoalError."""
    arm_joint_names = list(arm_joint_names)
    trajectory = goal.trajectory
    if goal.multi_dof_trajectory.joint_names or goal.multi_dof_trajectory.points:
        raise GoalError(INVALID_JOINTS, 'multi_dof_trajectory names joints this controller does not have (it moves '
                                        f'{list(arm_joint_names)})')
    if goal.component_path_tolerance or goal.component_goal_tolerance:
        raise GoalError(INVALID_GOAL, 'component tolerances apply to multi-DOF joints, which this controller does '
                                      'not have')
    names = list(trajectory.joint_names)
    if not names:
        raise GoalError(INVALID_JOINTS, 'the trajectory names no joints')
    unknown = [n for n in names if n not in arm_joint_names]
    if unknown:
        raise GoalError(INVALID_JOINTS, f'unknown joints {unknown}; the arm has {arm_joint_names}')
    if len(set(names)) != len(names):
        raise GoalError(INVALID_JOINTS, f'joint names repeat: {names}')
    points = list(trajectory.points)
    if not points:
        raise GoalError(INVALID_GOAL, 'the trajectory has no points')
    columns = [arm_joint_names.index(n) for n in names]
    times = np.array([to_seconds(p.time_from_start) for p in points])
    if times[0] < 0 or np.any(np.diff(times) <= 0):
        raise GoalError(INVALID_GOAL, 'time_from_start must be >= 0 and increase strictly from point to point')
    positions = np.tile(np.asarray(hold_positions, dtype=float), (len(points), 1))
    with_velocities = [len(p.velocities) > 0 for p in points]
    velocities = np.zeros_like(positions) if all(with_velocities) else None
    if any(with_velocities) and not all(with_velocities):
        raise GoalError(INVALID_GOAL, 'give velocities for every point or for none')
    for i, point in enumerate(points):
        if len(point.positions) != len(names):
            raise GoalError(INVALID_GOAL, f'point {i} has {len(point.positions)} positions for {len(names)} joints')
        positions[i, columns] = point.positions
        if velocities is not None:
            if len(point.velocities) != len(names):
                raise GoalError(INVALID_GOAL, f'point {i} has {len(point.velocities)} velocities for {len(names)} '
                                'joints')
            velocities[i, columns] = point.velocities
    goal_time = to_seconds(goal.goal_time_tolerance)
    return TrajectoryPlan(
        times=times, positions=positions, velocities=velocities,
        goal_position_tolerance=_tolerances(goal.goal_tolerance, arm_joint_names, 'position',
                                            default_goal_tolerance),
        goal_velocity_tolerance=_tolerances(goal.goal_tolerance, arm_joint_names, 'velocity', math.inf),
        path_position_tolerance=_tolerances(goal.path_tolerance, arm_joint_names, 'position', math.inf),
        goal_time_tolerance=goal_time if goal_time > 0 else default_goal_time_tolerance)
