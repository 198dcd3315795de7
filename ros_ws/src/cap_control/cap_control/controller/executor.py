"""The control loop of a generated controller: a fixed rate in simulated time, and limits the controller cannot reach.

Two ports, so that the loop runs the same against the simulator, a robot or fakes in tests:
- `Plant`: `start()` puts the plant at its defined start, takes it over and returns the reading there (or raises
  PlantError saying why it cannot: then nothing runs); `step(efforts, duration)` applies efforts (zero-order hold)
  and returns the reading `duration` seconds of plant time later (the simulator steps in lockstep with the loop; 0
  only reads); `release()` makes it safe.
- `Controller`: `call(state, budget_s)` evaluates the generated function on a state vector; returns its output and
  its own CPU time, or raises ControllerFailure (the function's exception, a stop past its budget, no answer).

Every run starts from the plant's defined start (never from what the last run left: a fallen pole would end every
later run at t = 0). Every tick: read the plant, check its state against the limits, ask the controller, check the
output (a finite number per actuator, not absurdly past the actuator's limit), clamp it to the limits, apply it for
one period (the run, its limits and the checks are cap_control.controller.plan's).
The loop ends when the duration has run, on a stop request, on a limit violation, on a bad output or a failed call
(an exception, an overrun, no answer), and on a plant that does not answer; in every case the plant is released
(made safe) before `run` returns. No rclpy here (cap_control.controller.node binds the ports to ROS).
"""
from __future__ import annotations

import dataclasses
import enum
import threading
import time
from typing import Callable, Protocol, Sequence

import numpy as np

from cap_control.controller.plan import (
    ControllerFailure, Reading, Run, check_output, state_vector, state_violation,
)


class Outcome(enum.Enum):
    """How a run ended (the controller node maps these to RunController's error codes)."""

    SUCCESSFUL = 'successful'
    STOPPED = 'stopped'
    LIMIT_VIOLATED = 'limit_violated'
    CONTROLLER_ERROR = 'controller_error'
    OVERRUN = 'overrun'
    PLANT_ERROR = 'plant_error'


class PlantError(Exception):
    """The plant did not answer or refused a step."""


class Plant(Protocol):
    def start(self) -> Reading: ...

    def step(self, efforts: Sequence[float], duration: float) -> Reading: ...

    def release(self) -> None: ...


class Controller(Protocol):
    def call(self, state: np.ndarray, budget_s: float) -> tuple[Sequence[float], float]: ...


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
            try:
                reading = self.plant.start()
            except PlantError as error:
                return self._end(result, Outcome.PLANT_ERROR, f'{run.controller} did not run: the plant could not '
                                                              f'be put at its start ({error})')
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


__all__ = ['ControlLoop', 'Controller', 'Outcome', 'Plant', 'PlantError', 'Result', 'Tick', 'percentile']
