"""Carrying out a Navigate request over a port to the mobile base (plain Python, no ROS).

`NavigationExecutor.run` resolves the goal (a named location of the kitchen: its approach pose; or a pose), plans a
path on the occupancy grid of the kitchen's furniture inflated by the base (cap_control.navigation.plan), drives it
with the path follower on an ideal base to time it, and sends the base's joints that timed trajectory. The base's
controller follows it within a path tolerance: a base held back by something the map does not have (pushed against
an obstacle) strays beyond it, the controller stops the base, and the executor marks the spot ahead of the base as
blocked and plans again from where the base is (a recovery), up to `max_recoveries` times. Feedback every
`feedback_period` while the base drives: its pose, the distance left along the path and the time left. A cancel
or a stop cancels the base's trajectory at once: the base brakes and holds where it is.
"""
from __future__ import annotations

import abc
import dataclasses
import math
import time
from concurrent.futures import Future
from typing import Callable

import numpy as np
from cap_mobile import layout
from cap_ros_common.parameters import parameter

from cap_control.navigation.plan import (
    FollowerLimits, NavigateErrorCode, NavigationError, OccupancyGrid, PathFollower, base_trajectory,
    follow_on_ideal_base, plan_path, wrap_angle,
)
from cap_control.ports import (
    ArmOutcome, ArmResult, Ending, Failed, GoalRun, Interrupted, Interruption, PendingGoal, WaitTimeouts,
)

FOLLOWER_PERIOD = 0.01  # [s] of the ideal base the follower drives to time the trajectory
POINT_PERIOD = 0.1  # [s] between the points sent to the base's controller


@dataclasses.dataclass(frozen=True)
class NavigationConfig:
    """The navigation node's parameters (the kitchen's facts are their defaults)."""

    resolution: float = parameter(0.05, 'Cell size of the occupancy grid [m].')
    margin: float = parameter(layout.NAVIGATION_MARGIN, 'Clearance kept beyond the base\'s radius [m].')
    max_speed: float = parameter(layout.BASE_MAX_SPEED, 'Highest forward speed [m/s].')
    max_acceleration: float = parameter(layout.BASE_MAX_ACCELERATION, 'Highest forward acceleration [m/s^2].')
    max_yaw_rate: float = parameter(layout.BASE_MAX_YAW_RATE, 'Highest turning rate [rad/s].')
    max_yaw_acceleration: float = parameter(layout.BASE_MAX_YAW_ACCELERATION, 'Highest turning acceleration '
                                            '[rad/s^2].')
    look_ahead: float = parameter(0.4, 'Pure pursuit\'s look-ahead distance [m].')
    position_tolerance: float = parameter(0.05, 'Goal position tolerance [m] (nav2\'s default: 0.25).')
    yaw_tolerance: float = parameter(0.05, 'Goal heading tolerance [rad] (nav2\'s default: 0.25).')
    path_tolerance: float = parameter(0.15, 'Tracking error of the base beyond which it counts as blocked [m or '
                                      'rad].')
    max_recoveries: int = parameter(3, 'Plans made again after the base was blocked, before the goal fails.')
    blocked_radius: float = parameter(0.2, 'Radius of the spot ahead of a blocked base marked as an obstacle [m].')
    service_timeout: float = parameter(5.0, 'Longest wait for the base to accept a goal or a cancel [s].')
    server_timeout: float = parameter(10.0, 'Longest wait for the base\'s action server and joint state [s].')
    motion_timeout_margin: float = parameter(60.0, 'Wall time allowed beyond a drive\'s planned duration before '
                                             'TIMEOUT [s].')
    feedback_period: float = parameter(0.2, 'Wall time between feedback messages [s].')

    def limits(self) -> FollowerLimits:
        """The follower's limits. Its drive, timed on an ideal base, ends within half the goal tolerances: at the full
        tolerance it could end on their edge, and the real base's few milliradians of tracking error fail the goal."""
        return FollowerLimits(self.max_speed, self.max_acceleration, self.max_yaw_rate, self.max_yaw_acceleration,
                              self.look_ahead, self.position_tolerance / 2, self.yaw_tolerance / 2)

    def grid(self) -> OccupancyGrid:
        """The kitchen's furniture on a grid, inflated so that the base's centre may stand on every free cell."""
        return OccupancyGrid.from_boxes(layout.obstacle_footprints(), layout.ROOM_X_RANGE, layout.ROOM_Y_RANGE,
                                        self.resolution).inflated(layout.BASE_RADIUS + self.margin)


class Base(abc.ABC):
    server_description = 'the mobile base\'s controller'

    @abc.abstractmethod
    def server_ready(self) -> Future:
        """Completes once the base's trajectory server can take goals; cancelled when the executor stops waiting."""

    @abc.abstractmethod
    def pose(self) -> Future:
        """Completes with the base's (x, y, yaw) joints (np.ndarray; yaw counts whole turns) once known."""

    @abc.abstractmethod
    def latest_pose(self) -> np.ndarray | None:
        """The base's joints in the latest joint state, None if unknown (for feedback)."""

    @abc.abstractmethod
    def follow(self, times: np.ndarray, positions: np.ndarray, velocities: np.ndarray,
               path_tolerance: float) -> PendingGoal:
        """Send a timed trajectory of (x, y, yaw); a tracking error above `path_tolerance` stops the base and the goal
        ends ArmResult.TOLERANCE_VIOLATED."""


@dataclasses.dataclass(frozen=True)
class NavigateRequest:
    location_name: str = ''  # a named location of the kitchen; empty: the pose (or the poses)
    pose: tuple[float, float, float] = (0.0, 0.0, 0.0)  # x, y [m], yaw [rad] in the map (world) frame
    poses: tuple[tuple[float, float, float], ...] = ()  # through these in order, instead of one goal


@dataclasses.dataclass(frozen=True)
class NavigateProgress:
    pose: np.ndarray  # (x, y, yaw) now
    elapsed: float  # [s] wall time since the goal began
    time_remaining: float  # [s] of the trajectory, simulated
    distance_remaining: float  # [m] along the path to the pose being driven to
    recoveries: int
    poses_remaining: int = 0  # after the one being driven to


@dataclasses.dataclass(frozen=True)
class NavigateOutcome:
    ending: Ending
    code: NavigateErrorCode
    message: str = ''
    pose: np.ndarray | None = None  # where the base ended
    recoveries: int = 0
    halt_confirmed: bool = True
    path: np.ndarray | None = None  # the last path planned (N, 2)


@dataclasses.dataclass
class _Trip:
    """What one request's drives share: its start, its recoveries, the poses left, the last path planned."""

    started: float  # [s] monotonic
    recoveries: int = 0
    poses_remaining: int = 0
    path: np.ndarray | None = None


class NavigationExecutor:
    def __init__(self, base: Base, config: NavigationConfig = NavigationConfig(),
                 log: Callable[[str, str], None] = lambda level, message: None) -> None:
        self.base = base
        self.config = config
        self.log = log
        self.static_grid = config.grid()

    def goal_poses(self, request: NavigateRequest) -> list[tuple[float, float, float]]:
        """The poses a request names, in order; NavigationError UNKNOWN_LOCATION for a location the kitchen lacks,
        UNREACHABLE for a pose that is not finite."""
        if request.location_name.strip():
            try:
                return [layout.location(request.location_name).approach()]
            except layout.UnknownLocationError as error:
                raise NavigationError(NavigateErrorCode.UNKNOWN_LOCATION, str(error)) from None
        poses = list(request.poses) if request.poses else [request.pose]
        for x, y, yaw in poses:
            if not all(math.isfinite(v) for v in (x, y, yaw)):
                raise NavigationError(NavigateErrorCode.UNREACHABLE, 'a goal pose has values that are not finite')
        return [(float(x), float(y), float(yaw)) for x, y, yaw in poses]

    def run(self, request: NavigateRequest, interruption: Interruption,
            feedback: Callable[[NavigateProgress], None] = lambda progress: None) -> NavigateOutcome:
        config = self.config
        run = GoalRun(interruption, WaitTimeouts(config.service_timeout, config.server_timeout),
                      NavigateErrorCode.TIMEOUT, NavigateErrorCode.UNKNOWN)
        trip = _Trip(time.monotonic())
        try:
            goals = self.goal_poses(request)
            # Every pose is checked before the base moves: a tour with one pose in furniture is refused whole.
            for goal in goals:
                if not self.static_grid.is_free(goal[:2]):
                    raise NavigationError(NavigateErrorCode.UNREACHABLE,
                                          f'the goal ({goal[0]:.2f}, {goal[1]:.2f}) is inside an obstacle or closer '
                                          f'to one than the base allows')
            run.available(self.base.server_ready(), self.base.server_description)
            messages = []
            for index, goal in enumerate(goals):
                trip.poses_remaining = len(goals) - index - 1
                messages.append(self._reach(run, goal, trip, feedback))
            pose = run.answer(self.base.pose(), config.server_timeout, 'the base\'s joint state')
            message = messages[0] if len(messages) == 1 else f'reached all {len(goals)} poses; the last {messages[-1]}'
            return NavigateOutcome(Ending.SUCCEEDED, NavigateErrorCode.NONE, message, pose, trip.recoveries,
                                   path=trip.path)
        except Interrupted:
            confirmed = run.cancel_active_goal()
            ending = interruption.reason or Ending.CANCELLED
            return NavigateOutcome(ending, NavigateErrorCode.CANCELLED, f'{ending.value}: the base holds where it '
                                   'stopped', self.base.latest_pose(), trip.recoveries, confirmed, trip.path)
        except NavigationError as error:
            return NavigateOutcome(Ending.FAILED, error.code, str(error), self.base.latest_pose(), trip.recoveries,
                                   path=trip.path)
        except Failed as failure:
            run.cancel_active_goal()
            return NavigateOutcome(Ending.FAILED, failure.code, failure.message, self.base.latest_pose(),
                                   trip.recoveries, path=trip.path)
        except Exception as error:  # noqa: BLE001 - whatever went wrong, the base stops and the goal says so
            run.cancel_active_goal()
            return NavigateOutcome(Ending.FAILED, NavigateErrorCode.UNKNOWN, f'navigation failed: {error!r}',
                                   self.base.latest_pose(), trip.recoveries, path=trip.path)

    def _reach(self, run: GoalRun, goal: tuple[float, float, float], trip: '_Trip',
               feedback: Callable[[NavigateProgress], None]) -> str:
        """Drive to one goal pose, planning again around blocked spots; the message of its arrival."""
        config = self.config
        grid = self.static_grid
        recoveries_here = 0
        while True:
            pose = run.answer(self.base.pose(), config.server_timeout, 'the base\'s joint state')
            trip.path = path = plan_path(grid, pose, goal)
            follower = PathFollower(path, goal[2], config.limits())
            poses, commands = follow_on_ideal_base(follower, (pose[0], pose[1], wrap_angle(pose[2])),
                                                   FOLLOWER_PERIOD)
            if not commands or not commands[-1].done:
                raise NavigationError(NavigateErrorCode.UNREACHABLE, 'the path follower did not reach the goal')
            times, positions, velocities = base_trajectory(poses, commands, FOLLOWER_PERIOD, float(pose[2]),
                                                           POINT_PERIOD)
            self.log('info', f'driving {len(path) - 1} leg(s) to ({goal[0]:.2f}, {goal[1]:.2f}, {goal[2]:.2f}) in '
                             f'{times[-1]:.1f} s')
            outcome = self._drive(run, times, positions, velocities, poses, trip, feedback)
            if outcome.result == ArmResult.SUCCEEDED:
                break
            if outcome.result != ArmResult.TOLERANCE_VIOLATED:
                raise Failed(NavigateErrorCode.UNKNOWN, f'the base failed: {outcome.message}')
            if recoveries_here >= config.max_recoveries:
                raise NavigationError(NavigateErrorCode.UNREACHABLE,
                                      f'the base was blocked {recoveries_here + 1} times on the way')
            recoveries_here += 1
            trip.recoveries += 1
            pose = run.answer(self.base.pose(), config.server_timeout, 'the base\'s joint state')
            grid = self._mark_blocked(grid, pose)
            self.log('warn', f'the base was blocked at ({pose[0]:.2f}, {pose[1]:.2f}) ({outcome.message}); '
                             f'planning again (recovery {trip.recoveries})')
        pose = run.answer(self.base.pose(), config.server_timeout, 'the base\'s joint state')
        error = math.dist(pose[:2], goal[:2])
        yaw_error = abs(wrap_angle(pose[2] - goal[2]))
        if error > config.position_tolerance or yaw_error > config.yaw_tolerance:
            raise Failed(NavigateErrorCode.UNKNOWN, f'the base stopped {error:.3f} m and {yaw_error:.3f} rad from '
                                                    f'the goal')
        return (f'reached ({goal[0]:.2f}, {goal[1]:.2f}, {goal[2]:.2f}) within {error:.3f} m and {yaw_error:.3f} '
                f'rad')

    def _drive(self, run: GoalRun, times: np.ndarray, positions: np.ndarray, velocities: np.ndarray,
               poses: np.ndarray, trip: '_Trip', feedback: Callable[[NavigateProgress], None]) -> ArmOutcome:
        """Send one trajectory and wait for its end, sending feedback meanwhile."""
        config = self.config
        goal = self.base.follow(times, positions, velocities, config.path_tolerance)
        run.send(goal, self.base.server_description, 'the base refused the trajectory')
        # How far along the drive each point is, to tell the distance left from the nearest point.
        travelled = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(poses[:, :2], axis=0), axis=1))])
        deadline = time.monotonic() + times[-1] + config.motion_timeout_margin
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                raise Failed(NavigateErrorCode.TIMEOUT, f'the base did not arrive within {times[-1]:.0f} s and '
                                                        f'{config.motion_timeout_margin:.0f} s more')
            try:
                outcome = run.wait(goal.result, min(config.feedback_period, left), 'the feedback period passed')
                run.active = None
                return outcome
            except Failed:  # no result within the feedback period: report, and wait on
                pass
            now = self.base.latest_pose()
            if now is not None:
                nearest = int(np.argmin(np.sum((poses[:, :2] - now[:2]) ** 2, axis=1)))
                elapsed = nearest * FOLLOWER_PERIOD
                feedback(NavigateProgress(now, time.monotonic() - trip.started, max(0.0, float(times[-1]) - elapsed),
                                          float(travelled[-1] - travelled[nearest]), trip.recoveries,
                                          trip.poses_remaining))

    def _mark_blocked(self, grid: OccupancyGrid, pose: np.ndarray) -> OccupancyGrid:
        """The grid with a disc ahead of the base (where it was pushing against something) occupied, inflated."""
        config = self.config
        ahead = layout.BASE_RADIUS + config.blocked_radius
        centre = (pose[0] + ahead * math.cos(pose[2]), pose[1] + ahead * math.sin(pose[2]))
        obstacle = OccupancyGrid.from_boxes([], layout.ROOM_X_RANGE, layout.ROOM_Y_RANGE, config.resolution)
        rows, columns = np.indices(obstacle.occupied.shape)
        xs = obstacle.origin[0] + (columns + 0.5) * config.resolution
        ys = obstacle.origin[1] + (rows + 0.5) * config.resolution
        disc = (xs - centre[0]) ** 2 + (ys - centre[1]) ** 2 <= config.blocked_radius ** 2
        inflated = dataclasses.replace(obstacle, occupied=disc).inflated(layout.BASE_RADIUS + config.margin)
        return dataclasses.replace(grid, occupied=grid.occupied | inflated.occupied)


__all__ = ['Base', 'NavigateOutcome', 'NavigateProgress', 'NavigateRequest', 'NavigationConfig',
           'NavigationExecutor']
