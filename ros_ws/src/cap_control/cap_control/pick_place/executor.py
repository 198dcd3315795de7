"""Carrying out a pick-and-place over ports to the arm, the gripper and perception (plain Python, no ROS).

`PickPlaceExecutor.run` looks the object and target up, plans (cap_control.pick_place.plan) before anything moves, then
runs the stages one by one, reporting each stage. A cancel or a stop (`Interruption`) cancels the running arm or
gripper goal at once (the arm holds where it is) and ends the run with CANCELLED.

A target the plan refuses (off the table's usable area, or on another block: OUTSIDE_WORKSPACE) ends the run before
the arm moves, with a message that names the target and what is allowed. After the retreat the executor waits for
perception to answer from an observation made after it, and a placed object seen off the table or away from its
target fails the run (OBJECT_DROPPED), so the result agrees with where the object really is.

Every wait sleeps on one condition that a port's future completing, an interruption or a timeout wakes, with one
exception: after the retreat, perception is asked again every FRESH_VIEW_RETRY until it answers from an observation
made after the retreat (perception has no event for "a newer observation"). The ports are small abstract classes
that the ROS node implements over its action clients, services and /joint_states, and unit tests implement with
fakes.

A goal counts as running from the moment it is sent, not only once the server accepts it: a cancel or stop while
the acceptance is awaited cancels it too (the port sends the cancel once the server has the goal), so a result that
says the arm stopped is true. If the controller does not confirm the cancel within service_timeout, the result
says so instead.
"""
from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
from cap_ros_common.parameters import parameter
from cap_tabletop.cameras import CAMERAS, DEFAULT_CAMERA
from cap_tabletop.workspace import REST_JOINTS

from cap_control.pick_place.plan import (
    GripperStep, ObjectInfo, Observation, PickPlaceConfig, PickPlaceError, PickPlaceErrorCode, PickPlacePlan,
    Stage, StageName, TrajectoryStep, plan_pick_place,
)
from cap_control.ports import (
    Arm, ArmOutcome, ArmResult, Ending, Failed, GoalRun, Gripper, GripperOutcome, Interrupted, Interruption,
    ObjectReport, PendingGoal, Perception, WaitTimeouts, interruption_message,
)

# Perception has no push for "a newer observation": after the retreat it is asked again this often [s] (a camera
# frame comes every 0.1 s at most).
FRESH_VIEW_RETRY = 0.02


@dataclass(frozen=True)
class ExecutionConfig:
    """How long the executor waits for each kind of answer [s]; parameters of the pick_place node."""

    service_timeout: float = parameter(5.0, 'Longest wait for a perception answer, or for the arm or gripper to '
                                       'accept a goal or a cancel [s].')
    server_timeout: float = parameter(10.0, 'Longest wait for the arm and gripper action servers, the perception '
                                      'services and the arm\'s joint state to appear [s].')
    motion_timeout_margin: float = parameter(30.0, 'Wall time allowed beyond a motion\'s planned duration before '
                                             'TIMEOUT [s].')
    gripper_timeout: float = parameter(15.0, 'Longest wait for a gripper command [s].')
    view_timeout: float = parameter(3.0, 'Longest wait after the retreat for perception to answer from an '
                                    'observation made after it (with clear_view: after the tool cleared the '
                                    'camera\'s view) [s].')


@dataclass(frozen=True)
class MotionSettings:
    """Node parameters that shape PickPlaceConfig's joint limits and clear_view_from."""

    velocity_scale: float = parameter(1.0, 'Fraction of the UR5e joint speed (180 deg/s) used, in (0, 1].')
    acceleration_scale: float = parameter(1.0, 'Fraction of the joint acceleration (3 rad/s^2) and jerk '
                                          '(30 rad/s^3) limits used, in (0, 1].')
    clear_view: bool = parameter(False, 'After placing, move the tool sideways out of the line of sight of the '
                                 'camera at camera_position, so camera-based perception sees what was just placed.')
    camera_position: tuple[float, ...] = parameter(CAMERAS[DEFAULT_CAMERA].position, 'Where the camera perception '
                                                   'watches the table from (world frame) [m]; used with clear_view. '
                                                   'The default is the simulated top camera.')
    look_again_joints: tuple[float, ...] = parameter(REST_JOINTS, 'With clear_view: joint positions out of the '
                                                     'camera\'s view [rad], where the arm goes to look again when what '
                                                     'it placed is still hidden after the sideways move; empty = '
                                                     'never. The default is the simulated arm\'s rest pose.')

    def apply(self, config: PickPlaceConfig) -> PickPlaceConfig:
        """`config` with the scaled joint limits and, with clear_view, the camera to keep out of the view of."""
        if self.clear_view and len(self.camera_position) != 3:
            raise ValueError(f'camera_position must be x, y, z, not {list(self.camera_position)}')
        if self.clear_view and len(self.look_again_joints) not in (0, 6):
            raise ValueError(f'look_again_joints must be 6 joint positions or empty, not '
                             f'{list(self.look_again_joints)}')
        camera = tuple(float(v) for v in self.camera_position) if self.clear_view else None
        look_again = tuple(float(v) for v in self.look_again_joints) if self.clear_view and self.look_again_joints \
            else None
        return dataclasses.replace(config, joint_limits=config.joint_limits.scaled(self.velocity_scale,
                                                                                   self.acceleration_scale),
                                   clear_view_from=camera, look_again_joints=look_again)


# ----------------------------------------------------------------------------------------------------- runs
@dataclass(frozen=True)
class PickPlaceRequest:
    object_name: str
    target_name: str = ''  # empty: place at target_xy
    target_xy: tuple[float, float] = (0.0, 0.0)


@dataclass(frozen=True)
class PickPlaceOutcome:
    ending: Ending
    code: PickPlaceErrorCode
    message: str = ''
    final_position: tuple[float, float, float] | None = None
    # Interrupted runs: whether the controller confirmed the cancel of the goal that was running (True: none was).
    halt_confirmed: bool = True


FeedbackCallback = Callable[[StageName, float], None]


class PickPlaceExecutor:
    """Runs pick-and-place requests one at a time over the ports."""

    def __init__(self, arm: Arm, gripper: Gripper, perception: Perception, config: PickPlaceConfig,
                 timeouts: ExecutionConfig = ExecutionConfig(), stop_source: str = 'a stop request',
                 log: Callable[[str, str], None] | None = None):
        self.arm, self.gripper, self.perception = arm, gripper, perception
        self.config, self.timeouts = config, timeouts
        self.stop_source = stop_source  # named in the message of a stopped run
        self.log = log or (lambda level, message: None)  # log(level, message), level 'debug', 'info' or 'warning'

    def run(self, request: PickPlaceRequest, interruption: Interruption,
            feedback: FeedbackCallback = lambda stage, progress: None) -> PickPlaceOutcome:
        run = PlanRun(self, interruption)
        try:
            plan = run.plan(request)
            attempt = 1
            while True:
                try:
                    run.execute(plan, feedback)
                    break
                except Failed as failure:
                    if failure.code != PickPlaceErrorCode.GRASP_MISSED or attempt >= self.config.grasp_attempts:
                        raise
                    attempt += 1
                    self.log('warning', f'{failure.message}; opening the fingers, lifting back and looking again '
                                        f'(grasp {attempt} of {self.config.grasp_attempts})')
                    run.back_off(plan)
                    plan = run.plan(request)
            final = run.object_state(plan.object.name)
            self.log('info', f'placed the {plan.object.name} on {plan.target_description}')
            return PickPlaceOutcome(Ending.SUCCEEDED, PickPlaceErrorCode.NONE, '',
                                    final.position if final.success else None)
        except Interrupted:
            confirmed = run.cancel_active_goal()
            ending = Ending.CANCELLED if interruption.reason == Ending.CANCELLED else Ending.STOPPED
            if not confirmed:
                self.log('warning', 'the controller did not confirm the cancel of the running goal')
            return PickPlaceOutcome(ending, PickPlaceErrorCode.CANCELLED,
                                    interruption_message(ending, self.stop_source, confirmed,
                                                         self.timeouts.service_timeout),
                                    halt_confirmed=confirmed)
        except (Failed, PickPlaceError) as failure:
            run.cancel_active_goal()
            self.log('warning', f'pick-and-place failed: {failure.message}')
            return PickPlaceOutcome(Ending.FAILED, failure.code, failure.message)


class PlanRun(GoalRun):
    """One request's waits, steps and checks (the mobile pick-and-place runs its own plans with it too)."""

    def __init__(self, executor: PickPlaceExecutor, interruption: Interruption):
        super().__init__(interruption, WaitTimeouts(executor.timeouts.service_timeout,
                                                    executor.timeouts.server_timeout),
                         PickPlaceErrorCode.TIMEOUT, PickPlaceErrorCode.UNKNOWN)
        self.executor = executor
        self.arm, self.gripper, self.perception = executor.arm, executor.gripper, executor.perception
        self.timeouts = executor.timeouts

    # ------------------------------------------------------------------------------------------- perception
    def object_state(self, name: str) -> ObjectReport:
        self.available(self.perception.state_service_ready(), self.perception.service_description)
        return self.answer(self.perception.object_state(name), self.timeouts.service_timeout, 'perception')

    def other_objects(self, exclude: str) -> list[ObjectReport] | None:
        """Every object perception knows of (seen now or remembered) but `exclude`; None when it cannot list them."""
        if not self.perception.names_available():
            return None
        names = self.answer(self.perception.object_names(visible_only=False), self.timeouts.service_timeout,
                            'perception')
        reports = [self.object_state(name) for name in names if name != exclude]
        return [report for report in reports if report.success]

    def objects_in_view(self, exclude: str) -> list[ObjectInfo] | None:
        """The other objects in view: the carried object passes over them and the fingers keep clear of them.

        Objects perception only remembers (not in view now) are left out: their last known place may be stale.
        None when perception cannot list them.
        """
        others = self.other_objects(exclude)
        return None if others is None else [report.info for report in others if report.visible]

    def current_joints(self) -> np.ndarray:
        return np.asarray(self.wait(self.arm.joints(), self.timeouts.server_timeout,
                                    f'{self.arm.joints_description} is not available'), dtype=float)

    # ------------------------------------------------------------------------------------------- plan and run
    def plan(self, request: PickPlaceRequest) -> PickPlacePlan:
        found = self.object_state(request.object_name)
        if not found.success:
            raise Failed(PickPlaceErrorCode.OBJECT_NOT_FOUND, found.message or
                          f'no object named {request.object_name!r}')
        target: ObjectInfo | Sequence[float]
        if request.target_name:
            target_found = self.object_state(request.target_name)
            if not target_found.success:
                raise Failed(PickPlaceErrorCode.TARGET_NOT_FOUND, target_found.message or
                              f'no object named {request.target_name!r}')
            target = target_found.info
        else:
            target = request.target_xy
        others = self.objects_in_view(found.info.name)
        obstacle_height = max((other.top for other in others), default=None) if others is not None else None
        return plan_pick_place(found.info, target, self.current_joints(), self.executor.config, obstacle_height,
                               others or ())

    def execute(self, plan: PickPlacePlan, feedback: FeedbackCallback) -> None:
        observation = Observation()
        done = 0.0
        for stage in plan.stages:
            self.check_interrupted()
            feedback(stage.name, float(done))
            opening = None  # a gripper goal running beside the stage's motions
            for step in stage.steps:
                if isinstance(step, TrajectoryStep):
                    self.move(plan, step, stage.name)
                elif step.wait:
                    self.grip_result(self.grip(step), observation)
                else:
                    opening = self.grip(step)
            if opening is not None:
                self.grip_result(opening, observation)
            if stage.name == StageName.RETREAT:
                # The outcome is judged on what perception sees after the retreat, not on what it last saw.
                if not self.wait_for_fresh_view(plan.object.name, warn=plan.look_again is None) \
                        and plan.look_again is not None:
                    self.executor.log('info', f'the {plan.object.name} is hidden from the camera after placing; '
                                      f'moving the arm out of its view to look again')
                    self.move(plan, plan.look_again, stage.name)
                    self.wait_for_fresh_view(plan.object.name)
            self.check(plan, stage, observation)
            done = stage.progress
        feedback(plan.stages[-1].name, 1.0)

    def back_off(self, plan: PickPlacePlan) -> None:
        """After a missed grasp: open the fingers, lift straight back up (the plan's lift), out of the camera's view
        where the plan has a place for that, and wait for perception to see the object from there."""
        self.grip_result(self.grip(GripperStep(plan.config.gripper_open_width)), Observation())
        for stage in plan.stages:
            if stage.name == StageName.LIFT:
                for step in stage.steps:
                    if isinstance(step, TrajectoryStep):
                        self.move(plan, step, StageName.LIFT)
        if plan.look_again is not None:
            self.move(plan, plan.look_again, StageName.LIFT)
        self.wait_for_fresh_view(plan.object.name, warn=False)

    def move(self, plan: PickPlacePlan, step: TrajectoryStep, stage: StageName) -> None:
        trajectory = plan.trajectory_for(step, self.current_joints())
        if len(trajectory) < 2:
            return
        self.available(self.arm.server_ready(), self.arm.server_description)
        goal = self.arm.follow(trajectory, step.contact_tolerance if step.stop_on_contact else None)
        self.send(goal, 'the arm controller', 'the arm controller refused the trajectory')
        outcome: ArmOutcome = self.answer(goal.result, trajectory.duration + self.timeouts.motion_timeout_margin,
                                          'the arm controller')
        self.active = None
        if outcome.result == ArmResult.SUCCEEDED:
            return
        if step.stop_on_contact and outcome.result == ArmResult.TOLERANCE_VIOLATED:
            # Touched down before the planned height (on the way, or in the last millimetres, where the arm ends
            # a few milliradians short of its goal): placing ends here.
            self.executor.log('debug', f'touched down: {outcome.message}')
            return
        raise Failed(PickPlaceErrorCode.UNKNOWN,
                     f'the arm did not complete its motion ({stage.value}): {outcome.message}')

    def grip(self, step: GripperStep) -> PendingGoal | None:
        """Send the gripper command (None when the step is skipped: the fingers are open enough already)."""
        if step.unless_open_at_least is not None:
            opening = self.arm.opening()
            if opening is not None and opening >= step.unless_open_at_least:
                return None
        self.available(self.gripper.server_ready(), self.gripper.server_description)
        goal = self.gripper.command(step.position, step.max_effort)
        self.send(goal, 'the gripper', 'the gripper refused the command')
        return goal

    def grip_result(self, goal: PendingGoal | None, observation: Observation) -> None:
        """Wait for the gripper command's end (if one was sent) and note the fingers' outcome.

        A command running beside a motion is no longer the active goal (the motion is): an interruption cancels the
        motion, and the fingers, which were only opening, finish on their own.
        """
        if goal is None:
            return
        outcome: GripperOutcome = self.answer(goal.result, self.timeouts.gripper_timeout, 'the gripper')
        if self.active is goal:
            self.active = None
        observation.gripper_position = outcome.width
        observation.gripper_stalled = outcome.stalled

    def wait_for_fresh_view(self, name: str, warn: bool = True) -> bool:
        """Wait until perception answers from an observation made after the retreat (and so after the tool cleared
        the camera's view, with clear_view); False if that observation does not show the object.

        Otherwise the check after it, and the next command, would see the placed object where perception last saw
        it (a camera: before the tool moved out of its view; the simulator's objects: up to a publishing period
        ago). A source without time stamps (stamp 0, e.g. a stub) is not waited for.
        """
        cleared_at = self.arm.state_time()
        if cleared_at is None:
            return True
        deadline = time.monotonic() + self.timeouts.view_timeout
        while True:
            report = self.object_state(name)
            if not report.success:
                return True  # perception no longer knows it: the check says so
            if report.stamp == 0.0:
                return True
            if report.stamp >= cleared_at:
                if not report.visible and warn:
                    self.executor.log('warning', f'the {name} is out of the camera\'s sight after placing; its '
                                      f'position is the one last seen')
                return report.visible
            if time.monotonic() > deadline:
                self.executor.log('warning', f'perception saw nothing newer than the place within '
                                  f'{self.timeouts.view_timeout:.0f} s; going on with what it has')
                return True
            # A timed retry: perception offers no event for "an observation newer than t".
            self.pause(FRESH_VIEW_RETRY)

    def check(self, plan: PickPlacePlan, stage: Stage, observation: Observation) -> None:
        if not stage.checks:
            return
        if not any(isinstance(step, GripperStep) for step in stage.steps):
            opening = self.arm.opening()
            if opening is not None:
                observation.gripper_position = opening
        if any(check.needs_object_position for check in stage.checks):
            seen = self.object_state(plan.object.name)
            observation.object_position = seen.position if seen.success else None
            observation.object_visible = bool(seen.success and seen.visible)
        for check in stage.checks:
            failure = check.failure(observation)
            if failure:
                raise Failed(stage.failure_code, failure)
