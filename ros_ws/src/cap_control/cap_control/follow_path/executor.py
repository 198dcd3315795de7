"""Carrying out a FollowPath request over ports to the arm and the tool's spring (plain Python, no ROS).

`PathExecutor.run` plans the whole path from the arm's joints before anything moves (cap_control.follow_path.plan:
a path off the surface or out of reach fails with nothing moved; a cancel or a stop while it plans ends the run
within one planning pass, a few hundredths of a second), then runs its motions one by one, reporting each
with the stroke, the points passed and the progress by length. With a touching tool it checks the tool's spring,
which the robot reports as a joint: after each landing the compression must come into the tool's band (the tool
touches the surface), and while a stroke is followed it must stay there (a tool that lifts off, or presses so hard
the spring bottoms out, fails the run with CONTACT_LOST and the arm halts). A cancel or a stop cancels the running
motion at once; the arm holds where it is.
"""
from __future__ import annotations

import abc
import time
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np
from cap_ros_common.parameters import parameter
from cap_whiteboard import tool as tools

from cap_control.follow_path.plan import (
    TOOL_NONE, PathConfig, PathError, PathErrorCode, PathPlan, PathStep, StepKind, plan_path, rest_parts,
)
from cap_control.ports import (
    Arm, ArmOutcome, ArmResult, Ending, Failed, GoalRun, Interrupted, Interruption, WaitTimeouts,
    interruption_message,
)

# How often the spring is looked at while a stroke is followed [s of wall time] (joint states come at 100 Hz of
# simulated time); a compression out of band on this many looks in a row fails the stroke.
CONTACT_CHECK_PERIOD = 0.01
CONTACT_LOOKS = 3
# The goal tolerance of motions that press the tool on the surface [rad]: the spring's push bends the wrist a few
# milliradians off the commanded joints (more than the controller's default of 2 mrad with the side-mounted eraser).
CONTACT_GOAL_TOLERANCE = 0.008
# Samples of a stroke's motion sent to the arm in one goal, where the stroke stops often enough (1 minute of motion):
# building and sending a goal takes some 15 us per sample here and in the controller, so a stop waits at most about
# 50 ms for the goal in flight. A stroke with hours of corners goes a part at a time.
MAX_GOAL_SAMPLES = 3000


@dataclass(frozen=True)
class PathTimeouts:
    """How long the executor waits for each kind of answer; parameters of the follow_path node."""

    service_timeout: float = parameter(5.0, 'Longest wait for the arm to accept a goal or a cancel [s].')
    server_timeout: float = parameter(10.0, 'Longest wait for the arm\'s action server and joint state to appear '
                                      '[s].')
    motion_timeout_margin: float = parameter(120.0, 'Wall time allowed beyond a motion\'s planned duration before '
                                             'TIMEOUT [s].')
    landing_time: float = parameter(0.5, 'Simulated time a landed tool\'s spring may take to settle into its '
                                    'band [s].')


class ToolSpring(abc.ABC):
    """The tool's sprung slide, as the robot's joint states report it."""

    @abc.abstractmethod
    def compression(self, tool: str) -> float | None:
        """How far `tool`'s spring is compressed now [m]; None when the joint state does not have it."""

    @abc.abstractmethod
    def state_time(self) -> float | None:
        """Time stamp of the latest joint state [s], None if none came yet."""


@dataclass(frozen=True)
class PathRequest:
    strokes: Sequence[np.ndarray]  # each (N, 2): x, y [m]
    tool: str  # plan.TOOL_NONE, TOOL_MARKER or TOOL_ERASER (cap_control.follow_path.plan)
    speed: float = 0.0  # [m/s]; 0: the default


@dataclass(frozen=True)
class PathOutcome:
    ending: Ending
    code: PathErrorCode
    message: str = ''
    fraction: float = 1.0
    points_done: int = 0
    halt_confirmed: bool = True  # interrupted runs: whether the controller confirmed the cancel
    contact: list[float] = field(default_factory=list)  # the compressions seen while following [m]


@dataclass(frozen=True)
class PathProgress:
    stage: str
    stroke: int
    points_done: int
    points_total: int
    progress: float  # by length, in [0, 1]


FeedbackCallback = Callable[[PathProgress], None]


class PathExecutor:
    """Runs FollowPath requests one at a time over the ports."""

    def __init__(self, arm: Arm, spring: ToolSpring, config: PathConfig = PathConfig(),
                 timeouts: PathTimeouts = PathTimeouts(), stop_source: str = 'a stop request',
                 log: Callable[[str, str], None] | None = None):
        config.validate()
        self.arm, self.spring, self.config, self.timeouts = arm, spring, config, timeouts
        self.stop_source = stop_source
        self.log = log or (lambda level, message: None)

    def run(self, request: PathRequest, interruption: Interruption,
            feedback: FeedbackCallback = lambda progress: None) -> PathOutcome:
        run = _Run(self, interruption, request.tool)
        try:
            plan = run.plan(request)
            run.execute(plan, feedback)
            return PathOutcome(Ending.SUCCEEDED, PathErrorCode.NONE, '', plan.fraction, plan.points_total,
                               contact=run.contact)
        except Interrupted:
            confirmed = run.cancel_active_goal()
            ending = Ending.CANCELLED if interruption.reason == Ending.CANCELLED else Ending.STOPPED
            return PathOutcome(ending, PathErrorCode.CANCELLED,
                               interruption_message(ending, self.stop_source, confirmed,
                                                    self.timeouts.service_timeout),
                               points_done=run.points_done, halt_confirmed=confirmed, contact=run.contact)
        except PathError as error:
            self.log('warning', f'path refused: {error.message}')
            return PathOutcome(Ending.FAILED, error.code, error.message, error.fraction)
        except Failed as failure:
            run.cancel_active_goal()
            self.log('warning', f'path following failed: {failure.message}')
            return PathOutcome(Ending.FAILED, failure.code, failure.message, points_done=run.points_done,
                               contact=run.contact)


class _Run(GoalRun):
    """One request's plan, motions and contact checks."""

    def __init__(self, executor: PathExecutor, interruption: Interruption, tool: str):
        super().__init__(interruption, WaitTimeouts(executor.timeouts.service_timeout,
                                                    executor.timeouts.server_timeout),
                         PathErrorCode.TIMEOUT, PathErrorCode.CONTROLLER_FAILED)
        self.executor, self.arm, self.spring = executor, executor.arm, executor.spring
        self.timeouts = executor.timeouts
        self.tool = tool
        self.band = tools.compression_band(tool) if tool != TOOL_NONE else None
        self.points_done = 0
        self.contact: list[float] = []

    def plan(self, request: PathRequest) -> PathPlan:
        joints = self.wait(self.arm.joints(), self.timeouts.server_timeout,
                           f'{self.arm.joints_description} is not available')
        # A cancel or a stop ends a long plan at its next pass, with nothing sent.
        return plan_path(joints, request.strokes, request.tool, request.speed, self.executor.config,
                         check_interrupted=self.check_interrupted)

    def execute(self, plan: PathPlan, feedback: FeedbackCallback) -> None:
        total = max(plan.length_total, 1e-12)
        for step in plan.steps:
            self.check_interrupted()
            feedback(PathProgress(step.kind.value, step.stroke, step.points_before, plan.points_total,
                                  min(1.0, step.length_before / total)))
            self.move(step, plan, feedback)
            if step.kind == StepKind.FOLLOW:
                self.points_done = step.points_before + step.points
            if step.kind == StepKind.DESCEND and self.band is not None:
                self.wait_for_contact()
        feedback(PathProgress('done', len(plan.steps) and plan.steps[-1].stroke, plan.points_total,
                              plan.points_total, 1.0))

    def move(self, step: PathStep, plan: PathPlan, feedback: FeedbackCallback) -> None:
        if len(step.trajectory) < 2:
            return
        pressing = self.band is not None and step.kind in (StepKind.DESCEND, StepKind.FOLLOW)
        # A long stroke goes to the arm a part at a time, each ending where the tool stops at a corner anyway: no
        # goal takes long to build and send, so a stop is never kept waiting behind one.
        parts = rest_parts(step.trajectory, MAX_GOAL_SAMPLES) if step.kind == StepKind.FOLLOW else [step.trajectory]
        done = 0.0  # [s] of the step's trajectory
        for trajectory in parts:
            self.check_interrupted()
            self.available(self.arm.server_ready(), self.arm.server_description)
            goal = self.arm.follow(trajectory, None, CONTACT_GOAL_TOLERANCE if pressing else None)
            self.send(goal, 'the arm controller', 'the arm controller refused the trajectory')
            timeout = trajectory.duration + self.timeouts.motion_timeout_margin
            if step.kind == StepKind.FOLLOW:
                outcome = self.follow(goal.result, timeout, step, plan, feedback, done)
            else:
                outcome = self.answer(goal.result, timeout, 'the arm controller')
            self.active = None
            if outcome.result != ArmResult.SUCCEEDED:
                raise Failed(PathErrorCode.CONTROLLER_FAILED,
                             f'the arm did not complete its motion: {outcome.message}')
            done += trajectory.duration

    def follow(self, result, timeout: float, step: PathStep, plan: PathPlan,
               feedback: FeedbackCallback, done_before: float = 0.0) -> ArmOutcome:
        """Wait for (a part of) a stroke's motion, beginning `done_before` seconds into the stroke's trajectory,
        checking the spring and reporting progress as it goes."""
        deadline = time.monotonic() + timeout
        started = self.spring.state_time()
        out_of_band = 0
        last_stamp = None
        total = max(plan.length_total, 1e-12)
        condition = self.interruption.condition
        result.add_done_callback(self.interruption.notify)
        while not result.done():
            self.check_interrupted()
            if time.monotonic() > deadline:
                raise Failed(PathErrorCode.TIMEOUT, f'no answer from the arm controller within {timeout:.0f} s')
            with condition:  # the motion's end or an interruption wakes this early
                if not result.done() and self.interruption.reason is None:
                    condition.wait(CONTACT_CHECK_PERIOD)
            stamp = self.spring.state_time()
            if stamp is None or stamp == last_stamp:
                continue
            last_stamp = stamp
            if started is not None and step.trajectory.duration > 0:
                done = min(1.0, max(0.0, (stamp - started + done_before) / step.trajectory.duration))
                feedback(PathProgress(step.kind.value, step.stroke, step.points_before + int(done * step.points),
                                      plan.points_total, min(1.0, (step.length_before + done * step.length) / total)))
            if self.band is None:
                continue
            compression = self.spring.compression(self.tool)
            if compression is None:
                continue
            self.contact.append(compression)
            low, high = self.band
            out_of_band = out_of_band + 1 if not low <= compression <= high else 0
            if out_of_band >= CONTACT_LOOKS:
                what = 'lifted off the board' if compression < low else 'pressed the board too hard'
                raise Failed(PathErrorCode.CONTACT_LOST,
                             f'the {self.tool} {what} while following stroke {step.stroke} (spring compressed '
                             f'{compression * 1000:.1f} mm; kept within {low * 1000:.1f}-{high * 1000:.1f} mm)')
        self.check_interrupted()
        return result.result()

    def wait_for_contact(self) -> None:
        """After a landing: wait (at most landing_time of simulated time) until the spring is in its band."""
        low, high = self.band
        start = self.spring.state_time()
        compression = None
        while True:
            compression = self.spring.compression(self.tool)
            if compression is not None and low <= compression <= high:
                return
            now = self.spring.state_time()
            if start is None or now is None or now - start > self.timeouts.landing_time:
                break
            self.pause(CONTACT_CHECK_PERIOD)
        seen = 'unknown' if compression is None else f'{compression * 1000:.1f} mm'
        raise Failed(PathErrorCode.CONTACT_LOST,
                     f'the {self.tool} did not land on the board (spring compressed {seen}; expected '
                     f'{low * 1000:.1f}-{high * 1000:.1f} mm)')


__all__ = ['CONTACT_CHECK_PERIOD', 'FeedbackCallback', 'MAX_GOAL_SAMPLES', 'PathExecutor', 'PathOutcome',
           'PathProgress', 'PathRequest', 'PathTimeouts', 'ToolSpring']
