"""Picking and placing from the mobile base (plain Python, no ROS): where the base stands to reach an object or a
spot on a piece of furniture, and the arm's stages planned in the arm's own frame.

The arm's frame is the UR5e's base frame on the mobile base (cap_mobile.robot.ARM_MOUNT): the kinematics and the
table top's planning helpers (cap_control.pick_place.plan) work in it unchanged; the checks of a plan (grasp width,
the object lifted, where it ended) stay in the world frame, where perception reports. The base stands at one of the
furniture's four sides, facing it, across from the object (`reach_pose`): the side whose spot is free for the base
and nearest the object within the arm's reach. A pick grasps top-down across the object's narrower side and ends in
the carry pose (the tool over the base, cap_mobile.robot.CARRY_TCP, the object hanging above the base's top); a
place goes over the spot, down until the held object touches (or, over a bin, lets it drop in from above the rim),
opens and stows the arm again.
"""
from __future__ import annotations

import dataclasses
import enum
import math
from typing import Sequence

import numpy as np
from cap_mobile import layout, robot

from cap_control.navigation.plan import OccupancyGrid, wrap_angle
from cap_control.pick_place.plan import (
    GraspCheck, GripperStep, LiftCheck, ObjectInfo, PickPlaceConfig, PickPlaceError, PickPlaceErrorCode,
    PickPlacePlan, PlacedCheck, Stage, StageName, _Planner,
)

# How far from the arm's base (horizontally) a top-down grasp reaches at the furniture's heights: the UR5e with the
# gripper pointing down reaches 0.8 m at 0.25 m above its base and 0.65 m at 0.5 m (measured with its kinematics).
REACH = 0.65  # [m]
LATERAL_MARGIN = 0.1  # [m] the base's spot stays this far inside a side's ends
LATERAL_STEP = 0.05  # [m] between the spots along a side the base may stand at
# The arm, moving from the carry pose out to an object, sweeps the floor plan between its base and the object at the
# furniture's height: an object within this of that line (a 21 cm bottle in front of an apple) would be knocked over.
ARM_CORRIDOR = 0.12  # [m]
# The elbow swings out beyond the base's footprint while the arm moves between the furniture and the carry pose: a
# base that works there keeps this far from the walls (the elbow hit the wall from 0.39 m).
WALL_CLEARANCE = 0.55  # [m] of the base's centre
APPROACH_CLEARANCE = 0.08  # [m] the tool above the object's top (or the spot) before it goes down
DROP_CLEARANCE = 0.12  # [m] the held object's bottom above a bin's rim when it is let go
TRAVEL_SAG = 0.05  # [m] a move over a spot may dip this much below its end height
CARRY_OUT = 0.4  # [m] ahead of the arm's base, where the tool goes straight out of the carry pose before a place
PLACE_TOLERANCE = 0.05  # [m] of an object placed at a spot from the spot
# Above the arm's base [m]: the least height a pick comes out at, above every object the kitchen's furniture holds.
OVER_HEIGHT = 0.45
MIN_GRASP_HEIGHT = 0.016  # [m] of the tool centre above the surface an object stands on
# The gripper's palm is 70 mm above the tool centre (models/ur5e_gripper.xml): a grasp goes at most this far below
# an object's top.
MAX_GRASP_DEPTH = 0.06  # [m]
# The kitchen's objects are larger than the table top's blocks: a can is 66 mm across, so the fingers (85 mm open)
# close on it with 5 mm to spare on each side instead of the table top's 10.
MOBILE_CONFIG = PickPlaceConfig(gripper_side_room=0.005)


# The MobilePickPlace action's codes: PickPlace's, and its own from 20.
MobileErrorCode = enum.IntEnum('MobileErrorCode', {**{code.name: code.value for code in PickPlaceErrorCode},
                                                   'UNREACHABLE': 20, 'HANDS_FULL': 21, 'NOTHING_HELD': 22})


def arm_pose(base_pose: Sequence[float]) -> np.ndarray:
    """4x4 world_T_arm of the base at (x, y, yaw)."""
    x, y, yaw = (float(v) for v in base_pose[:3])
    c, s = math.cos(yaw), math.sin(yaw)
    pose = np.eye(4)
    pose[:3, :3] = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
    mount = np.array(robot.ARM_MOUNT)
    pose[:3, 3] = [x + c * mount[0] - s * mount[1], y + s * mount[0] + c * mount[1], mount[2]]
    return pose


def to_arm(point: Sequence[float], base_pose: Sequence[float]) -> np.ndarray:
    """A world point in the arm's frame."""
    pose = arm_pose(base_pose)
    return pose[:3, :3].T @ (np.asarray(point, dtype=float)[:3] - pose[:3, 3])


def object_in_arm_frame(obj: ObjectInfo, base_pose: Sequence[float]) -> ObjectInfo:
    return dataclasses.replace(obj, position=tuple(float(v) for v in to_arm(obj.position, base_pose)),
                               yaw=wrap_angle(obj.yaw - float(base_pose[2])))


def reach_pose(xy: Sequence[float], piece: layout.Furniture, grid: OccupancyGrid, reach: float = REACH,
               keep_clear: Sequence[Sequence[float]] = ()) -> tuple[float, float, float]:
    """Where the base stands to reach `xy` on `piece`: facing one of its sides, on a free spot of `grid`, the nearest
    to the point whose arm path passes no object of `keep_clear` (x, y of the other objects there); the nearest spot
    when every one has an object in the way. PickPlaceError OUTSIDE_WORKSPACE when no side is within reach."""
    target = np.asarray(xy[:2], dtype=float)
    others = [np.asarray(point[:2], dtype=float) for point in keep_clear]
    best = None
    for side, (nx, ny) in layout.SIDES.items():
        half_normal = abs(nx) * piece.size[0] / 2 + abs(ny) * piece.size[1] / 2
        half_side = abs(ny) * piece.size[0] / 2 + abs(nx) * piece.size[1] / 2
        lateral_axis = np.array([-ny, nx])
        limit = max(half_side - LATERAL_MARGIN, 0.0)
        across = float(np.clip((target - piece.centre) @ lateral_axis, -limit, limit))
        distance = half_normal + layout.MANIPULATION_GAP + layout.BASE_RADIUS
        # Straight across from the point first, then slid along the side (a wall or furniture there, or an object in
        # the arm's way), nearest first.
        laterals = sorted(np.append(np.arange(-limit, limit + 1e-9, LATERAL_STEP), across),
                          key=lambda lateral: abs(lateral - across))
        for lateral in laterals:
            centre = np.array(piece.centre) + distance * np.array([nx, ny]) + lateral * lateral_axis
            if not (grid.is_free(centre) and _clear_of_walls(centre)):
                continue
            pose = (float(centre[0]), float(centre[1]), math.atan2(-ny, -nx))
            arm = arm_pose(pose)[:2, 3]
            gap = float(np.linalg.norm(arm - target))
            if gap > reach:
                continue
            blocked = any(_segment_distance(point, arm, target) < ARM_CORRIDOR for point in others)
            if best is None or (blocked, gap) < best[:2]:
                best = (blocked, gap, pose)
            if not blocked:
                break
    if best is None:
        raise PickPlaceError(PickPlaceErrorCode.OUTSIDE_WORKSPACE,
                             f'({xy[0]:.2f}, {xy[1]:.2f}) on the {piece.name} is out of the arm\'s reach from every '
                             f'side the base can stand at')
    return best[2]


def _segment_distance(point: np.ndarray, start: np.ndarray, end: np.ndarray) -> float:
    along = float(np.clip((point - start) @ (end - start) / max(float((end - start) @ (end - start)), 1e-12), 0, 1))
    return float(np.linalg.norm(point - (start + along * (end - start))))


def _clear_of_walls(xy: Sequence[float]) -> bool:
    """Whether the arm, swinging out of the carry pose, keeps off the room's walls from a base at `xy`."""
    (x0, x1), (y0, y1) = layout.ROOM_X_RANGE, layout.ROOM_Y_RANGE
    return min(xy[0] - x0, x1 - xy[0], xy[1] - y0, y1 - xy[1]) >= WALL_CLEARANCE


@dataclasses.dataclass(frozen=True)
class Held:
    """An object in the gripper: its size and how far its bottom hangs below the tool centre point."""

    name: str
    size: tuple[float, float, float]
    below_tcp: float
    grasp_width: float


def plan_pick(obj: ObjectInfo, world_obj: ObjectInfo, joints: Sequence[float],
              config: PickPlaceConfig = MOBILE_CONFIG) -> tuple[PickPlacePlan, Held]:
    """Stages that grasp `obj` (in the arm's frame; `world_obj` the same in the world, for the checks) from above,
    lift it and bring it to the carry pose."""
    room = config.gripper_open_width - 2 * config.gripper_side_room
    widths = {0: obj.size[1], 1: obj.size[0]}
    fitting = [quarter for quarter, width in widths.items() if width <= room]
    if not fitting:
        raise PickPlaceError(PickPlaceErrorCode.GRASP_MISSED,
                             f'the {obj.name} ({min(obj.size[:2]) * 1000:.0f} mm wide) does not fit in the gripper')
    quarter = min(fitting, key=lambda q: widths[q])
    width = widths[quarter]
    # Half way up, but high enough that the pads (12.5 mm below the tool centre) stay off the surface, and for a tall
    # object (a bottle) near enough its top that the palm stays above it.
    grasp_z = max(obj.bottom + config.grasp_height_fraction * obj.size[2], obj.bottom + MIN_GRASP_HEIGHT,
                  obj.top - MAX_GRASP_DEPTH)
    # The arm comes out over the object at OVER_HEIGHT (or higher), then goes straight down: moving out lower, the
    # arm swept a can standing beside the object off the desk.
    above_z = max(obj.top + APPROACH_CLEARANCE, OVER_HEIGHT)
    planner = _Planner(config, joints)
    x, y = obj.position[:2]
    yaw = planner.best_yaw((x, y, above_z), [obj.yaw + quarter * math.pi / 2 + k * math.pi for k in (-1, 0, 1)],
                           f'the {obj.name}')
    tolerance = config.grasp_width_tolerance
    # Up over the base first, then out: a joint move straight from the stowed pose to above the object swings the
    # gripper forward below the furniture's top, into a countertop's front edge (a rehearsal on the twin saw it).
    rise = planner.joint_move(robot.CARRY_TCP, yaw, 'over the base')
    stages = [
        Stage(StageName.APPROACH, [GripperStep(config.gripper_open_width, wait=False), rise,
                                   planner.travel((x, y, above_z), yaw, f'above the {obj.name}',
                                                  above_z - TRAVEL_SAG)],
              failure_code=PickPlaceErrorCode.IK_FAILED),
        Stage(StageName.DESCEND, [planner.line((x, y, grasp_z), yaw, f'the {obj.name}')],
              failure_code=PickPlaceErrorCode.IK_FAILED),
        Stage(StageName.GRASP, [GripperStep(max(width - config.grasp_squeeze, 0.0), config.grip_force)]),
        Stage(StageName.VERIFY, [], [GraspCheck(max(width - tolerance, 0.002), width + tolerance,
                                                config.require_stalled)], PickPlaceErrorCode.GRASP_MISSED),
        Stage(StageName.LIFT, [planner.line((x, y, above_z), yaw, f'above the {obj.name}')],
              [LiftCheck(obj.name, max(width - tolerance, 0.002))], PickPlaceErrorCode.OBJECT_DROPPED),
        Stage(StageName.MOVE, [planner.joint_move(robot.CARRY_TCP, planner.best_yaw(
            robot.CARRY_TCP, [yaw + k * math.pi / 2 for k in range(-2, 3)], 'the carry pose'), 'the carry pose')],
              [LiftCheck(obj.name, max(width - tolerance, 0.002))], PickPlaceErrorCode.OBJECT_DROPPED),
    ]
    for index, stage in enumerate(stages):
        stage.progress = (index + 1) / len(stages)
    plan = PickPlacePlan(world_obj, tuple(world_obj.position[:2]), 'the carry pose', stages, yaw, yaw, above_z,
                         grasp_z, grasp_z, config)
    return plan, Held(obj.name, obj.size, grasp_z - obj.bottom, width)


def plan_place(held: Held, spot: Sequence[float], world_spot: Sequence[float], joints: Sequence[float],
               config: PickPlaceConfig = MOBILE_CONFIG, drop_from: float | None = None,
               description: str = '') -> PickPlacePlan:
    """Stages that put the held object down at `spot` (x, y and the height it rests on, in the arm's frame;
    `world_spot` the same in the world): down until it touches, or with `drop_from` (a bin's rim height in the arm's
    frame) let go from above it; then open, rise and stow the arm."""
    planner = _Planner(config, joints)
    x, y, rest_z = (float(v) for v in spot[:3])
    description = description or f'({world_spot[0]:.2f}, {world_spot[1]:.2f})'
    yaw = planner.best_yaw((x, y, rest_z + held.below_tcp + APPROACH_CLEARANCE),
                           [k * math.pi / 2 for k in range(-2, 3)], description)
    release_width = min(config.gripper_open_width, held.grasp_width + 2 * config.release_side_room)
    if drop_from is not None:
        # Let go well above the rim: a joint move down to just over it could sweep the held object through the bin's
        # near wall, and out at the arm's reach the last centimetres down are not tracked to the millimetre.
        release_z = above_z = drop_from + DROP_CLEARANCE + held.below_tcp
    else:
        release_z = rest_z + held.below_tcp + config.place_clearance
        above_z = rest_z + held.below_tcp + APPROACH_CLEARANCE
    # Out of the carry pose in a straight line first (a joint move from there swings the upper arm through a tall
    # held object), then over the spot; a joint move that would dip more than TRAVEL_SAG below its end height (the
    # held object through a bin's wall or the furniture's edge) is a straight line instead.
    # Out at the height above the spot when that is higher than the carry pose, risen over the base first: going out
    # at the carry pose's height, a bottle held over a countertop's edge met it and turned in the fingers.
    carry_x, carry_y, carry_z = robot.CARRY_TCP
    out_z = max(carry_z, above_z)
    rise = [planner.line((carry_x, carry_y, out_z), yaw, 'up over the base')] if out_z > carry_z else []
    out = planner.line((CARRY_OUT, 0.0, out_z), yaw, 'out of the carry pose')
    move = [*rise, out, planner.travel((x, y, above_z), yaw, f'above {description}', above_z - TRAVEL_SAG)]
    if drop_from is not None:
        place_steps = []
    else:  # down slowly until the held object touches
        place_steps = [planner.line((x, y, release_z), yaw, description, stop_on_contact=True,
                                    limits=config.touchdown_limits)]
    # Up, back over the base (a joint move straight to the stowed joints from out there sweeps the fingers low
    # over the spot, into what was just put down), then stowed.
    retreat = [planner.line((x, y, max(above_z, release_z + APPROACH_CLEARANCE)), yaw, f'above {description}'),
               planner.joint_move(robot.CARRY_TCP, yaw, 'over the base'),
               planner.joint_goal(robot.STOWED_JOINTS, 'the stowed pose')]
    checks = [] if drop_from is not None else [PlacedCheck(held.name, (float(world_spot[0]), float(world_spot[1])),
                                                           PLACE_TOLERANCE)]
    stages = [
        Stage(StageName.MOVE, move, failure_code=PickPlaceErrorCode.IK_FAILED),
        Stage(StageName.PLACE, place_steps, failure_code=PickPlaceErrorCode.IK_FAILED),
        Stage(StageName.RELEASE, [GripperStep(release_width)]),
        Stage(StageName.RETREAT, retreat, checks, PickPlaceErrorCode.OBJECT_DROPPED),
    ]
    for index, stage in enumerate(stages):
        stage.progress = (index + 1) / len(stages)
    obj = ObjectInfo(held.name, (float(world_spot[0]), float(world_spot[1]), float(world_spot[2])), held.size)
    return PickPlacePlan(obj, (float(world_spot[0]), float(world_spot[1])), description, stages, yaw, yaw, above_z,
                         release_z, release_z, config)


__all__ = ['DROP_CLEARANCE', 'Held', 'MOBILE_CONFIG', 'MobileErrorCode', 'REACH', 'arm_pose', 'object_in_arm_frame',
           'plan_pick', 'plan_place', 'reach_pose', 'to_arm']
