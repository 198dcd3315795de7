"""Carrying out a MobilePickPlace request over ports (plain Python, no ROS): drive where the arm reaches, then run
the arm's stages (cap_control.mobile_pick_place.plan) with the table top's plan runner
(cap_control.pick_place.executor.PlanRun).

One object is held at a time: a pick with the hands full, or a place with nothing held, is refused before anything
moves. The object is looked up again after the base arrived (the camera sees it better from there), and its
position is taken into the arm's frame from the base's pose as the joint states report it. A cancel or a stop
cancels the drive or the arm's motion in progress; both hold where they are.
"""
from __future__ import annotations

import abc
import dataclasses
from concurrent.futures import Future
from typing import Callable, Sequence

import numpy as np
from cap_mobile import layout, objects as mobile_objects, robot

from cap_control.mobile_pick_place.plan import (
    MOBILE_CONFIG, Held, MobileErrorCode, object_in_arm_frame, plan_pick, plan_place, reach_pose, to_arm,
)
from cap_control.navigation.plan import OccupancyGrid
from cap_control.pick_place.executor import ExecutionConfig, PickPlaceOutcome, PlanRun
from cap_control.pick_place.plan import ObjectInfo, PickPlaceConfig, PickPlaceError, StageName, overlapping_at
from cap_control.ports import (
    Arm, Ending, Failed, Gripper, Interrupted, Interruption, PendingGoal, Perception, interruption_message,
)

TASK_PICK, TASK_PLACE_AT_POSITION, TASK_PLACE_AT_OBJECT = 'pick', 'place_at_position', 'place_at_object'
STAGE_NAVIGATE = 'navigate'
DRIVE_TIMEOUT = 180.0  # [s] of wall time for the base to arrive


class Navigator(abc.ABC):
    server_description = 'the navigation node'

    @abc.abstractmethod
    def server_ready(self) -> Future:
        """Completes once the navigation action can take goals and its map has come."""

    @abc.abstractmethod
    def map(self) -> OccupancyGrid:
        """The navigation node's own map: where the base's centre may stand (once server_ready completed)."""

    @abc.abstractmethod
    def go(self, pose: tuple[float, float, float]) -> PendingGoal:
        """Drive the base to (x, y, yaw); the result completes with (error code, message), code 0 on arrival."""

    @abc.abstractmethod
    def pose(self) -> Future:
        """Completes with the base's (x, y, yaw) joints."""


@dataclasses.dataclass(frozen=True)
class MobileRequest:
    task: str  # TASK_PICK, TASK_PLACE_AT_POSITION or TASK_PLACE_AT_OBJECT
    object_name: str = ''
    target_xy: tuple[float, float] = (0.0, 0.0)


class MobilePickPlaceExecutor:
    """Runs MobilePickPlace requests one at a time; remembers what the gripper holds between them."""

    def __init__(self, arm: Arm, gripper: Gripper, perception: Perception, navigator: Navigator,
                 config: PickPlaceConfig = MOBILE_CONFIG, timeouts: ExecutionConfig = ExecutionConfig(),
                 stop_source: str = 'a stop request',
                 log: Callable[[str, str], None] | None = None) -> None:
        self.arm, self.gripper, self.perception, self.navigator = arm, gripper, perception, navigator
        self.config, self.timeouts = config, timeouts
        self.stop_source = stop_source
        self.log = log or (lambda level, message: None)
        self.held: Held | None = None

    def run(self, request: MobileRequest, interruption: Interruption,
            feedback: Callable[[str, float], None] = lambda stage, progress: None) -> PickPlaceOutcome:
        run = PlanRun(self, interruption)
        try:
            if request.task == TASK_PICK:
                final = self._pick(run, request.object_name, feedback)
            elif request.task in (TASK_PLACE_AT_POSITION, TASK_PLACE_AT_OBJECT):
                final = self._place(run, request, feedback)
            else:
                raise Failed(MobileErrorCode.UNKNOWN, f'unknown task {request.task!r}')
            return PickPlaceOutcome(Ending.SUCCEEDED, MobileErrorCode.NONE, '', final)
        except Interrupted:
            confirmed = run.cancel_active_goal()
            ending = Ending.CANCELLED if interruption.reason == Ending.CANCELLED else Ending.STOPPED
            return PickPlaceOutcome(ending, MobileErrorCode.CANCELLED,
                                    interruption_message(ending, self.stop_source, confirmed,
                                                         self.timeouts.service_timeout, 'the robot'),
                                    halt_confirmed=confirmed)
        except (Failed, PickPlaceError) as failure:
            run.cancel_active_goal()
            self.log('warning', f'mobile pick-and-place failed: {failure.message}')
            return PickPlaceOutcome(Ending.FAILED, MobileErrorCode(int(failure.code)), failure.message)
        except Exception as error:  # noqa: BLE001 - whatever went wrong, the motion stops and the goal says so
            run.cancel_active_goal()
            return PickPlaceOutcome(Ending.FAILED, MobileErrorCode.UNKNOWN, f'mobile pick-and-place failed: {error!r}')

    # ------------------------------------------------------------------------------------------- tasks
    def _pick(self, run: PlanRun, name: str, feedback) -> tuple[float, float, float] | None:
        if self.held is not None:
            raise Failed(MobileErrorCode.HANDS_FULL, f'the gripper holds the {self.held.name}; put it down first')
        found = self._find(run, name, MobileErrorCode.OBJECT_NOT_FOUND)
        piece = self._surface(found.info.position, f'the {found.info.name}')
        keep_clear = self._others_on(run, piece, found.info.name)
        self._drive(run, found.info.position, piece, keep_clear, feedback)
        seen = self._find(run, found.info.name, MobileErrorCode.OBJECT_NOT_FOUND)
        base = self._base_pose(run)
        plan, held = plan_pick(object_in_arm_frame(seen.info, base), seen.info, run.current_joints(), self.config)
        self._execute(run, plan, feedback)
        self.held = held
        self.log('info', f'picked the {held.name} from the {piece.name}')
        final = run.object_state(held.name)
        return final.position if final.success else None

    def _place(self, run: PlanRun, request: MobileRequest, feedback) -> tuple[float, float, float] | None:
        held = self.held
        if held is None:
            raise Failed(MobileErrorCode.NOTHING_HELD, 'the gripper holds nothing to put down')
        if request.task == TASK_PLACE_AT_OBJECT:
            target = self._find(run, request.object_name, MobileErrorCode.TARGET_NOT_FOUND)
            if target.info.name == held.name:
                raise Failed(MobileErrorCode.TARGET_NOT_FOUND, f'cannot put the {held.name} on itself')
            xy, rest_z, what = target.info.position[:2], target.info.top, f'the {target.info.name}'
        else:
            xy = tuple(float(v) for v in request.target_xy)
            rest_z, what = mobile_objects.surface_height(*xy), f'({xy[0]:.2f}, {xy[1]:.2f})'
        piece = self._surface(xy, what)
        drop_from = None
        if piece.kind == 'bin':  # let it fall in from above the rim: the arm does not reach down into a bin
            drop_from = piece.top - robot.ARM_MOUNT[2]
            what = f'the {piece.name}'
        if request.task != TASK_PLACE_AT_OBJECT and drop_from is None:
            self._refuse_taken_spot(run, held, xy, rest_z)
        keep_clear = self._others_on(run, piece, held.name)
        self._drive(run, xy, piece, keep_clear, feedback)
        base = self._base_pose(run)
        spot = to_arm((xy[0], xy[1], rest_z), base)
        plan = plan_place(held, spot, (xy[0], xy[1], rest_z), run.current_joints(), self.config, drop_from, what)
        self._execute(run, plan, feedback)
        self.held = None
        self.log('info', f'put the {held.name} down at {what}')
        final = run.object_state(held.name)
        return final.position if final.success else None

    # ------------------------------------------------------------------------------------------- steps
    def _find(self, run: PlanRun, name: str, code: MobileErrorCode):
        report = run.object_state(name)
        if not report.success:
            raise Failed(code, report.message or f'no object named {name!r}')
        return report

    @staticmethod
    def _refuse_taken_spot(run: PlanRun, held: Held, xy: Sequence[float], rest_z: float) -> None:
        """A point another object stands on is refused before the base moves: the held object would come down on
        it, tilt and fall (a bottle set on an orange), and pressed between the fingers and the other object, the
        physics of a simulator can fail too. The table top refuses such a point the same way."""
        others = [report.info for report in run.other_objects(held.name) or ()]
        placed = ObjectInfo(held.name, (float(xy[0]), float(xy[1]), float(rest_z)), held.size)
        taken = overlapping_at(placed, xy, others)
        if taken:
            other = min(taken, key=lambda info: float(np.hypot(info.position[0] - xy[0], info.position[1] - xy[1])))
            raise Failed(MobileErrorCode.OUTSIDE_WORKSPACE,
                         f'cannot put the {held.name} down at ({xy[0]:.2f}, {xy[1]:.2f}): the {other.name} at '
                         f'({other.position[0]:.2f}, {other.position[1]:.2f}) is in the way. Choose a free spot, or '
                         f'put it on the {other.name} by name')

    @staticmethod
    def _others_on(run: PlanRun, piece: layout.Furniture, exclude: str) -> list[tuple[float, float]]:
        """Where the other objects perception knows of stand on `piece`: the arm keeps its path clear of them."""
        return [report.info.position[:2] for report in run.other_objects(exclude) or ()
                if mobile_objects.surface_of(*report.info.position[:2]) == piece.name]

    @staticmethod
    def _surface(xy: Sequence[float], what: str) -> layout.Furniture:
        name = mobile_objects.surface_of(float(xy[0]), float(xy[1]))
        if name is None:
            raise Failed(MobileErrorCode.OUTSIDE_WORKSPACE, f'{what} is on the floor, not on a piece of furniture '
                                                            'the arm can work on')
        return layout.location(name)

    def _drive(self, run: PlanRun, xy: Sequence[float], piece: layout.Furniture,
               keep_clear: Sequence[Sequence[float]], feedback) -> None:
        """Bring the base where the arm reaches `xy` on `piece`: a spot free on the navigation node's own map (its
        parameters decide the base's clearance, so a spot chosen here is one it accepts)."""
        feedback(STAGE_NAVIGATE, 0.0)
        run.available(self.navigator.server_ready(), self.navigator.server_description)
        goal = self.navigator.go(reach_pose(xy, piece, self.navigator.map(), keep_clear=keep_clear))
        run.send(goal, self.navigator.server_description, 'the navigation node refused the goal')
        code, message = run.answer(goal.result, DRIVE_TIMEOUT, self.navigator.server_description)
        run.active = None
        if code != 0:
            raise Failed(MobileErrorCode.UNREACHABLE, f'the base could not get within reach: {message}')

    def _base_pose(self, run: PlanRun) -> np.ndarray:
        return np.asarray(run.wait(self.navigator.pose(), self.timeouts.server_timeout,
                                   'the base\'s joint state is not available'), dtype=float)

    def _execute(self, run: PlanRun, plan, feedback) -> None:
        run.execute(plan, lambda stage, progress: feedback(stage.value if isinstance(stage, StageName) else
                                                           str(stage), progress))


__all__ = ['MobilePickPlaceExecutor', 'MobileRequest', 'Navigator', 'STAGE_NAVIGATE', 'TASK_PICK',
           'TASK_PLACE_AT_OBJECT', 'TASK_PLACE_AT_POSITION']
