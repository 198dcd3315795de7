"""Pick-and-place as a plan of stages: which motions, gripper commands and checks move an object onto a target.

The plan is pure data computed before anything moves, so that an unreachable pose or a target outside the
workspace is reported before the arm starts. The executor (cap_control.pick_place.executor) runs the stages:

    for stage in plan.stages:                      # feedback: stage.name; cancel is honoured between stages
        for step in stage.steps:
            TrajectoryStep -> plan.trajectory_for(step, actual_joints) as a FollowJointTrajectory goal; cancel
                              the goal when the action is cancelled. With step.stop_on_contact, a tracking error
                              above step.contact_tolerance (or PATH_TOLERANCE_VIOLATED) means "touched down": the
                              step ends there successfully.
            GripperStep    -> a GripperCommand goal; its result feeds the checks.
        for check in stage.checks: failure = check.failure(observation); on failure stop with stage.failure_code.

Stages (names as in PickPlace.action feedback): approach above the object with the gripper open, descend, close
(grasp), verify the grasp (finger gap and the fingers stalling on the object), lift (the fingers still apart),
move above the target, place (descend until contact or the target's height: onto a block's top, into a bowl down
to its floor, onto the table), release, retreat (and see the object on the table, near the target).

Workspace limits are enforced here whatever the caller asks, before anything moves, with OUTSIDE_WORKSPACE and a
message that names the target and what is allowed:
- an object to pick outside the table bounds is refused;
- a place that would leave any of the placed object over the table's edge is refused: its centre must lie within
  the table less half its footprint and `edge_margin` (`allowed_target_range`), on the table or in the bowl it
  goes into (on a block: within the table less half its footprint, as that block is);
- a point of the table where the object would come down on another block is refused (it would slide off that
  block's edge and end beside it, tilted): the caller names the block to stack onto instead;
- a point of the table where the object would come down on a bowl's rim moves clear of it, at most `rim_shift`
  (it would slide off the rim's slope); the check after placing still measures from the point asked for.
No TCP pose goes below the table's safety height. After the retreat, an object seen off the table (fallen), not
resting on it where placed at a point, or farther from the target than the tolerance fails the pick-and-place with
OBJECT_DROPPED and the reason, so the result matches where the object really is.
"""
from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field
from typing import Sequence, Union

import numpy as np
from cap_ros_common.parameters import parameter
from cap_tabletop.objects import CATEGORY_BLOCK, CATEGORY_BOWL
from cap_tabletop.workspace import TABLE_X_RANGE, TABLE_Y_RANGE, TABLE_Z

from cap_control.kinematics import (
    DEFAULT_TOOL_OFFSET, IKError, forward_kinematics, inverse_kinematics, joint_distance, top_down_pose,
)
from cap_control.trajectory import (
    DEFAULT_PERIOD, UR5E_LIMITS, CartesianLimits, JointLimits, JointTrajectory, TrajectoryError, cartesian_line,
    time_joint_path, trajectory_tcp_positions,
)


class PickPlaceErrorCode(enum.IntEnum):
    """Result codes; the values are those of cap_interfaces/action/PickPlace.action."""

    NONE = 0
    UNKNOWN = 1
    OBJECT_NOT_FOUND = 2
    TARGET_NOT_FOUND = 3
    OUTSIDE_WORKSPACE = 4
    IK_FAILED = 5
    GRASP_MISSED = 6
    OBJECT_DROPPED = 7
    CANCELLED = 8
    TIMEOUT = 9


class StageName(str, enum.Enum):
    """Stage names; the values are the STAGE_* feedback constants of PickPlace.action."""

    APPROACH = 'approach'
    DESCEND = 'descend'
    GRASP = 'grasp'
    VERIFY = 'verify'
    LIFT = 'lift'
    MOVE = 'move'
    PLACE = 'place'
    RELEASE = 'release'
    RETREAT = 'retreat'


class PickPlaceError(Exception):
    """A pick-and-place that cannot be done, with the result code to report."""

    def __init__(self, code: PickPlaceErrorCode, message: str):
        super().__init__(message)
        self.code = code
        self.message = message


@dataclass(frozen=True)
class Workspace:
    """Where the arm may pick and place: the table-top rectangle [m, world frame] and its surface height."""

    x_min: float = parameter(TABLE_X_RANGE[0], 'Workspace (table-top) bounds, world frame [m]; objects and targets '
                             'outside are refused.')
    x_max: float = parameter(TABLE_X_RANGE[1], 'See x_min.')
    y_min: float = parameter(TABLE_Y_RANGE[0], 'See x_min.')
    y_max: float = parameter(TABLE_Y_RANGE[1], 'See x_min.')
    table_z: float = parameter(TABLE_Z, 'Height of the table surface [m].')
    # The finger pads reach 12.5 mm below the TCP.
    min_tcp_height: float = parameter(0.016, 'Lowest tool-centre-point height above the table [m].')

    def contains_xy(self, x: float, y: float) -> bool:
        return self.x_min <= x <= self.x_max and self.y_min <= y <= self.y_max

    def describe(self) -> str:
        return f'x in [{self.x_min:g}, {self.x_max:g}], y in [{self.y_min:g}, {self.y_max:g}]'


@dataclass(frozen=True)
class ObjectInfo:
    """An object on the table: centre of its bounding box, its own extents (along its yaw, across it, height)."""

    name: str
    position: tuple[float, float, float]
    size: tuple[float, float, float]
    category: str = CATEGORY_BLOCK
    yaw: float = 0.0

    @property
    def bottom(self) -> float:
        return self.position[2] - self.size[2] / 2

    @property
    def top(self) -> float:
        return self.position[2] + self.size[2] / 2

    @classmethod
    def from_bounding_box(cls, name: str, bbox_min: Sequence[float], bbox_max: Sequence[float],
                          category: str = CATEGORY_BLOCK, yaw: float = 0.0) -> 'ObjectInfo':
        """From a world-axis-aligned bounding box (what perception reports) and the object's yaw about z.

        A box turned by yaw has a wider axis-aligned box; its own extents a (along yaw) and b solve
        X = a|cos| + b|sin|, Y = a|sin| + b|cos|. Near 45 degrees that system is ill-conditioned, and the object
        is taken as square.
        """
        low, high = np.asarray(bbox_min, dtype=float), np.asarray(bbox_max, dtype=float)
        extent = high - low
        c, s = abs(math.cos(yaw)), abs(math.sin(yaw))
        determinant = c * c - s * s
        if abs(determinant) < 0.3:
            side = (extent[0] + extent[1]) / (2 * (c + s))
            along, across = side, side
        else:
            along = (extent[0] * c - extent[1] * s) / determinant
            across = (extent[1] * c - extent[0] * s) / determinant
        centre = (low + high) / 2
        return cls(name, (float(centre[0]), float(centre[1]), float(centre[2])),
                   (float(along), float(across), float(extent[2])), category, float(yaw))


def yaw_of_quaternion(x: float, y: float, z: float, w: float) -> float:
    """Yaw [rad] of a box's faces about world z, whichever face it rests on.

    The body axis nearest vertical is the one the box stands on; the yaw is the heading of another body axis,
    which is exact modulo a quarter turn for a cube (and modulo a half turn for an upright box).
    """
    norm = math.sqrt(x * x + y * y + z * z + w * w)
    x, y, z, w = x / norm, y / norm, z / norm, w / norm
    rotation = np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])
    vertical = int(np.argmax(np.abs(rotation[2])))
    heading = 0 if vertical != 0 else 1
    return math.atan2(rotation[1, heading], rotation[0, heading])


@dataclass(frozen=True)
class PickPlaceConfig:
    """Heights, gripper settings, checks and motion limits of pick-and-place [m, rad, N, s].

    Every field but joint_limits, clear_view_from and look_again_joints is a parameter of the pick_place node, under
    its field name (workspace and cartesian_limits as dotted names: workspace.x_min, cartesian_limits.speed).
    """

    workspace: Workspace = Workspace()
    tool_offset: float = parameter(DEFAULT_TOOL_OFFSET, 'Tool centre point along the flange z axis [m].')
    travel_height: float = parameter(0.12, 'Lowest tool height while carrying or approaching [m].')
    travel_clearance: float = parameter(0.05, 'Gap kept under a carried object over the tallest other object [m].')
    grasp_height_fraction: float = parameter(0.5, 'Grasp point: this fraction of the object\'s height above its '
                                             'bottom.')
    gripper_open_width: float = parameter(0.085, 'Opening of the open gripper [m].')
    gripper_side_room: float = parameter(0.01, 'Room needed on either side of an object to close around it [m].')
    # A fully opened gripper could push a bowl's wall.
    release_side_room: float = parameter(0.01, 'Opening on release: the object\'s width plus this on each side [m].')
    grip_force: float = parameter(20.0, 'Grip force per finger when grasping [N].')
    # Commanded that far inside the object, the fingers' servo squeezes with its full force limit, and the command
    # ends soon after the fingers stop on the object (a close to zero would run on for the whole width).
    grasp_squeeze: float = parameter(0.015, 'A grasp commands an opening this much narrower than the object [m].')
    grasp_width_tolerance: float = parameter(0.012, 'A grasp is verified when the fingers stop within this of the '
                                             'object\'s width [m].')
    require_stalled: bool = parameter(True, 'A grasp counts only if the fingers stalled on the object.')
    # A missed grasp is most often a stale or partial view of the object (a camera that last saw it from behind the
    # arm): looking again and grasping once more finishes the pick, as a person would.
    grasp_attempts: int = parameter(2, 'Grasps tried before a missed grasp fails the pick; after a miss the fingers '
                                    'open, the arm lifts back (and clears the camera\'s view) and perception looks '
                                    'again.')
    place_clearance: float = parameter(0.005, 'Release height above the expected contact [m].')
    bowl_floor_thickness: float = parameter(0.01, 'A bowl\'s floor is taken this far above its bottom [m].')
    finger_thickness: float = parameter(0.014, 'Thickness of a finger outside its pad [m]; grasp and place yaws keep '
                                        'the fingers clear of neighbouring objects.')
    finger_room: float = parameter(0.03, 'Room beside the fingers beyond which every grasp or place yaw counts as '
                                   'clear [m].')
    # Camera position (world) that perception watches the table from, or None. When set, after placing the tool
    # moves clear_view_distance sideways at travel height, out of that camera's line of sight to what it just
    # placed, so that perception sees the new stack rather than remembering its blocks where they were.
    clear_view_from: tuple[float, float, float] | None = None
    # With clear_view_from: joint positions out of the camera's view, where the arm goes to look again when what it
    # placed is still hidden after the sideways move (the forearm can hang over a stack near the base); None: never.
    look_again_joints: tuple[float, ...] | None = None
    # 0.12 left far targets on the centre line hidden by the forearm.
    clear_view_distance: float = parameter(0.20, 'How far sideways the tool moves after placing to clear the '
                                           'camera\'s view (with clear_view) [m].')
    contact_tolerance: float = parameter(0.001, 'Joint tracking error read as contact while placing [rad] (sent as '
                                         'the path tolerance of the place descent).')
    # After retreating, an object placed on a target object farther than this was dropped on the way.
    place_tolerance: float = parameter(0.08, 'Largest xy distance of the placed object from the target object [m] '
                                       'before the result reports it dropped.')
    point_place_tolerance: float = parameter(0.03, 'Largest xy distance of an object placed at a point of the table '
                                             'from that point [m] before the result reports a failure.')
    edge_margin: float = parameter(0.01, 'Room kept between a placed object\'s footprint and the table\'s edges '
                                   '[m]; a target that leaves less is refused (OUTSIDE_WORKSPACE).')
    # Set down on another block's edge, a block slides off and ends beside it, 1.4-3.5 cm from the point, or
    # leaning on it, tilted.
    target_room: float = parameter(0.0, 'Room kept between a point target and the footprints of the other blocks '
                                   '[m] (0: not overlapping them).')
    # Set down with its footprint on a bowl's sloping wall from outside, an object slides off outwards, 1.3-3.4 cm
    # from the point (measured at full speed), or stays on the rim, tilted.
    rim_shift: float = parameter(0.025, 'A point target where the object would come down on a bowl\'s rim moves at '
                                 'most this far, to the nearest point clear of every rim [m] (0: never moved).')
    stack_radius: float = parameter(0.015, 'A point target this close to a block\'s centre means that block: the '
                                    'object is stacked on it (a program that places "at get_obj_pos(block)") [m].')
    resting_tolerance: float = parameter(0.015, 'Placed at a point, the object must rest on the table: its centre '
                                         'at most this much above half its height [m].')
    allowed_sag: float = parameter(0.03, 'Largest sag of a joint-space move below its endpoints\' height before a '
                                   'straight line is used instead [m].')
    joint_limits: JointLimits = UR5E_LIMITS
    cartesian_limits: CartesianLimits = CartesianLimits()
    # The last centimetres of a place are slow: at full acceleration the servos lag the reference by more than
    # the contact tolerance, which would read as a touch-down in mid-air.
    touchdown_limits: CartesianLimits = CartesianLimits(speed=0.1, acceleration=0.8, jerk=8.0)
    touchdown_height: float = parameter(0.015, 'The place descent slows down (touchdown_limits) this far above the '
                                        'expected contact [m].')
    # The robot's controller and the unit tests run on the same points.
    trajectory_period: float = parameter(DEFAULT_PERIOD, 'Time between trajectory points sent to the controller '
                                         '[s].')
    replan_tolerance: float = parameter(0.01, 'An actual start farther than this from a step\'s planned start makes '
                                        'the step be planned again [rad].')


@dataclass
class TrajectoryStep:
    """Follow a joint trajectory. `goal_pose` (4x4) for straight lines, `goal_joints` for joint-space moves."""

    trajectory: JointTrajectory
    cartesian: bool
    goal_joints: np.ndarray
    goal_pose: np.ndarray
    stop_on_contact: bool = False
    contact_tolerance: float = 0.0
    limits: CartesianLimits | None = None  # a straight line's limits; None: the config's cartesian_limits


@dataclass
class GripperStep:
    """Command the gripper opening [m] with at most `max_effort` [N] (0 = the gripper's default).

    With `unless_open_at_least` [m], the step is skipped when the fingers are already open that wide. With `wait`
    False, the stage's next motion starts at once and the stage waits for the gripper at its end (the fingers open
    while the arm travels).
    """

    position: float
    max_effort: float = 0.0
    unless_open_at_least: float | None = None
    wait: bool = True


Step = Union[TrajectoryStep, GripperStep]


@dataclass
class Observation:
    """What the executor saw after a stage's steps.

    gripper_position/stalled: the last gripper result, or the current finger opening [m] where the executor can
    read it (e.g. from /joint_states); object_position: from perception, for checks that need it, with
    object_visible False when perception only remembers where the object was last seen.
    """

    gripper_position: float | None = None
    gripper_stalled: bool | None = None
    object_position: tuple[float, float, float] | None = None
    object_visible: bool = True


@dataclass(frozen=True)
class GraspCheck:
    """The fingers closed on the object: the opening is about the object's width (and the fingers stalled)."""

    min_gap: float
    max_gap: float
    require_stalled: bool
    needs_object_position = False

    def failure(self, observation: Observation) -> str | None:
        gap = observation.gripper_position
        if gap is None:
            return 'no gripper result to verify the grasp'
        if gap < self.min_gap:
            return f'grasp missed: the fingers closed to {gap * 1000:.1f} mm (the object is about ' \
                   f'{(self.min_gap + self.max_gap) * 500:.0f} mm wide)'
        if gap > self.max_gap:
            return f'grasp missed: the fingers stopped at {gap * 1000:.1f} mm, wider than the object'
        if self.require_stalled and not observation.gripper_stalled:
            return 'grasp missed: the fingers did not stop on the object'
        return None


@dataclass(frozen=True)
class LiftCheck:
    """The object rose with the gripper: the fingers are still held apart by it after the lift.

    Judged by the fingers alone: a camera sees a held object only in part (the gripper hides it), and detectors
    place it badly, while fingers that closed past the object's width tell a slip for certain.
    """

    object_name: str
    min_gap: float
    needs_object_position = False

    def failure(self, observation: Observation) -> str | None:
        if observation.gripper_position is None:
            return f'cannot tell whether the {self.object_name} was lifted (no finger opening)'
        if observation.gripper_position < self.min_gap:
            return f'the {self.object_name} slipped out of the gripper while lifting (the fingers closed to ' \
                   f'{observation.gripper_position * 1000:.1f} mm)'
        return None


@dataclass(frozen=True)
class PlacedCheck:
    """The object ended on the table, within `tolerance` [m] (xy) of the target point (judged where it is seen)."""

    object_name: str
    target_xy: tuple[float, float]
    tolerance: float
    workspace: Workspace | None = None  # the table the object must still be on; None: not checked
    max_height: float | None = None  # highest centre of an object resting on the table; None: not checked
    needs_object_position = True

    def failure(self, observation: Observation) -> str | None:
        if observation.object_position is None:
            return f'the {self.object_name} was not found after placing'
        if not observation.object_visible:
            return None
        if self.workspace is not None:
            reason = off_table_reason(self.object_name, observation.object_position, self.workspace)
            if reason:
                return reason
        if self.max_height is not None and observation.object_position[2] > self.max_height:
            return f'the {self.object_name} did not come to rest on the table at ({self.target_xy[0]:.3f}, ' \
                   f'{self.target_xy[1]:.3f}): its centre is {observation.object_position[2]:.3f} m high, on top ' \
                   f'of something'
        miss = math.dist(observation.object_position[:2], self.target_xy)
        if miss > self.tolerance:
            return f'the {self.object_name} ended {miss:.3f} m from the target ({self.target_xy[0]:.3f}, ' \
                   f'{self.target_xy[1]:.3f}), more than the {self.tolerance:.3f} m allowed'
        return None


Check = Union[GraspCheck, LiftCheck, PlacedCheck]


@dataclass
class Stage:
    """One stage: steps run in order, then checks; `progress` is the fraction of the whole done after it."""

    name: StageName
    steps: list[Step]
    checks: list[Check] = field(default_factory=list)
    failure_code: PickPlaceErrorCode = PickPlaceErrorCode.UNKNOWN
    progress: float = 0.0


@dataclass
class PickPlacePlan:
    """The stages of one pick-and-place, and the figures they were planned from."""

    object: ObjectInfo
    target_xy: tuple[float, float]
    target_description: str
    stages: list[Stage]
    grasp_yaw: float
    place_yaw: float
    travel_z: float
    grasp_z: float
    place_z: float
    config: PickPlaceConfig
    # A move out of the camera's view, made only when the placed object is hidden after the retreat.
    look_again: TrajectoryStep | None = None

    @property
    def duration(self) -> float:
        """Planned motion time [s] (gripper time excluded)."""
        return sum(step.trajectory.duration for stage in self.stages for step in stage.steps
                   if isinstance(step, TrajectoryStep))

    def trajectory_for(self, step: TrajectoryStep, actual_joints: Sequence[float]) -> JointTrajectory:
        """The step's trajectory from where the arm actually is (planned again if it is not at the step's start).

        After a place that stopped on contact, for instance, the retreat starts lower than planned.
        """
        actual = np.asarray(actual_joints, dtype=float)
        if joint_distance(actual, step.trajectory.start) <= self.config.replan_tolerance:
            return step.trajectory
        try:
            if step.cartesian:
                return cartesian_line(actual, step.goal_pose, self.config.joint_limits,
                                      step.limits or self.config.cartesian_limits, self.config.trajectory_period,
                                      self.config.tool_offset)
            return time_joint_path([actual, step.goal_joints], self.config.joint_limits,
                                   self.config.trajectory_period)
        except (IKError, TrajectoryError) as error:
            raise PickPlaceError(PickPlaceErrorCode.IK_FAILED, f'cannot move on from the actual position: {error}')


Target = Union[ObjectInfo, Sequence[float]]


class _Planner:
    """Builds one plan; keeps the joint state the stages chain through."""

    def __init__(self, config: PickPlaceConfig, current_joints: Sequence[float]):
        self.config = config
        self.joints = np.asarray(current_joints, dtype=float)

    def solve(self, xyz: Sequence[float], yaw: float, what: str) -> np.ndarray:
        try:
            return inverse_kinematics(top_down_pose(xyz, yaw), self.joints, self.config.tool_offset)
        except IKError as error:
            raise PickPlaceError(PickPlaceErrorCode.IK_FAILED,
                                 f'cannot reach {what} at {np.round(xyz, 3).tolist()}: {error}')

    def best_yaw(self, xyz: Sequence[float], yaws: Sequence[float], what: str) -> float:
        """Of equivalent yaws, the one whose joints are nearest the current ones (least wrist turning)."""
        costs = []
        for yaw in yaws:
            try:
                q = inverse_kinematics(top_down_pose(xyz, yaw), self.joints, self.config.tool_offset)
            except IKError:
                continue
            costs.append((float(np.sum((q - self.joints) ** 2)), yaw))
        if not costs:
            self.solve(xyz, yaws[0], what)  # raises with the reason
        return min(costs)[1]

    def joint_move(self, xyz: Sequence[float], yaw: float, what: str) -> TrajectoryStep:
        """A joint-space move to the tool pointing down at xyz, turned by yaw."""
        return self.joint_goal(self.solve(xyz, yaw, what), what, top_down_pose(xyz, yaw))

    def joint_goal(self, joints: Sequence[float], what: str, pose: np.ndarray | None = None) -> TrajectoryStep:
        """A joint-space move to the given joint positions (`pose`: the tool's there, if known)."""
        goal = np.asarray(joints, dtype=float)
        try:
            trajectory = time_joint_path([self.joints, goal], self.config.joint_limits,
                                         self.config.trajectory_period)
        except TrajectoryError as error:
            raise PickPlaceError(PickPlaceErrorCode.IK_FAILED, f'cannot move to {what}: {error}')
        self.joints = trajectory.end
        return TrajectoryStep(trajectory, False, goal,
                              pose if pose is not None else forward_kinematics(goal, self.config.tool_offset))

    def line(self, xyz: Sequence[float], yaw: float, what: str, stop_on_contact: bool = False,
             limits: CartesianLimits | None = None) -> TrajectoryStep:
        pose = top_down_pose(xyz, yaw)
        try:
            trajectory = cartesian_line(self.joints, pose, self.config.joint_limits,
                                        limits or self.config.cartesian_limits, self.config.trajectory_period,
                                        self.config.tool_offset)
        except (IKError, TrajectoryError) as error:
            raise PickPlaceError(PickPlaceErrorCode.IK_FAILED,
                                 f'cannot move straight to {what} at {np.round(xyz, 3).tolist()}: {error}')
        self.joints = trajectory.end
        return TrajectoryStep(trajectory, True, trajectory.end, pose, stop_on_contact,
                              self.config.contact_tolerance if stop_on_contact else 0.0, limits)

    def travel(self, xyz: Sequence[float], yaw: float, what: str, lowest_allowed_z: float) -> TrajectoryStep:
        """A joint-space move at travel height, or a straight line if the joint move would sag too low."""
        start = self.joints
        step = self.joint_move(xyz, yaw, what)
        if trajectory_tcp_positions(step.trajectory, self.config.tool_offset)[:, 2].min() >= lowest_allowed_z:
            return step
        self.joints = start
        return self.line(xyz, yaw, what)


def _footprint_radius(obj: ObjectInfo) -> float:
    """Radius of the circle around the object's footprint (a block's corners, a bowl's rim)."""
    return math.hypot(obj.size[0], obj.size[1]) / 2 if obj.category != CATEGORY_BOWL else max(obj.size[:2]) / 2


def top_block_in_bowl(bowl: ObjectInfo, neighbours: Sequence[ObjectInfo]) -> ObjectInfo | None:
    """The highest block resting in the bowl, if any: one more block goes on top of it, squarely.

    Dropped at the bowl's centre, blocks pile up crooked on each other and a pile of three or four topples over
    the rim; stacked squarely they form a steady tower in the bowl.
    """
    inside = [other for other in neighbours if other.category != CATEGORY_BOWL
              and math.dist(other.position[:2], bowl.position[:2]) < max(bowl.size[:2]) / 2]
    return max(inside, key=lambda other: other.top) if inside else None


def finger_clearance(xy: Sequence[float], yaw: float, neighbours: Sequence[ObjectInfo],
                     finger_reach: float) -> float:
    """Room between the fingers around `xy` (turned by `yaw`, reaching `finger_reach` out from the centre) and the
    nearest neighbouring object [m].

    The fingers close along the TCP y axis, world (sin yaw, -cos yaw) for a top-down pose.
    """
    axis = np.array([math.sin(yaw), -math.cos(yaw)])
    centre = np.asarray(xy[:2], dtype=float)
    room = math.inf
    for other in neighbours:
        for side in (1.0, -1.0):
            finger = centre + side * finger_reach * axis
            room = min(room, float(np.linalg.norm(finger - np.asarray(other.position[:2]))) - _footprint_radius(other))
    return room


def _roomiest_yaw(planner: '_Planner', xyz: Sequence[float], yaws: Sequence[float],
                  neighbours: Sequence[ObjectInfo], finger_reach: float, config: PickPlaceConfig, what: str) -> float:
    """Of equivalent yaws, one that keeps the fingers clearest of the neighbours, then the least wrist turning.

    A finger that comes down on or against a neighbour pushes it out of its place (or off the table).
    """
    rooms = {yaw: min(finger_clearance(xyz, yaw, neighbours, finger_reach), config.finger_room) for yaw in yaws}
    roomiest = max(rooms.values())
    try:
        return planner.best_yaw(xyz, [yaw for yaw in yaws if rooms[yaw] >= roomiest - 1e-3], what)
    except PickPlaceError:  # the roomiest yaws are out of reach: any reachable one
        return planner.best_yaw(xyz, yaws, what)


CLEAR_VIEW_MIN_REACH = 0.3  # [m] from the base axis; the table's near edge is 0.2 m out


def _clear_view_step(planner: '_Planner', place_xy: Sequence[float], travel_z: float, yaw: float,
                     config: PickPlaceConfig) -> TrajectoryStep | None:
    """A straight move at travel height that takes the tool out of the camera's line of sight to `place_xy`.

    Sideways across the line from the camera, first to the side nearer the robot's base (easier to reach), else
    the other side, else straight away from the camera, but never within CLEAR_VIEW_MIN_REACH of the base; None if
    none of them can be reached.
    """
    camera = np.asarray(config.clear_view_from[:2], dtype=float)
    target = np.asarray(place_xy[:2], dtype=float)
    away = target - camera
    away = away / np.linalg.norm(away) if np.linalg.norm(away) > 1e-3 else np.array([1.0, 0.0])
    across = np.array([-away[1], away[0]])
    sides = sorted((target + config.clear_view_distance * across, target - config.clear_view_distance * across),
                   key=lambda point: float(np.linalg.norm(point)))
    # Not close in to the base: folded up there, the arm's next travel sweeps low across the table.
    points = [point for point in [*sides, target + config.clear_view_distance * away]
              if np.linalg.norm(point) >= CLEAR_VIEW_MIN_REACH]
    for point in points:
        try:
            return planner.line((float(point[0]), float(point[1]), travel_z), yaw, 'out of the camera\'s view')
        except PickPlaceError:
            continue
    return None


def footprint_half_extents(obj: ObjectInfo) -> tuple[float, float]:
    """Half the world x and y extents of the object's footprint, whichever quarter turn it is placed at.

    The place keeps the held object's faces turned as they were (or a quarter turn from that), so the footprint
    is the object's own, turned by its yaw; a bowl is round.
    """
    if obj.category == CATEGORY_BOWL:
        radius = max(obj.size[:2]) / 2
        return radius, radius
    along, across = obj.size[0], obj.size[1]
    c, s = abs(math.cos(obj.yaw)), abs(math.sin(obj.yaw))
    x = max(along * c + across * s, across * c + along * s) / 2
    y = max(along * s + across * c, across * s + along * c) / 2
    return x, y


def allowed_target_range(obj: ObjectInfo, config: PickPlaceConfig, margin: float | None = None
                         ) -> tuple[tuple[float, float], tuple[float, float]]:
    """The x and y ranges [m] of a place point that keep all of `obj` on the table, `margin` (default:
    `edge_margin`) to spare.

    Empty (low > high) when the object is too large for the table.
    """
    workspace = config.workspace
    margin = config.edge_margin if margin is None else margin
    half_x, half_y = footprint_half_extents(obj)
    reach_x, reach_y = half_x + margin, half_y + margin
    return (workspace.x_min + reach_x, workspace.x_max - reach_x), (workspace.y_min + reach_y,
                                                                    workspace.y_max - reach_y)


def check_place_on_table(obj: ObjectInfo, place_xy: Sequence[float], config: PickPlaceConfig,
                         support: ObjectInfo | None = None) -> None:
    """Raise OUTSIDE_WORKSPACE unless `obj`, placed with its centre at `place_xy`, lies wholly on the table.

    `support` is what it would be placed on (None: the table at that point). On a block the object rests on that
    block, which is on the table already: the edge margin (room for the errors of a place on the table) is not
    asked for again; a block set down at the margin's limit may end a few millimetres beyond it.
    """
    margin = 0.0 if support is not None and support.category != CATEGORY_BOWL else config.edge_margin
    (x_low, x_high), (y_low, y_high) = allowed_target_range(obj, config, margin)
    x, y = float(place_xy[0]), float(place_xy[1])
    if x_low <= x <= x_high and y_low <= y <= y_high:
        return
    workspace = config.workspace
    half_x, half_y = footprint_half_extents(obj)
    point = f'({x:.3f}, {y:.3f})'
    where = f'the target point {point}' if support is None else f'the {support.name} at {point}'
    why = 'is outside the workspace' if not workspace.contains_xy(x, y) else 'is too close to the table\'s edge'
    room = f', and a {margin * 100:.1f} cm margin' if margin else ''
    raise PickPlaceError(
        PickPlaceErrorCode.OUTSIDE_WORKSPACE,
        f'cannot place the {obj.name} there: {where} {why}: the {obj.name} would not be wholly on the table. '
        f'Allowed for its centre: x in [{x_low:.3f}, {x_high:.3f}], y in [{y_low:.3f}, {y_high:.3f}] '
        f'(the table {workspace.describe()}, less half the {obj.name}\'s footprint, {half_x * 100:.1f} x '
        f'{half_y * 100:.1f} cm{room})')


def target_taken_by(obj: ObjectInfo, place_xy: Sequence[float], neighbours: Sequence[ObjectInfo],
                    config: PickPlaceConfig) -> ObjectInfo | None:
    """The block that `obj`, set down on the table with its centre at `place_xy`, would come down on, if any
    (footprints as in overlapping_at, `target_room` apart). Bowls are not in the way: a point inside one puts the
    object into it, and one by a bowl's rim moves clear of it (clear_of_bowl_rims).
    """
    blocks = [other for other in neighbours if other.name != obj.name and other.category != CATEGORY_BOWL]
    return next(iter(overlapping_at(obj, place_xy, blocks, config.target_room)), None)


# [m] kept between a moved place's footprint and a bowl's rim (a rim of 12 flat wall segments reaches 2.5 mm
# past its circle at their joints)
RIM_GAP = 0.005
RIM_SHIFT_STEP = 0.0025  # [m] between the rings of points tried
RIM_SHIFT_DIRECTIONS = 24


def clear_of_bowl_rims(obj: ObjectInfo, place_xy: tuple[float, float], neighbours: Sequence[ObjectInfo],
                       config: PickPlaceConfig) -> tuple[tuple[float, float], ObjectInfo | None]:
    """Where to set `obj` down for the point target `place_xy`, and the bowl whose rim moved it there (or None).

    A point whose footprint would come within RIM_GAP of a bowl's rim moves to the nearest point, at most
    `rim_shift` away, where the footprint clears every rim by RIM_GAP, stays on the table (allowed_target_range)
    and meets no block; with no such point it stays, and the check after placing judges where the object ends. A
    point with all of the footprint within a rim's circle puts the object into that bowl and stays too.
    """
    bowls = [other for other in neighbours if other.category == CATEGORY_BOWL and other.name != obj.name]
    half_x, half_y = footprint_half_extents(obj)

    def gap(xy: Sequence[float], bowl: ObjectInfo) -> float:
        # From the footprint (a world-axis box) to the rim's circle; negative where it reaches over the rim.
        dx = max(abs(xy[0] - bowl.position[0]) - half_x, 0.0)
        dy = max(abs(xy[1] - bowl.position[1]) - half_y, 0.0)
        return math.hypot(dx, dy) - footprint_half_extents(bowl)[0]

    # Wholly within a rim's circle, the object goes into that bowl.
    if config.rim_shift <= 0 or any(math.dist(place_xy, bowl.position[:2]) + math.hypot(half_x, half_y)
                                    <= footprint_half_extents(bowl)[0] for bowl in bowls):
        return place_xy, None
    reached = [bowl for bowl in bowls if gap(place_xy, bowl) < RIM_GAP]
    if not reached:
        return place_xy, None
    (x_low, x_high), (y_low, y_high) = allowed_target_range(obj, config)
    for ring in range(1, int(config.rim_shift / RIM_SHIFT_STEP + 1e-9) + 1):
        radius = ring * RIM_SHIFT_STEP
        candidates = [(place_xy[0] + radius * math.cos(angle), place_xy[1] + radius * math.sin(angle))
                      for angle in np.linspace(0.0, 2 * math.pi, RIM_SHIFT_DIRECTIONS, endpoint=False)]
        clear = [xy for xy in candidates if x_low <= xy[0] <= x_high and y_low <= xy[1] <= y_high
                 and all(gap(xy, bowl) >= RIM_GAP for bowl in bowls)
                 and target_taken_by(obj, xy, neighbours, config) is None]
        if clear:  # the roomiest of the nearest
            best = max(clear, key=lambda xy: min(gap(xy, bowl) for bowl in bowls))
            return best, min(reached, key=lambda bowl: gap(place_xy, bowl))
    return place_xy, None


def overlapping_at(obj: ObjectInfo, place_xy: Sequence[float], others: Sequence[ObjectInfo],
                   margin: float = 0.0) -> list[ObjectInfo]:
    """The objects of `others` whose footprint comes within `margin` of `obj`'s with its centre at `place_xy`.

    Footprints are compared as world-axis boxes (a turned block's box is larger than the block: it errs on the
    safe side)."""
    half_x, half_y = footprint_half_extents(obj)
    overlapping = []
    for other in others:
        other_x, other_y = footprint_half_extents(other)
        if abs(place_xy[0] - other.position[0]) < half_x + other_x + margin and \
                abs(place_xy[1] - other.position[1]) < half_y + other_y + margin:
            overlapping.append(other)
    return overlapping


def off_table_reason(name: str, position: Sequence[float], workspace: Workspace) -> str | None:
    """Why an object seen at `position` (its centre) is no longer on the table, or None if it is on it."""
    x, y, z = (float(v) for v in position[:3])
    if z < workspace.table_z:
        return f'the {name} fell off the table: it is at ({x:.3f}, {y:.3f}), {workspace.table_z - z:.2f} m below ' \
               f'the table top'
    if not workspace.contains_xy(x, y):
        return f'the {name} fell off the table: it is at ({x:.3f}, {y:.3f}), outside the table ' \
               f'({workspace.describe()})'
    return None


def _target_point(target: Target) -> tuple[float, float]:
    if isinstance(target, ObjectInfo):
        return float(target.position[0]), float(target.position[1])
    values = [float(v) for v in target]
    if len(values) not in (2, 3) or not all(math.isfinite(v) for v in values):
        raise PickPlaceError(PickPlaceErrorCode.TARGET_NOT_FOUND, f'target point {values} is not an x, y point')
    return values[0], values[1]


def plan_pick_place(obj: ObjectInfo, target: Target, current_joints: Sequence[float],
                    config: PickPlaceConfig = PickPlaceConfig(), obstacle_height: float | None = None,
                    neighbours: Sequence[ObjectInfo] = ()) -> PickPlacePlan:
    """Plan picking `obj` and placing it on `target` (an object, or an x, y point of the table) from `current_joints`.

    `obstacle_height` is the top of the tallest thing the held object must pass over (default: the target's and
    the object's own tops). `neighbours` are the other objects in view (not `obj`): a block goes into a bowl on
    top of the blocks already there, and the place yaw keeps the fingers clear of what stands around the target.
    Raises PickPlaceError with the result code when it cannot be done.
    """
    workspace = config.workspace
    target_xy = _target_point(target)
    target_object = target if isinstance(target, ObjectInfo) else None
    if not workspace.contains_xy(obj.position[0], obj.position[1]):
        raise PickPlaceError(PickPlaceErrorCode.OUTSIDE_WORKSPACE,
                             f'the {obj.name} at ({obj.position[0]:.3f}, {obj.position[1]:.3f}) is outside the '
                             f'workspace ({workspace.describe()})')
    target_description = f'the {target_object.name}' if target_object else \
        f'({target_xy[0]:.3f}, {target_xy[1]:.3f})'
    if target_object is not None and not workspace.contains_xy(*target_xy):
        raise PickPlaceError(PickPlaceErrorCode.OUTSIDE_WORKSPACE,
                             f'the target {target_object.name} at ({target_xy[0]:.3f}, {target_xy[1]:.3f}) is outside '
                             f'the workspace ({workspace.describe()})')
    if target_object is not None and target_object.name == obj.name:
        raise PickPlaceError(PickPlaceErrorCode.TARGET_NOT_FOUND, f'cannot place the {obj.name} on itself')

    # Grasp across the narrower side that fits between the open fingers. The fingers close along the TCP y axis,
    # so at yaw = object yaw they close across the object's second extent.
    room = config.gripper_open_width - 2 * config.gripper_side_room
    widths = {0: obj.size[1], 1: obj.size[0]}  # quarter turns -> width between the fingers
    fitting = [quarter for quarter, width in widths.items() if width <= room]
    if not fitting:
        raise PickPlaceError(PickPlaceErrorCode.GRASP_MISSED,
                             f'the {obj.name} ({min(obj.size[:2]) * 1000:.0f} mm wide) does not fit in the gripper '
                             f'(opens {config.gripper_open_width * 1000:.0f} mm)')
    grasp_width = min(widths[q] for q in fitting)
    quarters = [q for q in fitting if math.isclose(widths[q], grasp_width, abs_tol=0.005)]

    table_z = workspace.table_z
    lowest_tcp = table_z + workspace.min_tcp_height
    grasp_z = max(obj.bottom + config.grasp_height_fraction * obj.size[2], lowest_tcp)
    held_below_tcp = grasp_z - obj.bottom  # from the TCP down to the held object's bottom
    neighbours = [other for other in neighbours if other.name != obj.name]
    support = target_object  # what the held object will rest on (None: the table)
    if target_object is not None and target_object.category == CATEGORY_BOWL:
        support = top_block_in_bowl(target_object, neighbours) or target_object
    place_xy = target_xy if support is None else (float(support.position[0]), float(support.position[1]))
    # All of the placed object must be over the table (on a block or in a bowl near the edge too): an
    # overhanging one topples off, or the fingers push it off.
    check_place_on_table(obj, place_xy, config, support)
    taken = target_taken_by(obj, place_xy, neighbours, config) if support is None else None
    at_point = [other for other in neighbours if other.category != CATEGORY_BOWL
                and math.dist(place_xy, other.position[:2]) <= config.stack_radius]
    if taken is not None and at_point:
        # The point is a block's own position: stack on it (the top one of a stack there), as if it had been named.
        taken = max(at_point, key=lambda other: other.top)
        support = target_object = taken
        place_xy = target_xy = (float(taken.position[0]), float(taken.position[1]))
        target_description = f'the {taken.name}'
        check_place_on_table(obj, place_xy, config, taken)
        taken = None
    if support is None:
        if taken is not None:
            raise PickPlaceError(
                PickPlaceErrorCode.OUTSIDE_WORKSPACE,
                f'cannot place the {obj.name} at ({place_xy[0]:.3f}, {place_xy[1]:.3f}): the {taken.name} at '
                f'({taken.position[0]:.3f}, {taken.position[1]:.3f}) is in the way (the {obj.name} would '
                f'come down on it and slide off, tilted). Choose a free spot, or put it on the {taken.name} by name')
    if support is None:
        moved_xy, rim_of = clear_of_bowl_rims(obj, place_xy, neighbours, config)
        if rim_of is not None:
            target_description += (f', moved {math.dist(moved_xy, place_xy) * 100:.1f} cm to '
                                   f'({moved_xy[0]:.3f}, {moved_xy[1]:.3f}), clear of the {rim_of.name}\'s rim')
            place_xy = moved_xy
        place_z = table_z + held_below_tcp + config.place_clearance
    elif support.category == CATEGORY_BOWL:
        place_z = support.bottom + config.bowl_floor_thickness + held_below_tcp + config.place_clearance
    else:
        place_z = support.top + held_below_tcp + config.place_clearance
    place_z = max(place_z, lowest_tcp)
    highest_below = max(obstacle_height if obstacle_height is not None else table_z, obj.top,
                        target_object.top if target_object else table_z)
    travel_z = max(config.travel_height, highest_below + config.travel_clearance + held_below_tcp,
                   place_z + 0.02, grasp_z + 0.02)
    lowest_travel_z = travel_z - config.allowed_sag

    planner = _Planner(config, current_joints)
    above_object = (obj.position[0], obj.position[1], travel_z)
    grasp_point = (obj.position[0], obj.position[1], grasp_z)
    above_target = (place_xy[0], place_xy[1], travel_z)
    place_point = (place_xy[0], place_xy[1], place_z)

    # Approach: rise straight up first if the gripper is low (it may be among objects), then move above the object.
    # The fingers open fully (room for the aim's errors) while the arm travels.
    approach_steps: list[Step] = [GripperStep(config.gripper_open_width, wait=False,
                                              unless_open_at_least=config.gripper_open_width - 0.002)]
    start_tcp = forward_kinematics(planner.joints, config.tool_offset)
    if start_tcp[2, 3] < lowest_travel_z and start_tcp[2, 2] < -0.99:
        start_yaw = math.atan2(start_tcp[1, 0], start_tcp[0, 0])
        approach_steps.append(planner.line((start_tcp[0, 3], start_tcp[1, 3], travel_z), start_yaw,
                                           'the travel height'))
    grasp_yaw = _roomiest_yaw(planner, grasp_point, [obj.yaw + q * math.pi / 2 + k * math.pi for q in quarters
                                                     for k in (-1, 0, 1)],
                              neighbours, config.gripper_open_width / 2 + config.finger_thickness, config,
                              f'the {obj.name}')
    approach_steps.append(planner.travel(above_object, grasp_yaw, f'above the {obj.name}', lowest_travel_z))
    descend = planner.line(grasp_point, grasp_yaw, f'the {obj.name}')
    lift = planner.line(above_object, grasp_yaw, f'above the {obj.name}')

    # Keep the held object's faces turned the same way in the world (or square with the block it goes on), with
    # the fingers across whichever side has room: a finger that touches a neighbour pushes it out of its place.
    base_yaw = support.yaw if support is not None and support.category != CATEGORY_BOWL else grasp_yaw
    yaws = [base_yaw + k * math.pi / 2 for k in range(-4, 5)]
    below = {thing.name for thing in (support, target_object) if thing is not None}
    release_width = min(config.gripper_open_width, grasp_width + 2 * config.release_side_room)
    place_yaw = _roomiest_yaw(planner, place_point, yaws, [other for other in neighbours if other.name not in below],
                              release_width / 2 + config.finger_thickness, config, target_description)
    move = planner.travel(above_target, place_yaw, f'above {target_description}', lowest_travel_z)
    # Down fast to just above the expected contact, then slowly, stopping at a touch-down. The contact may come
    # sooner: set down by a bowl, the held object meets its rim first.
    slow_from_z = place_z + config.touchdown_height
    for other in overlapping_at(obj, place_xy, [other for other in neighbours if other.name not in below]):
        slow_from_z = max(slow_from_z, other.top + held_below_tcp + config.touchdown_height)
    place = [planner.line((place_xy[0], place_xy[1], min(slow_from_z, travel_z)), place_yaw, target_description),
             planner.line(place_point, place_yaw, target_description, stop_on_contact=True,
                          limits=config.touchdown_limits)]
    retreat = [planner.line(above_target, place_yaw, f'above {target_description}')]
    if config.clear_view_from is not None:
        clear = _clear_view_step(planner, place_xy, travel_z, place_yaw, config)
        if clear is not None:
            retreat.append(clear)

    tolerance = config.grasp_width_tolerance
    stages = [
        Stage(StageName.APPROACH, approach_steps, failure_code=PickPlaceErrorCode.IK_FAILED),
        Stage(StageName.DESCEND, [descend], failure_code=PickPlaceErrorCode.IK_FAILED),
        Stage(StageName.GRASP, [GripperStep(max(grasp_width - config.grasp_squeeze, 0.0), config.grip_force)]),
        Stage(StageName.VERIFY, [], [GraspCheck(max(grasp_width - tolerance, 0.002), grasp_width + tolerance,
                                                config.require_stalled)], PickPlaceErrorCode.GRASP_MISSED),
        Stage(StageName.LIFT, [lift], [LiftCheck(obj.name, max(grasp_width - tolerance, 0.002))],
              PickPlaceErrorCode.OBJECT_DROPPED),
        Stage(StageName.MOVE, [move], failure_code=PickPlaceErrorCode.IK_FAILED),
        Stage(StageName.PLACE, place, failure_code=PickPlaceErrorCode.IK_FAILED),
        Stage(StageName.RELEASE, [GripperStep(release_width)]),
        Stage(StageName.RETREAT, retreat, [PlacedCheck(
            obj.name, target_xy, config.place_tolerance if target_object else config.point_place_tolerance,
            workspace, None if target_object else table_z + obj.size[2] / 2 + config.resting_tolerance)],
              PickPlaceErrorCode.OBJECT_DROPPED),
    ]
    for index, stage in enumerate(stages):
        stage.progress = (index + 1) / len(stages)
    look_again = planner.joint_goal(config.look_again_joints, 'out of the camera\'s view') \
        if config.clear_view_from is not None and config.look_again_joints is not None else None
    return PickPlacePlan(obj, target_xy, target_description, stages, grasp_yaw, place_yaw, travel_z, grasp_z,
                         place_z, config, look_again)
