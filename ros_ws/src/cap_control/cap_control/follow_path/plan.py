"""Planning a tool's path over a work surface: strokes of a marker, wipes of an eraser, or moves above the surface.

A request is a list of strokes, each a polyline of (x, y) points on the surface [m, world frame]. Each stroke is one
continuous contact: the tool travels above its first point, descends onto the surface (pressing its sprung tip in
by the tool's press depth), follows the polyline, and lifts. With no tool (TOOL_NONE) the strokes are followed at
travel height without touching.

Everything is planned before the arm moves (`plan_path`), so a bad request fails with nothing moved:
- points off the surface (less than `margin` inside its edges), not finite, or too many: INVALID_PATH or
  OUTSIDE_WORKSPACE, naming the first offending point and the allowed range;
- a point the arm cannot reach with the tool pointing at the surface: IK_FAILED, with the fraction of the path (by
  length) that could be solved, as MoveIt's Cartesian planning reports it (`fraction`; the path is run only at 1.0).

Timing. A stroke is resampled every `step` metres and cut where it turns by more than `corner_angle`: each smooth
piece is timed along its length by Ruckig (jerk-limited, from rest to rest, at the requested tool speed), so a
polygon's corners are sharp (the tool stops at each) and a circle is drawn in one sweep. Every sample is solved by
IK seeded with the previous one (no branch flips: a joint jump above `max_joint_step` fails the plan), and a piece
that would need a joint faster than the UR5e's limits is slowed down as a whole. No ROS here.

Cost. Planning takes a time linear in the samples (the path's length over `step`, and its duration over the
trajectory's period): they are solved in NumPy passes of twenty thousand (cap_control.kinematics.
inverse_kinematics_path, cap_control.trajectory.timed_cartesian_paths), some 0.05 s per 100,000 samples: 5,000
points all over the board (hours of drawing) in about half a second, 1.2 s for the longest path 5,000 points make
(corner to far corner and back). Between passes the plan calls `check_interrupted`, so that a cancel or a stop ends
it within a few hundredths of a second.
"""
from __future__ import annotations

import dataclasses
import enum
import math
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
from cap_ros_common.parameters import parameter
from cap_whiteboard import board, tool as tools

from cap_control.kinematics import (
    HOME_JOINTS, IKError, forward_kinematics, inverse_kinematics, inverse_kinematics_path, top_down_pose,
)
from cap_control.trajectory import (
    CartesianLimits, JointLimits, JointTrajectory, TrajectoryError, UR5E_LIMITS, cartesian_line,
    time_joint_path, timed_cartesian_paths,
)

TOOL_NONE = 'none'
TOOL_MARKER = tools.TOOL_MARKER
TOOL_ERASER = tools.TOOL_ERASER
TOOLS = (TOOL_NONE, TOOL_MARKER, TOOL_ERASER)

# The seed of every stroke's first pose: UR's ready pose over the table (elbow up, wrist down). Seeded with the arm's
# current joints instead, the nearest branch may be elbow-down, which sweeps the elbow into the table.
READY_JOINTS = HOME_JOINTS
MAX_STROKES = 200
MAX_POINTS = 20000  # over every stroke, as given


class PathErrorCode(enum.IntEnum):
    """The FollowPath action's error codes (cap_interfaces/action/FollowPath.action)."""

    NONE = 0
    UNKNOWN = 1
    INVALID_PATH = 2
    OUTSIDE_WORKSPACE = 3
    IK_FAILED = 4
    CANCELLED = 5
    CONTACT_LOST = 6
    TIMEOUT = 7
    CONTROLLER_FAILED = 8


class PathError(Exception):
    """A path that cannot be followed; nothing has moved. `fraction`: the part of the path (by length) solved."""

    def __init__(self, code: PathErrorCode, message: str, fraction: float = 0.0):
        super().__init__(message)
        self.code = code
        self.message = message
        self.fraction = fraction


@dataclass(frozen=True)
class Surface:
    """The work surface: a horizontal rectangle [m, world frame] (the whiteboard by default)."""

    x_min: float = parameter(board.X_RANGE[0], 'Left edge of the work surface [m].')
    x_max: float = parameter(board.X_RANGE[1], 'Right edge of the work surface [m].')
    y_min: float = parameter(board.Y_RANGE[0], 'Bottom edge of the work surface [m].')
    y_max: float = parameter(board.Y_RANGE[1], 'Top edge of the work surface [m].')
    z: float = parameter(board.SURFACE_Z, 'Height of the work surface [m].')
    margin: float = parameter(board.DRAW_MARGIN, 'Path points must keep this far inside the edges [m].')

    def contains(self, x: float, y: float) -> bool:
        return bool(self.contains_all(np.array([[x, y]]))[0])

    def contains_all(self, points: np.ndarray) -> np.ndarray:
        """Whether each point (N, 2) lies on the surface, `margin` inside its edges."""
        slack = 1e-9  # a point computed exactly on the limit (-0.64 - 0.05) is on it
        x, y = points[:, 0], points[:, 1]
        return ((self.x_min + self.margin - slack <= x) & (x <= self.x_max - self.margin + slack)
                & (self.y_min + self.margin - slack <= y) & (y <= self.y_max - self.margin + slack))

    def describe(self) -> str:
        return (f'x in [{self.x_min + self.margin:.3f}, {self.x_max - self.margin:.3f}] m, '
                f'y in [{self.y_min + self.margin:.3f}, {self.y_max - self.margin:.3f}] m')


@dataclass(frozen=True)
class PathConfig:
    """How paths are followed: parameters of the follow_path node (defaults here, the one home of them)."""

    surface: Surface = Surface()
    speed: float = parameter(0.1, 'Tool speed along a stroke when the goal asks for none [m/s].')
    max_speed: float = parameter(0.25, 'Fastest tool speed a goal may ask for along a stroke [m/s].')
    acceleration: float = parameter(0.5, 'Tool acceleration along a stroke [m/s^2].')
    jerk: float = parameter(5.0, 'Tool jerk along a stroke [m/s^3].')
    step: float = parameter(0.002, 'Strokes are resampled this often along their length [m].')
    corner_angle: float = parameter(math.radians(25.0), 'A stroke turning more than this at a point stops there '
                                    '(a sharp corner) [rad].')
    travel_height: float = parameter(0.09, 'Height of the tool tip above the surface between strokes [m]; clears '
                                     'the objects standing on it.')
    descent_speed: float = parameter(0.05, 'Tool speed while landing on and lifting off the surface [m/s].')
    travel_speed: float = parameter(0.25, 'Tool speed between strokes [m/s].')
    max_joint_step: float = parameter(0.1, 'Largest joint change between two samples of a path [rad]; more means '
                                      'the IK branch would flip.')
    park_joints: tuple[float, ...] = parameter((0.8413, -2.2842, 1.7017, -0.9883, -1.5708, -0.7295),
                                               'Where the arm waits after a path, out of the cameras\' view of '
                                               'the surface [rad]; empty: stay above the last point.')
    joint_limits: JointLimits = dataclasses.field(default=UR5E_LIMITS, metadata={'description': ''})

    def validate(self) -> None:
        for name in ('speed', 'max_speed', 'acceleration', 'jerk', 'step', 'travel_height', 'descent_speed',
                     'travel_speed', 'max_joint_step'):
            if not getattr(self, name) > 0:
                raise ValueError(f'{name} must be positive, not {getattr(self, name)}')
        if self.park_joints and len(self.park_joints) != 6:
            raise ValueError(f'park_joints needs 6 joint angles or none, not {len(self.park_joints)}')


class StepKind(enum.Enum):
    TRAVEL = 'travel'  # above the surface, to the next stroke
    DESCEND = 'descend'  # onto the surface
    FOLLOW = 'follow'  # along a stroke (in contact, unless the tool is TOOL_NONE)
    LIFT = 'lift'  # off the surface
    PARK = 'park'  # out of the way, after the last stroke


@dataclass(frozen=True)
class PathStep:
    """One timed motion of a plan. `points_before`: path points done before it; `points`: how many it covers."""

    kind: StepKind
    trajectory: JointTrajectory
    stroke: int
    points_before: int
    points: int
    length_before: float  # [m] of stroke length done before it
    length: float  # [m] of stroke length it covers


@dataclass(frozen=True)
class PathPlan:
    tool: str
    steps: list[PathStep]
    points_total: int
    length_total: float  # [m] summed over the strokes
    fraction: float = 1.0

    @property
    def duration(self) -> float:
        return float(sum(step.trajectory.duration for step in self.steps))


# ----------------------------------------------------------------------------------------------- geometry
def _flange_to_tool(tool: str) -> np.ndarray:
    """flange_T_tool of `tool`; with TOOL_NONE the marker's tip is the point that follows the path."""
    return tools.flange_to_tool(TOOL_ERASER if tool == TOOL_ERASER else TOOL_MARKER)


def flange_pose(tool: str, xyz: Sequence[float], yaw: float) -> np.ndarray:
    """World pose of the flange that puts `tool`'s touching point at `xyz`, pointing down, turned by `yaw`."""
    return top_down_pose(xyz, yaw) @ np.linalg.inv(_flange_to_tool(tool))


def choose_yaw(tool: str, points: np.ndarray, z: float) -> float:
    """The tool's yaw for a whole request: of eight yaws, the one whose joint solutions at the path's centre and
    extremes lie nearest the UR5e's ready pose (elbow up, wrist down over the table), so every stroke starts on
    that branch and turns the wrist least. The marker is round, and the eraser's pad (3 x 6 cm) covers a 3 mm line
    whichever way it is turned; reachability decides."""
    probes = np.vstack([np.mean(points, axis=0), points[np.argmin(points[:, 0])], points[np.argmax(points[:, 0])],
                        points[np.argmin(points[:, 1])], points[np.argmax(points[:, 1])]])
    best = None
    for yaw in np.linspace(-math.pi, math.pi, 8, endpoint=False):
        try:
            cost = sum(float(np.sum((inverse_kinematics(flange_pose(tool, (x, y, z), float(yaw)), READY_JOINTS,
                                                        tool_offset=0.0) - READY_JOINTS) ** 2))
                       for x, y in probes)
        except IKError:
            continue
        if best is None or cost < best[0]:
            best = (cost, float(yaw))
    return 0.0 if best is None else best[1]


def resample(points: np.ndarray, step: float) -> np.ndarray:
    """The polyline through `points` (N, 2) with points every `step` or less along it, every vertex kept."""
    starts, ends = points[:-1], points[1:]
    counts = np.maximum(1, np.ceil(np.linalg.norm(ends - starts, axis=1) / step)).astype(int)
    segment = np.repeat(np.arange(len(counts)), counts)
    # 1, 2, ..., count within each segment: the fraction of the way along it is that over count.
    index = np.arange(len(segment)) - np.repeat(np.cumsum(counts) - counts, counts) + 1
    fractions = index / counts[segment]
    return np.vstack([points[:1], starts[segment] + fractions[:, None] * (ends[segment] - starts[segment])])


def polyline_length(points: np.ndarray) -> float:
    return float(np.sum(np.linalg.norm(np.diff(points, axis=0), axis=1))) if len(points) > 1 else 0.0


def split_at_corners(points: np.ndarray, corner_angle: float) -> list[np.ndarray]:
    """Pieces of the polyline (each sharing its end point with the next) cut where it turns by more than
    `corner_angle`; repeated points are dropped first."""
    points, cuts = corners(points, corner_angle)
    if len(points) < 3:
        return [points]
    return [points[start:end + 1] for start, end in zip(cuts[:-1], cuts[1:])]


def corners(points: np.ndarray, corner_angle: float) -> tuple[np.ndarray, np.ndarray]:
    """The polyline without repeated points, and the indices where its pieces begin and end: its ends and where
    it turns by more than `corner_angle` (see split_at_corners)."""
    keep = np.concatenate([[True], np.linalg.norm(np.diff(points, axis=0), axis=1) > 1e-9])
    points = points[keep]
    if len(points) < 3:
        return points, np.array([0, len(points) - 1])
    a, b = points[1:-1] - points[:-2], points[2:] - points[1:-1]
    cos = np.sum(a * b, axis=1) / (np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1))
    turns = np.flatnonzero(np.arccos(np.clip(cos, -1.0, 1.0)) > corner_angle) + 1
    return points, np.concatenate([[0], turns, [len(points) - 1]])


# ----------------------------------------------------------------------------------------------- checks
def check_strokes(strokes: Sequence[np.ndarray], surface: Surface) -> list[np.ndarray]:
    """The strokes as (N, 2) float arrays, or PathError(INVALID_PATH / OUTSIDE_WORKSPACE) naming the problem."""
    if not strokes:
        raise PathError(PathErrorCode.INVALID_PATH, 'the path has no points')
    if len(strokes) > MAX_STROKES:
        raise PathError(PathErrorCode.INVALID_PATH, f'the path has {len(strokes)} strokes; at most {MAX_STROKES}')
    checked, total = [], 0
    for index, stroke in enumerate(strokes):
        points = np.asarray(stroke, dtype=float)
        if points.ndim != 2 or points.shape[1] < 2 or len(points) == 0:
            raise PathError(PathErrorCode.INVALID_PATH, f'stroke {index} has no points (x, y)')
        points = points[:, :2]
        total += len(points)
        if total > MAX_POINTS:
            raise PathError(PathErrorCode.INVALID_PATH, f'the path has more than {MAX_POINTS} points')
        if not np.all(np.isfinite(points)):
            raise PathError(PathErrorCode.INVALID_PATH, f'stroke {index} has a point that is not a finite number')
        inside = surface.contains_all(points)
        if not np.all(inside):
            point = points[int(np.argmin(inside))]
            raise PathError(PathErrorCode.OUTSIDE_WORKSPACE,
                            f'the point ({point[0]:.3f}, {point[1]:.3f}) of stroke {index} is off the board: '
                            f'points must lie within {surface.describe()}')
        checked.append(points)
    return checked


def flange_poses(tool: str, points: np.ndarray, z: float, yaw: float) -> np.ndarray:
    """`flange_pose` at each point (N, 2) at height z: (N, 4, 4)."""
    poses = np.repeat(flange_pose(tool, (0.0, 0.0, z), yaw)[None], len(points), axis=0)
    poses[:, :2, 3] += points
    return poses


# Samples of a stroke solved in one pass, between looks at whether the request was interrupted.
SAMPLES_PER_PASS = 20000


def _reach(tool: str, stroke: np.ndarray, z: float, yaw: float, q_seed: np.ndarray, config: PathConfig,
           check_interrupted: Callable[[], None]) -> tuple[np.ndarray, tuple[np.ndarray, float] | None]:
    """IK along the stroke resampled every `config.step` at height z, seeded sample to sample (the first with
    `q_seed`), some ten thousand samples at a time: (the last solution, None), or (the solution before, (the first
    sample that fails, the stroke's length up to the sample before it)). A sample fails where it cannot be reached
    or a joint jumps more than `max_joint_step` from the sample before (the first may be any distance from the
    seed)."""
    counts = np.maximum(1, np.ceil(np.linalg.norm(np.diff(stroke, axis=0), axis=1) / config.step)).astype(int)
    groups, first, size = [], 0, 0  # runs of segments with some SAMPLES_PER_PASS samples
    for segment, count in enumerate(counts.tolist()):
        size += count
        if size >= SAMPLES_PER_PASS:
            groups.append((first, segment + 1))
            first, size = segment + 1, 0
    if first < len(counts) or not groups:
        groups.append((first, len(counts)))
    q, solved_length = np.asarray(q_seed, dtype=float), 0.0
    for number, (first, last) in enumerate(groups):
        check_interrupted()
        samples = resample(stroke[first:last + 1], config.step)
        done = 0 if number == 0 else 1  # a later run's first sample is the run before's last
        solutions, _ = inverse_kinematics_path(flange_poses(tool, samples[done:], z, yaw), q, tool_offset=0.0)
        steps = np.max(np.abs(np.diff(np.concatenate([q[:, None], solutions.T], axis=1), axis=1)), axis=0)
        if number == 0 and len(steps):
            steps[0] = 0.0
        jumps = np.flatnonzero(steps > config.max_joint_step)
        reached = int(jumps[0]) if len(jumps) else len(solutions)
        if reached:
            q = solutions[reached - 1]
        if done + reached < len(samples):
            return q, (samples[done + reached], solved_length + polyline_length(samples[:done + reached]))
        solved_length += polyline_length(samples)
    return q, None


# ----------------------------------------------------------------------------------------------- plan
def plan_path(q_start: Sequence[float], strokes: Sequence[np.ndarray], tool: str, speed: float = 0.0,
              config: PathConfig = PathConfig(), check_interrupted: Callable[[], None] = lambda: None) -> PathPlan:
    """Every motion of the request, timed, from joint positions `q_start`; PathError if it cannot be followed.

    Planning takes a time linear in the path's samples (see the module's docstring); `check_interrupted` is called
    between passes of twenty thousand samples and may raise to abandon the plan (a cancel or a stop)."""
    if tool not in TOOLS:
        raise PathError(PathErrorCode.INVALID_PATH, f'unknown tool {tool!r}; tools: {", ".join(TOOLS)}')
    if not math.isfinite(speed) or speed < 0 or speed > config.max_speed:
        raise PathError(PathErrorCode.INVALID_PATH,
                        f'speed {speed} m/s: give one in (0, {config.max_speed}] m/s, or 0 for the default')
    strokes = check_strokes(strokes, config.surface)
    speed = speed or config.speed
    surface = config.surface
    contact = tool != TOOL_NONE
    z_follow = surface.z - (tools.press_depth(tool) if contact else -config.travel_height)
    z_travel = surface.z + config.travel_height
    yaw = choose_yaw(tool, np.vstack(strokes), z_follow)
    lengths = [polyline_length(stroke) for stroke in strokes]
    total_length = float(sum(lengths))

    # Reachability first, over the whole path resampled every `step`, so that a path the arm cannot follow fails
    # before anything moves.
    q = READY_JOINTS
    solved_length = 0.0
    for index, stroke in enumerate(strokes):
        q, failure = _reach(tool, stroke, z_follow, yaw, q, config, check_interrupted)
        if failure is not None:
            (x, y), stroke_length = failure
            fraction = (solved_length + stroke_length) / total_length if total_length > 0 else 0.0
            raise PathError(PathErrorCode.IK_FAILED,
                            f'the arm cannot follow the path with the {tool if contact else "tool"} at '
                            f'({x:.3f}, {y:.3f}): no joint solution without a jump (fraction {fraction:.2f})',
                            fraction)
        solved_length += lengths[index]

    limits = config.joint_limits
    follow_limits = CartesianLimits(speed=speed, acceleration=config.acceleration, jerk=config.jerk)
    vertical_limits = CartesianLimits(speed=config.descent_speed)
    travel_limits = CartesianLimits(speed=config.travel_speed)
    steps: list[PathStep] = []
    q = np.asarray(q_start, dtype=float)
    points_before, length_before = 0, 0.0

    def add(kind: StepKind, trajectory: JointTrajectory, stroke: int, points: int = 0, length: float = 0.0) -> None:
        nonlocal q
        steps.append(PathStep(kind, trajectory, stroke, points_before, points, length_before, length))
        q = trajectory.end

    try:
        for index, stroke in enumerate(strokes):
            check_interrupted()
            first = stroke[0]
            if index == 0:  # from wherever the arm is: a joint-space move onto the ready branch
                above = inverse_kinematics(flange_pose(tool, (*first, z_travel), yaw), q_seed=READY_JOINTS,
                                           tool_offset=0.0)
                add(StepKind.TRAVEL, time_joint_path([q, above], limits), index)
            else:  # between strokes: straight at travel height, clear of the objects on the surface
                add(StepKind.TRAVEL, _line(q, tool, (*first, z_travel), yaw, limits, travel_limits, config), index)
            add(StepKind.DESCEND, _line(q, tool, (*first, z_follow), yaw, limits, vertical_limits, config), index)
            add(StepKind.FOLLOW, _follow(q, tool, stroke, z_follow, yaw, limits, follow_limits, config,
                                         check_interrupted), index, len(stroke), lengths[index])
            points_before += len(stroke)
            length_before += lengths[index]
            add(StepKind.LIFT, _line(q, tool, (*stroke[-1], z_travel), yaw, limits, vertical_limits, config),
                index)
        if config.park_joints:
            add(StepKind.PARK, time_joint_path([q, np.asarray(config.park_joints, dtype=float)], limits),
                len(strokes) - 1)
    except (IKError, TrajectoryError) as error:
        raise PathError(PathErrorCode.IK_FAILED, f'the arm cannot follow the path: {error}') from None
    return PathPlan(tool, steps, sum(len(stroke) for stroke in strokes), total_length)


def _line(q: np.ndarray, tool: str, xyz: Sequence[float], yaw: float, limits: JointLimits,
          cartesian_limits: CartesianLimits, config: PathConfig) -> JointTrajectory:
    """A straight move of the tool to `xyz` (same orientation) from joint positions q."""
    return cartesian_line(q, flange_pose(tool, xyz, yaw), limits, cartesian_limits, tool_offset=0.0,
                          max_joint_step=config.max_joint_step)


def _follow(q: np.ndarray, tool: str, stroke: np.ndarray, z: float, yaw: float, limits: JointLimits,
            cartesian_limits: CartesianLimits, config: PathConfig,
            check_interrupted: Callable[[], None]) -> JointTrajectory:
    """Along a stroke at height z: each smooth piece timed along its length, from rest to rest. (The corners of
    the stroke resampled are the stroke's own: resampling adds points only along its straight segments.)"""
    points, cuts = corners(stroke, config.corner_angle)  # the pieces: points cuts[k] to cuts[k + 1]
    if len(points) < 2:
        return time_joint_path([q], limits)
    # Piece k runs from k to k + 1 of one parameter along the stroke, through its points at their fractions of its
    # length: one interpolation gives the points of any pieces at any of their path parameters.
    along = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    lengths = along[cuts[1:]] - along[cuts[:-1]]
    piece = np.searchsorted(cuts, np.arange(len(points)), side='right') - 1  # the piece each point begins
    piece[-1] = len(lengths) - 1
    knots = piece + (along - along[cuts[piece]]) / lengths[piece]
    knots[cuts[1:]] = np.arange(1, len(cuts))  # a piece's last point is k + 1, not the next piece's start
    flange = flange_pose(tool, (0.0, 0.0, z), yaw)  # at (x, y): moved by (x, y)

    def poses_at(piece: np.ndarray, s: np.ndarray) -> np.ndarray:
        along = piece + s
        poses = np.repeat(flange[None], len(s), axis=0)
        poses[:, 0, 3] += np.interp(along, knots, points[:, 0])
        poses[:, 1, 3] += np.interp(along, knots, points[:, 1])
        return poses

    return timed_cartesian_paths(q, poses_at, lengths, None, limits, cartesian_limits, tool_offset=0.0,
                                 max_joint_step=config.max_joint_step, check_interrupted=check_interrupted)


def rest_parts(trajectory: JointTrajectory, max_samples: int) -> list[JointTrajectory]:
    """The trajectory cut where it is at rest (every joint's velocity and acceleration zero: a stroke's corners)
    into consecutive trajectories of at most `max_samples` samples each, each from time 0; more where it does not
    come to rest that often. One part when it has no more samples than that."""
    if len(trajectory) <= max_samples:
        return [trajectory]
    last = len(trajectory) - 1
    rests = np.append(np.flatnonzero(~np.any(trajectory.velocities[:-1], axis=1)
                                     & ~np.any(trajectory.accelerations[:-1], axis=1)), last)
    cuts = [0]
    while cuts[-1] < last:
        # The last rest within max_samples of the part's start, else the first after it (a long smooth piece
        # goes whole).
        within = int(rests[np.searchsorted(rests, cuts[-1] + max_samples - 1, side='right') - 1])
        cuts.append(within if within > cuts[-1] else int(rests[np.searchsorted(rests, cuts[-1], side='right')]))
    return [JointTrajectory(trajectory.times[a:b + 1] - trajectory.times[a], trajectory.positions[a:b + 1],
                            trajectory.velocities[a:b + 1], trajectory.accelerations[a:b + 1], trajectory.joint_names)
            for a, b in zip(cuts[:-1], cuts[1:])]


def tool_tip_positions(trajectory: JointTrajectory, tool: str) -> np.ndarray:
    """(N, 3) world positions of the tool's touching point along a trajectory (the commanded path)."""
    flange_to_tool = _flange_to_tool(tool)
    return np.array([(forward_kinematics(q, 0.0) @ flange_to_tool)[:3, 3] for q in trajectory.positions])
