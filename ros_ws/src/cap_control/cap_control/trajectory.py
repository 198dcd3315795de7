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
    DEFAULT_TOOL_OFFSET, JOINT_LOWER, JOINT_NAMES, JOINT_UPPER, forward_kinematics, inverse_kinematics_path,
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


class _PathParameterProfiles:
    """Jerk-limited rest-to-rest motions of the path parameters s of several paths from 0 to 1, each Ruckig's
    time-optimal one within its limits (speed, acceleration, jerk: `limits` (k, 3)), sampled every `period` and
    exactly at the end (`_sample_times`).

    Ruckig computes each profile; the samples of any run of paths are evaluated together in NumPy: each of a
    profile's seven phases has a constant jerk, so s is a cubic in the time since the phase began (what
    `at_time` evaluates).
    """

    def __init__(self, limits: np.ndarray, period: float):
        self.limits, self.period = np.asarray(limits, dtype=float).reshape(-1, 3), period
        count = len(self.limits)
        self.durations = np.empty(count)
        self.phases = np.empty((count, 7))  # phase durations; then the state where each phase begins:
        self.p, self.v, self.a, self.j = (np.empty((count, 7)) for _ in range(4))
        self.irregular: dict[int, np.ndarray] = {}  # s at the sample times of profiles not from rest
        generator, request, timed = ruckig.Ruckig(1), ruckig.InputParameter(1), ruckig.Trajectory(1)
        request.current_position, request.target_position = [0.0], [1.0]
        for index, (speed, acceleration, jerk) in enumerate(self.limits.tolist()):
            request.max_velocity, request.max_acceleration, request.max_jerk = [speed], [acceleration], [jerk]
            try:
                result = generator.calculate(request, timed)
            except ruckig.RuckigError:
                # Ruckig 0.19 fails on the boundary case where full acceleration is reached exactly at full speed
                # (acceleration^2 / jerk == speed); one percent less jerk steps off it.
                request.max_jerk = [jerk * 0.99]
                result = generator.calculate(request, timed)
            if result not in (ruckig.Result.Working, ruckig.Result.Finished):
                raise TrajectoryError(f'Ruckig could not time the Cartesian line: {result}')
            profile = timed.profiles[0][0]
            self.durations[index] = timed.duration
            self.phases[index] = profile.t
            self.p[index], self.v[index], self.a[index] = profile.p[:-1], profile.v[:-1], profile.a[:-1]
            self.j[index] = profile.j
            if profile.brake.duration > 0 or profile.accel.duration > 0:
                self.irregular[index] = np.array([timed.at_time(float(t))[0][0]
                                                  for t in _sample_times(timed.duration, period)])
        self.ends = np.cumsum(self.phases, axis=1)  # when each phase ends
        self.begins = self.ends - self.phases
        # How many samples each profile has (both ends included), as _sample_times makes them.
        steps = np.ceil(self.durations / period).astype(int)  # of np.arange(0, duration, period)
        sliver = (self.durations - (steps - 1) * period < 0.5 * period) & (steps > 1)
        self.samples = steps + 1 - sliver

    def sampled(self, first: int, last: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The samples of paths first to last (excluded), one after the other, each path's last sample the next
        one's first: (times from the first path's start (R,), s (R,), the path of each sample (R,; the first
        sample is the first path's), the sample where each path starts (and, last, where the last one ends))."""
        counts = self.samples[first:last] - 1
        starts = np.concatenate([[0], np.cumsum(counts)])
        path = np.repeat(np.arange(first, last), counts)
        index = np.arange(1, starts[-1] + 1) - np.repeat(starts[:-1], counts)  # 1 .. samples - 1 within a path
        duration = self.durations[path]
        at_end = index == self.samples[path] - 1
        t = np.where(at_end, duration, index * self.period)
        phase = np.minimum(np.count_nonzero(self.ends[path] <= t[:, None], axis=1), 6)
        dt = t - self.begins[path, phase]
        p, v, a, j = (table[path, phase] for table in (self.p, self.v, self.a, self.j))
        s = np.where(at_end | (t >= duration), 1.0, p + dt * (v + dt * (a / 2 + dt * j / 6)))
        for number, values in self.irregular.items():
            if first <= number < last:
                s[starts[number - first]:starts[number - first + 1]] = values[1:]
        offsets = np.concatenate([[0.0], np.cumsum(self.durations[first:last])])
        times = np.concatenate([[0.0], offsets[path - first] + t])
        return times, np.concatenate([[0.0], np.clip(s, 0.0, 1.0)]), np.concatenate([[first], path]), starts


def _finite_difference(times: np.ndarray, at_rest: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
    """d values / d time along the last axis of what it is given (second-order central differences, np.gradient's
    for uneven steps), zero at the samples `at_rest` (where a path starts or ends) and at both ends."""
    before, after = np.diff(times[:-1]), np.diff(times[1:])
    weights = (-after / (before * (before + after)), (after - before) / (before * after),
               before / (after * (before + after)))

    def derivative(values: np.ndarray) -> np.ndarray:
        result = np.zeros_like(values)
        if len(times) < 3:
            return result
        middle = result[..., 1:-1]
        np.multiply(weights[0], values[..., :-2], out=middle)
        middle += weights[1] * values[..., 1:-1]
        middle += weights[2] * values[..., 2:]
        result[..., at_rest] = 0.0
        return result
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


def _path_parameter_limits(lengths: np.ndarray, angles: np.ndarray, cartesian_limits: CartesianLimits) -> np.ndarray:
    """Speed, acceleration and jerk (k, 3) of the path parameters of paths `lengths` [m] long turning by `angles`
    [rad]: the tighter of the linear and angular limits."""
    speed = np.minimum(cartesian_limits.speed / np.maximum(lengths, 1e-12),
                       cartesian_limits.angular_speed / np.maximum(angles, 1e-12))
    straight = lengths > 1e-9
    acceleration = np.where(straight, cartesian_limits.acceleration / np.maximum(lengths, 1e-12), speed * 4.0)
    jerk = np.where(straight, cartesian_limits.jerk / np.maximum(lengths, 1e-12), speed * 40.0)
    return np.column_stack([speed, acceleration, jerk])


# Samples solved in one pass of timed_cartesian_paths: bounds the memory of a long request, and how long it goes
# without looking whether it was interrupted.
_SAMPLES_PER_PASS = 20000


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
    return timed_cartesian_paths(q_start, lambda _, s: poses_at(s), [length], [angle], limits, cartesian_limits,
                                 period, tool_offset, max_joint_step)


def timed_cartesian_paths(q_start: Sequence[float], poses_at: Callable[[np.ndarray, np.ndarray], np.ndarray],
                          lengths: Sequence[float], angles: Sequence[float] | None = None,
                          limits: JointLimits = UR5E_LIMITS, cartesian_limits: CartesianLimits = CartesianLimits(),
                          period: float = DEFAULT_PERIOD, tool_offset: float = DEFAULT_TOOL_OFFSET,
                          max_joint_step: float = 0.1,
                          check_interrupted: Callable[[], None] = lambda: None) -> JointTrajectory:
    """One trajectory through several Cartesian paths one after the other, each from where the previous one ends
    (the first from `q_start`), each as `timed_cartesian_path` times it: from rest to rest, slowed down on its own
    until the joints respect `limits`. No paths: at rest at `q_start`.

    `poses_at(path, s)` gives the TCP poses (N, 4, 4) of paths `path` (N, indices) at their path parameters s (N,)
    in [0, 1]; path k at s = 0 is where path k - 1 ends. `lengths` [m] and `angles` [rad] (none: 0) are each path's
    length and total turn. The paths are solved together, some ten thousand samples per NumPy pass, so that
    thousands of short paths take a time linear in their samples; `check_interrupted` is called before each pass
    (it raises to abandon the work).
    """
    lengths = np.asarray(lengths, dtype=float)
    angles = np.zeros_like(lengths) if angles is None else np.asarray(angles, dtype=float)
    check_interrupted()
    profiles = _PathParameterProfiles(_path_parameter_limits(lengths, angles, cartesian_limits), period)
    q = np.asarray(q_start, dtype=float)
    parts = [_at_rest(q)]
    first = 0
    while first < len(lengths):
        check_interrupted()
        # Paths up to some ten thousand samples (at least one path).
        last = first + max(1, int(np.searchsorted(np.cumsum(profiles.samples[first:]), _SAMPLES_PER_PASS)))
        trajectory, starts, ratios = _solve_timed(q, poses_at, profiles, first, last, limits, tool_offset,
                                                  max_joint_step)
        taken = 0  # paths of the pass taken so far
        for index in np.flatnonzero(ratios > 1.0).tolist():
            parts.append(_rows(trajectory, starts[taken], starts[index]))
            slowed = _slowed(parts[-1].end, poses_at, first + index, profiles.limits[first + index],
                             float(ratios[index]), period, limits, tool_offset, max_joint_step, check_interrupted)
            parts.append(slowed)
            taken = index + 1
            if not np.array_equal(slowed.end, trajectory.positions[starts[index + 1]]):
                break  # it ended elsewhere than the pass assumed: the rest is solved again from there
        else:
            parts.append(_rows(trajectory, starts[taken], starts[-1]))
            taken = last - first
        first += taken
        q = parts[-1].end
    return concatenate(parts)


def _slowed(q_start: np.ndarray, poses_at: Callable[[np.ndarray, np.ndarray], np.ndarray], path: int,
            path_limits: np.ndarray, ratio: float, period: float, limits: JointLimits, tool_offset: float,
            max_joint_step: float, check_interrupted: Callable[[], None]) -> JointTrajectory:
    """A path too fast for a joint (near a singularity) slowed down as a whole and timed again until it is not."""
    speed, acceleration, jerk = path_limits
    for _ in range(19):
        check_interrupted()
        slow_down = 0.9 / ratio
        speed, acceleration, jerk = speed * slow_down, acceleration * slow_down ** 2, jerk * slow_down ** 3
        profile = _PathParameterProfiles(np.array([speed, acceleration, jerk]), period)
        trajectory, _, ratios = _solve_timed(q_start, lambda _, s: poses_at(np.full(len(s), path), s), profile, 0,
                                             1, limits, tool_offset, max_joint_step)
        ratio = float(ratios[0])
        if ratio <= 1.0:
            return trajectory
    raise TrajectoryError('the path cannot be made slow enough for the joint limits (singularity?)')


def _rows(trajectory: JointTrajectory, first: int, last: int) -> JointTrajectory:
    """Samples first to last (included) of a trajectory, as a trajectory starting at time 0."""
    rows = slice(first, last + 1)
    return JointTrajectory(trajectory.times[rows] - trajectory.times[first], trajectory.positions[rows],
                           trajectory.velocities[rows], trajectory.accelerations[rows])


def _solve_timed(q_start: np.ndarray, poses_at: Callable[[np.ndarray, np.ndarray], np.ndarray],
                 profiles: _PathParameterProfiles, first: int, last: int, limits: JointLimits, tool_offset: float,
                 max_joint_step: float) -> tuple[JointTrajectory, np.ndarray, np.ndarray]:
    """Paths first to last (excluded) at their profiles' samples, solved by IK one after the other (the first
    from `q_start`): the trajectory through them all, the sample where each path starts (and, last, where the last
    one ends), and the ratio of each path's fastest joint to the limits (above 1: too fast)."""
    times, s, path, starts = profiles.sampled(first, last)
    poses = poses_at(path[1:], s[1:])  # the first sample is where the arm is
    solutions, unreachable = inverse_kinematics_path(poses, q_start, tool_offset)
    # Joint first (6, N) from here on: each joint's samples contiguous, reductions over joints fast.
    positions = np.concatenate([q_start[:, None], solutions.T], axis=1)
    steps = np.max(np.abs(np.diff(positions, axis=1)), axis=0)
    if np.any(steps > max_joint_step):
        jump = int(np.argmax(steps > max_joint_step))
        raise TrajectoryError(
            f'the path would flip the arm configuration at {np.round(poses[jump, :3, 3], 3).tolist()} '
            f'(a joint jumps by {steps[jump]:.2f} rad between samples)')
    if unreachable is not None:
        raise unreachable
    derivative = _finite_difference(times, starts)  # every path starts and ends at rest
    velocities = derivative(positions)
    accelerations = derivative(velocities)
    ratio = np.maximum(np.max(np.abs(velocities) / limits.velocity[:, None], axis=0),
                       np.sqrt(np.max(np.abs(accelerations) / limits.acceleration[:, None], axis=0)))
    return (JointTrajectory(times, positions.T, velocities.T, accelerations.T), starts,
            np.maximum.reduceat(ratio, starts[:-1]))


def trajectory_tcp_positions(trajectory: JointTrajectory, tool_offset: float = DEFAULT_TOOL_OFFSET) -> np.ndarray:
    """TCP positions (N, 3) along a trajectory, e.g. to check it stays above the table."""
    return np.array([forward_kinematics(q, tool_offset)[:3, 3] for q in trajectory.positions])


__all__ = [
    'CartesianLimits', 'DEFAULT_PERIOD', 'JointLimits', 'JointTrajectory', 'TrajectoryError',
    'UR5E_LIMITS', 'cartesian_line', 'concatenate', 'time_joint_path', 'timed_cartesian_path',
    'timed_cartesian_paths', 'trajectory_tcp_positions',
]
