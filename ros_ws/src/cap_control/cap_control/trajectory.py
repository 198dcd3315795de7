"""Timed joint trajectories for the UR5e: joint-space paths timed by Ruckig, and straight Cartesian lines.

Limits: Universal Robots publishes the joint speed (180 deg/s) but no joint acceleration or jerk limit. We choose
3 rad/s^2 (about twice URScript's movej default of 1.4 rad/s^2, well below what the arm can do) and 30 rad/s^3
(full acceleration reached in 0.1 s), which keeps a block held by friction steady in the gripper.

Ruckig's free edition computes waypoint trajectories only through its cloud service, so a path through several
waypoints is timed segment by segment, each time-optimal from rest to rest. Pick-and-place motions are short
point-to-point moves, so the stops cost little and keep every waypoint exact.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np
import ruckig
from cap_ros_common.parameters import parameter
from scipy.spatial.transform import Rotation, Slerp

from cap_control.kinematics import (
    DEFAULT_TOOL_OFFSET, JOINT_LOWER, JOINT_NAMES, JOINT_UPPER, forward_kinematics, inverse_kinematics,
)

# Time between the points of a timed trajectory [s]: what the arm's controller is sent.
DEFAULT_PERIOD = 0.02


class TrajectoryError(RuntimeError):
    """A trajectory cannot be made: limits inconsistent, joints out of range, or the IK branch would flip."""


@dataclass(frozen=True)
class JointLimits:
    """Per-joint kinematic limits [rad, rad/s, rad/s^2, rad/s^3]."""

    velocity: np.ndarray
    acceleration: np.ndarray
    jerk: np.ndarray
    lower: np.ndarray = field(default_factory=lambda: JOINT_LOWER.copy())
    upper: np.ndarray = field(default_factory=lambda: JOINT_UPPER.copy())

    def scaled(self, velocity_scale: float = 1.0, acceleration_scale: float = 1.0) -> 'JointLimits':
        """The same limits with velocity and acceleration (and jerk, with acceleration) scaled down."""
        if not (0.0 < velocity_scale <= 1.0 and 0.0 < acceleration_scale <= 1.0):
            raise ValueError('scales must lie in (0, 1]')
        return JointLimits(self.velocity * velocity_scale, self.acceleration * acceleration_scale,
                           self.jerk * acceleration_scale, self.lower, self.upper)


UR5E_LIMITS = JointLimits(
    velocity=np.array([math.pi, math.pi, math.pi, 2 * math.pi, 2 * math.pi, 2 * math.pi]),
    acceleration=np.array([12.0, 12.0, 12.0, 24.0, 24.0, 24.0]),
    jerk=np.array([150.0, 150.0, 150.0, 300.0, 300.0, 300.0]),
)


@dataclass(frozen=True)
class CartesianLimits:
    """Limits of the TCP along a straight line: linear [m/s, m/s^2, m/s^3] and angular speed [rad/s]."""

    speed: float = parameter(0.5, 'Tool speed on straight descents and lifts [m/s].')
    acceleration: float = parameter(6.0, 'Tool acceleration on straight lines [m/s^2].')
    jerk: float = parameter(80.0, 'Tool jerk on straight lines [m/s^3].')
    angular_speed: float = parameter(1.0, 'Tool turning speed on straight lines [rad/s].')


@dataclass
class JointTrajectory:
    """Samples of a timed joint trajectory: times (N,) from 0, positions/velocities/accelerations (N, 6)."""

    times: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray
    accelerations: np.ndarray
    joint_names: tuple[str, ...] = JOINT_NAMES

    @property
    def duration(self) -> float:
        return float(self.times[-1])

    @property
    def start(self) -> np.ndarray:
        return self.positions[0]

    @property
    def end(self) -> np.ndarray:
        return self.positions[-1]

    def __len__(self) -> int:
        return len(self.times)


def _at_rest(q: np.ndarray) -> JointTrajectory:
    q = np.asarray(q, dtype=float).reshape(1, 6)
    return JointTrajectory(np.zeros(1), q.copy(), np.zeros((1, 6)), np.zeros((1, 6)))


def _sample_times(duration: float, period: float) -> np.ndarray:
    """0, period, 2*period, ... and exactly `duration` at the end (no sliver of a last step)."""
    times = np.arange(0.0, duration, period)
    if duration - times[-1] < 0.5 * period and len(times) > 1:
        times = times[:-1]
    return np.append(times, duration)


def _ruckig_segment(start: np.ndarray, goal: np.ndarray, limits: JointLimits, period: float) -> JointTrajectory:
    generator = ruckig.Ruckig(len(start))
    request = ruckig.InputParameter(len(start))
    request.current_position = start.tolist()
    request.current_velocity = [0.0] * len(start)
    request.current_acceleration = [0.0] * len(start)
    request.target_position = goal.tolist()
    request.target_velocity = [0.0] * len(start)
    request.target_acceleration = [0.0] * len(start)
    request.max_velocity = np.broadcast_to(limits.velocity, start.shape).tolist()
    request.max_acceleration = np.broadcast_to(limits.acceleration, start.shape).tolist()
    request.max_jerk = np.broadcast_to(limits.jerk, start.shape).tolist()
    timed = ruckig.Trajectory(len(start))
    result = generator.calculate(request, timed)
    if result not in (ruckig.Result.Working, ruckig.Result.Finished):
        raise TrajectoryError(f'Ruckig could not time the motion {start.tolist()} -> {goal.tolist()}: {result}')
    times = _sample_times(timed.duration, period)
    samples = [timed.at_time(float(t)) for t in times]
    positions = np.array([s[0] for s in samples])
    positions[-1] = goal  # exact endpoint, free of rounding in the profile evaluation
    return JointTrajectory(times, positions, np.array([s[1] for s in samples]), np.array([s[2] for s in samples]))


def concatenate(parts: Sequence[JointTrajectory]) -> JointTrajectory:
    """One trajectory running the parts one after the other (each part's first sample equals the previous end)."""
    if not parts:
        raise ValueError('nothing to concatenate')
    times, positions, velocities, accelerations = [parts[0].times], [parts[0].positions], [parts[0].velocities], \
        [parts[0].accelerations]
    offset = parts[0].duration
    for part in parts[1:]:
        times.append(part.times[1:] + offset)
        positions.append(part.positions[1:])
        velocities.append(part.velocities[1:])
        accelerations.append(part.accelerations[1:])
        offset += part.duration
    return JointTrajectory(np.concatenate(times), np.concatenate(positions), np.concatenate(velocities),
                           np.concatenate(accelerations), parts[0].joint_names)


def time_joint_path(waypoints: Sequence[Sequence[float]], limits: JointLimits = UR5E_LIMITS,
                    period: float = DEFAULT_PERIOD) -> JointTrajectory:
    """Time a joint-space path through `waypoints` (the first is the current position), at rest at each waypoint.

    Each segment is Ruckig's time-optimal jerk-limited profile within `limits`; all joints of a segment start and
    stop together. Samples every `period` seconds, and exactly at each waypoint's arrival time at the end.
    """
    if period <= 0:
        raise ValueError('period must be positive')
    points = np.asarray(waypoints, dtype=float)
    if points.ndim != 2 or points.shape[1] != 6 or len(points) == 0:
        raise ValueError(f'expected waypoints of shape (N, 6), got {points.shape}')
    outside = np.any((points < limits.lower - 1e-9) | (points > limits.upper + 1e-9), axis=1)
    if np.any(outside):
        raise TrajectoryError(f'waypoint {int(np.argmax(outside))} lies outside the joint limits')
    parts = [_at_rest(points[0])]
    for start, goal in zip(points[:-1], points[1:]):
        if np.max(np.abs(goal - start)) < 1e-12:
            continue
        parts.append(_ruckig_segment(start, goal, limits, period))
    return concatenate(parts)


def _time_path_parameter(period: float, speed: float, acceleration: float, jerk: float) -> tuple[np.ndarray, ...]:
    """Times and s(t) in [0, 1] of a jerk-limited rest-to-rest motion of one path parameter."""
    generator = ruckig.Ruckig(1)
    request = ruckig.InputParameter(1)
    request.current_position = [0.0]
    request.target_position = [1.0]
    request.max_velocity = [speed]
    request.max_acceleration = [acceleration]
    request.max_jerk = [jerk]
    timed = ruckig.Trajectory(1)
    try:
        result = generator.calculate(request, timed)
    except ruckig.RuckigError:
        # Ruckig 0.19 fails on the boundary case where full acceleration is reached exactly at full speed
        # (acceleration^2 / jerk == speed); one percent less jerk steps off it.
        request.max_jerk = [jerk * 0.99]
        result = generator.calculate(request, timed)
    if result not in (ruckig.Result.Working, ruckig.Result.Finished):
        raise TrajectoryError(f'Ruckig could not time the Cartesian line: {result}')
    times = _sample_times(timed.duration, period)
    s = np.array([timed.at_time(float(t))[0][0] for t in times])
    s[-1] = 1.0
    return times, np.clip(s, 0.0, 1.0)


def _finite_difference(values: np.ndarray, times: np.ndarray) -> np.ndarray:
    if len(times) < 3:
        return np.zeros_like(values)
    derivative = np.gradient(values, times, axis=0)
    derivative[0] = derivative[-1] = 0.0  # the line starts and ends at rest
    return derivative


def cartesian_line(q_start: Sequence[float], end_pose: np.ndarray, limits: JointLimits = UR5E_LIMITS,
                   cartesian_limits: CartesianLimits = CartesianLimits(), period: float = DEFAULT_PERIOD,
                   tool_offset: float = DEFAULT_TOOL_OFFSET, max_joint_step: float = 0.1) -> JointTrajectory:
    """Joint trajectory moving the TCP on a straight line from where `q_start` puts it to `end_pose`.

    Position moves linearly and orientation by slerp, along a path parameter timed by Ruckig within
    `cartesian_limits`; every sample is solved by IK seeded with the previous one. The line is slowed down until
    the joints respect `limits` (velocity and acceleration). Raises TrajectoryError if a sample leaves the IK branch
    (a joint jumps by more than `max_joint_step` [rad] between samples) and IKError if a sample is out of reach.
    """
    q_start = np.asarray(q_start, dtype=float)
    start_pose = forward_kinematics(q_start, tool_offset)
    end_pose = np.asarray(end_pose, dtype=float)
    length = float(np.linalg.norm(end_pose[:3, 3] - start_pose[:3, 3]))
    rotations = Rotation.from_matrix(np.stack([start_pose[:3, :3], end_pose[:3, :3]]))
    angle = float((rotations[0].inv() * rotations[1]).magnitude())
    if length < 1e-9 and angle < 1e-9:
        return _at_rest(q_start)
    slerp = Slerp([0.0, 1.0], rotations)

    def poses_at(s: np.ndarray) -> np.ndarray:
        poses = np.tile(np.eye(4), (len(s), 1, 1))
        poses[:, :3, :3] = slerp(s).as_matrix()
        poses[:, :3, 3] = (1.0 - s)[:, None] * start_pose[:3, 3] + s[:, None] * end_pose[:3, 3]
        return poses

    return timed_cartesian_path(q_start, poses_at, length, angle, limits, cartesian_limits, period, tool_offset,
                                max_joint_step)


def timed_cartesian_path(q_start: Sequence[float], poses_at: Callable[[np.ndarray], np.ndarray], length: float,
                         angle: float = 0.0, limits: JointLimits = UR5E_LIMITS,
                         cartesian_limits: CartesianLimits = CartesianLimits(), period: float = DEFAULT_PERIOD,
                         tool_offset: float = DEFAULT_TOOL_OFFSET, max_joint_step: float = 0.1) -> JointTrajectory:
    """Joint trajectory moving the TCP along a Cartesian path from rest to rest.

    `poses_at(s)` gives the TCP poses (N, 4, 4) at path parameters s (N,) in [0, 1]; `poses_at([0])` must be where
    `q_start` puts the TCP. `length` [m] and `angle` [rad] are the path's length and total turn, which set how
    fast s may run within `cartesian_limits`. s is timed by Ruckig (jerk-limited), every sample solved by IK seeded
    with the previous one, and the whole path slowed down until the joints respect `limits` (velocity and
    acceleration). Raises TrajectoryError if a sample leaves the IK branch (a joint jumps by more than
    `max_joint_step` [rad] between samples) and IKError if a sample is out of reach.
    """
    q_start = np.asarray(q_start, dtype=float)
    # Path-parameter limits: the tighter of the linear and angular ones.
    speed = min(cartesian_limits.speed / max(length, 1e-12), cartesian_limits.angular_speed / max(angle, 1e-12))
    acceleration = cartesian_limits.acceleration / max(length, 1e-12) if length > 1e-9 else speed * 4.0
    jerk = cartesian_limits.jerk / max(length, 1e-12) if length > 1e-9 else speed * 40.0
    for _ in range(20):
        times, s = _time_path_parameter(period, speed, acceleration, jerk)
        positions = np.empty((len(times), 6))
        previous = q_start
        for k, pose in enumerate(poses_at(s)):
            q = inverse_kinematics(pose, q_seed=previous, tool_offset=tool_offset)
            step = float(np.max(np.abs(q - previous)))
            if step > max_joint_step:
                raise TrajectoryError(
                    f'the path would flip the arm configuration at {np.round(pose[:3, 3], 3).tolist()} '
                    f'(a joint jumps by {step:.2f} rad between samples)')
            positions[k] = q
            previous = q
        positions[0] = q_start  # the path starts exactly where the arm is
        velocities = _finite_difference(positions, times)
        accelerations = _finite_difference(velocities, times)
        ratio = max(float(np.max(np.abs(velocities) / limits.velocity)),
                    math.sqrt(float(np.max(np.abs(accelerations) / limits.acceleration))))
        if ratio <= 1.0:
            return JointTrajectory(times, positions, velocities, accelerations)
        # Too fast for a joint (near a singularity): slow the whole path and time it again.
        slow_down = 0.9 / ratio
        speed, acceleration, jerk = speed * slow_down, acceleration * slow_down ** 2, jerk * slow_down ** 3
    raise TrajectoryError('the path cannot be made slow enough for the joint limits (singularity?)')


def trajectory_tcp_positions(trajectory: JointTrajectory, tool_offset: float = DEFAULT_TOOL_OFFSET) -> np.ndarray:
    """TCP positions (N, 3) along a trajectory, e.g. to check it stays above the table."""
    return np.array([forward_kinematics(q, tool_offset)[:3, 3] for q in trajectory.positions])


__all__ = [
    'CartesianLimits', 'DEFAULT_PERIOD', 'JointLimits', 'JointTrajectory', 'TrajectoryError',
    'UR5E_LIMITS', 'cartesian_line', 'concatenate', 'time_joint_path', 'timed_cartesian_path',
    'trajectory_tcp_positions',
]
