"""The control loop of a generated controller: a fixed rate in simulated time, and limits the controller cannot reach.

Two ports, so that the loop runs the same against the simulator, a robot or fakes in tests:
- `Plant`: `step(efforts, duration)` applies efforts (zero-order hold) and returns the reading `duration` seconds
  of plant time later (the simulator steps in lockstep with the loop; 0 only reads); `release()` makes it safe.
- `Controller`: `call(state, budget_s)` evaluates the generated function on a state vector; returns its output and
  its own CPU time, or raises ControllerFailure (the function's exception, a stop past its budget, no answer).

Every tick: read the plant, check its state against the limits, ask the controller, check the output (a finite
number per actuator, not absurdly past the actuator's limit), clamp it to the limits, apply it for one period.
The loop ends when the duration has run, on a stop request, on a limit violation, on a bad output or a failed call
(an exception, an overrun, no answer), and on a plant that does not answer; in every case the plant is released
(made safe) before `run` returns. No rclpy here (controller_node binds the ports to ROS).
"""
from __future__ import annotations

import dataclasses
import enum
import math
import threading
import time
from typing import Callable, Protocol, Sequence

import numpy as np

from cap_control import kinematics
from cap_controllers import plants
from cap_ros_common.parameters import parameter
from cap_controllers.plants import ArmState, PlantSpec


class Outcome(enum.Enum):
    """How a run ended (controller_node maps these to RunController's error codes)."""

    SUCCESSFUL = 'successful'
    STOPPED = 'stopped'
    LIMIT_VIOLATED = 'limit_violated'
    CONTROLLER_ERROR = 'controller_error'
    OVERRUN = 'overrun'
    PLANT_ERROR = 'plant_error'


@dataclasses.dataclass(frozen=True)
class Reading:
    """The plant's joints at one instant: time [s], positions and velocities in the plant's joint order."""

    time: float
    positions: np.ndarray
    velocities: np.ndarray


class PlantError(Exception):
    """The plant did not answer or refused a step."""


class ControllerFailure(Exception):
    """One call of the controller failed; `kind` is the exception's type name, or 'ControllerOverrun'."""

    def __init__(self, kind: str, message: str) -> None:
        super().__init__(message)
        self.kind = kind


class Plant(Protocol):
    def step(self, efforts: Sequence[float], duration: float) -> Reading: ...

    def release(self) -> None: ...


class Controller(Protocol):
    def call(self, state: np.ndarray, budget_s: float) -> tuple[Sequence[float], float]: ...


@dataclasses.dataclass(frozen=True)
class Limits:
    """What the loop enforces. Plant-specific fields apply to their plant only."""

    effort: tuple[float, ...]  # per actuator: outputs are clamped to +-this
    max_pole_angle: float = plants.POLE_ANGLE_LIMIT  # [rad]
    max_cart_position: float = plants.RAIL_LIMIT  # [m]
    max_joint_speed: float = plants.ARM_JOINT_SPEED_LIMIT  # [rad/s]
    workspace_min: tuple[float, float, float] = plants.ARM_WORKSPACE_MIN  # the tool's box [m]
    workspace_max: tuple[float, float, float] = plants.ARM_WORKSPACE_MAX
    effort_stop_factor: float = plants.EFFORT_STOP_FACTOR  # an output past this multiple of its limit stops the run


@dataclasses.dataclass(frozen=True)
class Run:
    """One controller run: which function (by name, for messages), which plant, how fast, how long, what limits."""

    controller: str
    plant: PlantSpec
    rate: float  # [Hz of plant time]
    duration: float  # [s of plant time]
    time_budget: float  # [s] of the function's own CPU time per call
    limits: Limits


@dataclasses.dataclass
class Result:
    outcome: Outcome
    message: str
    simulated_time: float = 0.0
    start_time: float = 0.0  # [s] the plant's clock at the first tick
    calls: int = 0
    saturated_calls: int = 0
    call_seconds: list[float] = dataclasses.field(default_factory=list)  # wall time per call, as the loop saw it
    function_seconds: list[float] = dataclasses.field(default_factory=list)  # the function's own CPU time
    step_seconds: list[float] = dataclasses.field(default_factory=list)  # wall time per plant step
    final_state: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0))


@dataclasses.dataclass(frozen=True)
class Tick:
    """What feedback reports: plant time since the start, calls so far, the state and the output applied."""

    time: float
    calls: int
    state: np.ndarray
    output: np.ndarray


@dataclasses.dataclass(frozen=True)
class ControllerNodeConfig:
    """controller_node's parameters: the limits it enforces on every run (a goal may only tighten them) and how
    long it waits for the plant and the controller."""

    max_pole_angle: float = parameter(plants.POLE_ANGLE_LIMIT, "The cart-pole's largest lean [rad].")
    max_cart_position: float = parameter(plants.RAIL_LIMIT, "The cart's largest distance from the rail's centre [m].")
    max_joint_speed: float = parameter(plants.ARM_JOINT_SPEED_LIMIT, "The arm's fastest joint speed [rad/s].")
    workspace_min: tuple[float, ...] = parameter(plants.ARM_WORKSPACE_MIN, "Lower corner of the tool's box [m].")
    workspace_max: tuple[float, ...] = parameter(plants.ARM_WORKSPACE_MAX, "Upper corner of the tool's box [m].")
    effort_stop_factor: float = parameter(plants.EFFORT_STOP_FACTOR, 'An output past this multiple of its '
                                          "actuator's limit stops the run (a smaller excess is clamped).")
    call_timeout: float = parameter(2.0, 'Longest wait for one call of the controller, round trip [s of wall '
                                    'time]: a backstop for a session that does not answer; the function\'s own '
                                    'time is bounded by the goal\'s time_budget, in the sandbox process.')
    plant_timeout: float = parameter(2.0, 'Longest wait for one step of the plant [s of wall time].')
    feedback_every: int = parameter(10, 'Feedback every this many ticks.')


class RunError(ValueError):
    """A run that cannot start (unknown plant, a rate or duration out of range, malformed limits)."""


def make_run(controller: str, plant_name: str, rate: float, duration: float, time_budget: float,
             max_pole_angle: float = 0.0, max_cart_position: float = 0.0, max_joint_speed: float = 0.0,
             max_effort: Sequence[float] = (), base: Limits | None = None) -> Run:
    """A Run from a request; limits given (> 0) may only tighten the plant's own. RunError says what is wrong."""
    try:
        plant = plants.plant(plant_name)
    except ValueError as error:
        raise RunError(str(error)) from None
    rate = rate or plants.DEFAULT_RATE
    if not (math.isfinite(rate) and plants.MIN_RATE <= rate <= plants.MAX_RATE):
        raise RunError(f'the rate must be within {plants.MIN_RATE:g}-{plants.MAX_RATE:g} Hz, not {rate:g}')
    if not (math.isfinite(duration) and 0 < duration <= plants.MAX_DURATION):
        raise RunError(f'the duration must be within 0-{plants.MAX_DURATION:g} s, not {duration:g}')
    budget = time_budget or plants.default_budget(rate)
    if not (math.isfinite(budget) and 0 < budget <= 1.0 / rate):
        raise RunError(f'the time budget must be more than 0 and at most one period ({1000.0 / rate:g} ms), '
                       f'not {budget * 1000:g} ms')
    base = base or Limits(effort=plant.effort_limits)
    effort = tuple(base.effort)
    if len(max_effort):
        if len(max_effort) != len(plant.actuators) or not all(math.isfinite(v) and v > 0 for v in max_effort):
            raise RunError(f'max_effort needs {len(plant.actuators)} positive values, one per actuator '
                           f'({", ".join(plant.actuators)})')
        effort = tuple(min(a, float(b)) for a, b in zip(effort, max_effort))

    def tighter(mine: float, asked: float) -> float:
        return min(mine, asked) if asked > 0 and math.isfinite(asked) else mine

    limits = dataclasses.replace(base, effort=effort,
                                 max_pole_angle=tighter(base.max_pole_angle, max_pole_angle),
                                 max_cart_position=tighter(base.max_cart_position, max_cart_position),
                                 max_joint_speed=tighter(base.max_joint_speed, max_joint_speed))
    return Run(controller or 'the controller', plant, float(rate), float(duration), float(budget), limits)


# ------------------------------------------------------------------------------------------------ state
def state_vector(plant: PlantSpec, elapsed: float, reading: Reading) -> np.ndarray:
    """The flat state vector a controller of `plant` is sent (cap_controllers.plants layout)."""
    if plant is plants.CARTPOLE:
        (x, theta), (x_dot, theta_dot) = reading.positions, reading.velocities
        return plants.cartpole_vector(elapsed, x, x_dot, theta, theta_dot)
    q, qd = np.asarray(reading.positions, dtype=float), np.asarray(reading.velocities, dtype=float)
    jacobian = kinematics.jacobian(q)
    return ArmState(time=elapsed, q=q, qd=qd, ee_pose=kinematics.forward_kinematics(q), ee_velocity=jacobian @ qd,
                    jacobian=jacobian).pack()


def state_violation(plant: PlantSpec, vector: np.ndarray, limits: Limits) -> str | None:
    """Why the state breaks a limit, in words; None when it does not."""
    if not np.all(np.isfinite(vector)):
        return 'the plant reported a state that is not a number'
    if plant is plants.CARTPOLE:
        x, _, theta, _ = plants.cartpole_state(vector)
        if abs(theta) > limits.max_pole_angle:
            return (f'the pole leaned {math.degrees(theta):.1f} degrees, past the limit of '
                    f'{math.degrees(limits.max_pole_angle):.1f}')
        if abs(x) > limits.max_cart_position:
            return f'the cart reached x = {x:.2f} m, past the limit of +-{limits.max_cart_position:g} m'
        return None
    state = ArmState.unpack(vector)
    fastest = int(np.argmax(np.abs(state.qd)))
    if abs(state.qd[fastest]) > limits.max_joint_speed:
        return (f'the {plant.joints[fastest]} turned at {abs(state.qd[fastest]):.2f} rad/s, past the limit of '
                f'{limits.max_joint_speed:g} rad/s')
    tool = state.ee_pose[:3, 3]
    if np.any(tool < limits.workspace_min) or np.any(tool > limits.workspace_max):
        return (f'the tool left the workspace at ({tool[0]:.3f}, {tool[1]:.3f}, {tool[2]:.3f}) m (box '
                f'{tuple(limits.workspace_min)} to {tuple(limits.workspace_max)})')
    return None


def check_output(plant: PlantSpec, name: str, output: object, limits: Limits) -> tuple[np.ndarray, bool]:
    """(the output clamped to the limits, whether it was clamped). Raises ControllerFailure for an output that is not
    a finite number per actuator, and ValueError (a limit violation) for one absurdly past an actuator's limit."""
    try:
        values = np.asarray(output, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        shown = repr(output)[:80]
        raise ControllerFailure('TypeError', f'{name} returned {shown}, not a number') from None
    wanted = len(plant.actuators)
    if values.size != wanted:
        what = 'one number (the force on the cart [N])' if plant is plants.CARTPOLE else \
            f'{wanted} numbers (the joint torques [N m])'
        raise ControllerFailure('ValueError', f'{name} returned {values.size} values; a {plant.name} controller '
                                              f'returns {what}')
    if not np.all(np.isfinite(values)):
        raise ControllerFailure('ValueError', f'{name} returned {values.tolist()}, which is not a finite number')
    bound = np.asarray(limits.effort, dtype=float)
    worst = int(np.argmax(np.abs(values) / bound))
    if abs(values[worst]) > limits.effort_stop_factor * bound[worst]:
        raise ValueError(f'{name} asked the {plant.actuators[worst]} actuator for {values[worst]:.4g}, more than '
                         f'{limits.effort_stop_factor:g} times its limit of {bound[worst]:g}')
    clamped = np.clip(values, -bound, bound)
    return clamped, bool(np.any(clamped != values))


# ------------------------------------------------------------------------------------------------ the loop
class ControlLoop:
    """Runs one controller to its end (see the module docstring)."""

    def __init__(self, plant: Plant, controller: Controller, clock: Callable[[], float] = time.perf_counter) -> None:
        self.plant = plant
        self.controller = controller
        self._clock = clock

    def run(self, run: Run, stop: threading.Event, feedback: Callable[[Tick], None] | None = None,
            feedback_every: int = 10) -> Result:
        result = Result(Outcome.SUCCESSFUL, '')
        period = 1.0 / run.rate
        ticks = max(1, int(round(run.duration * run.rate)))
        plant = run.plant
        output = np.zeros(len(plant.actuators))
        try:
            reading = self.plant.step([], 0.0)
            start = result.start_time = reading.time
            for tick in range(ticks + 1):
                elapsed = reading.time - start
                vector = state_vector(plant, elapsed, reading)
                result.simulated_time, result.final_state = elapsed, vector
                violation = state_violation(plant, vector, run.limits)
                if violation:
                    return self._end(result, Outcome.LIMIT_VIOLATED, f'{violation} at t = {elapsed:.2f} s')
                if stop.is_set():
                    return self._end(result, Outcome.STOPPED, f'stopped at t = {elapsed:.2f} s')
                if tick == ticks:
                    return self._end(result, Outcome.SUCCESSFUL, f'ran {run.controller} for {elapsed:.2f} s')
                called = self._clock()
                try:
                    value, own = self.controller.call(vector, run.time_budget)
                    if own > run.time_budget:  # the sandbox process stops the call at its budget; this is a backstop
                        raise ControllerFailure('ControllerOverrun', f'{run.controller} took {own * 1000:.3g} ms, '
                                                f'more than its time budget of {run.time_budget * 1000:.3g} ms')
                    output, saturated = check_output(plant, run.controller, value, run.limits)
                except ControllerFailure as failure:
                    outcome = Outcome.OVERRUN if failure.kind == 'ControllerOverrun' else Outcome.CONTROLLER_ERROR
                    return self._end(result, outcome, f'{failure} (call {tick + 1}, t = {elapsed:.2f} s)')
                except ValueError as excess:
                    return self._end(result, Outcome.LIMIT_VIOLATED, f'{excess} (t = {elapsed:.2f} s)')
                result.call_seconds.append(self._clock() - called)
                result.function_seconds.append(own)
                result.calls += 1
                result.saturated_calls += int(saturated)
                if feedback is not None and tick % feedback_every == 0:
                    feedback(Tick(elapsed, result.calls, vector, output))
                stepped = self._clock()
                reading = self.plant.step(output.tolist(), period)
                result.step_seconds.append(self._clock() - stepped)
        except PlantError as error:
            return self._end(result, Outcome.PLANT_ERROR, str(error))
        finally:
            self._release(result)
        return result  # not reached: the loop returns at its last tick

    @staticmethod
    def _end(result: Result, outcome: Outcome, message: str) -> Result:
        result.outcome, result.message = outcome, message
        return result

    def _release(self, result: Result) -> None:
        try:
            self.plant.release()
        except PlantError as error:  # the plant could not be told: say so, whatever the outcome was
            result.message += f'; making the plant safe failed: {error}'
            if result.outcome is Outcome.SUCCESSFUL:
                result.outcome = Outcome.PLANT_ERROR


def percentile(values: Sequence[float], share: float) -> float:
    """The `share` (0-1) quantile of `values` (0 for none)."""
    return float(np.quantile(np.asarray(values, dtype=float), share)) if len(values) else 0.0


__all__ = ['ControlLoop', 'Controller', 'ControllerFailure', 'ControllerNodeConfig', 'Limits', 'Outcome', 'Plant',
           'PlantError', 'Reading', 'Result', 'Run', 'RunError', 'Tick', 'check_output', 'make_run', 'percentile',
           'state_vector', 'state_violation']
