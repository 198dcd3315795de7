"""What a run of a generated controller may do, and the checks of every tick (plain Python, no ROS).

The controller node has no planning of its own; what it decides before and during a run is here: `make_run` turns
a RunController request into a `Run` (a known plant, a rate, duration and time budget in range, limits that may
only tighten the node's own `Limits`, which ControllerNodeConfig's parameters set), and each tick's state and output
are checked against those limits (`state_violation`, `check_output`) on the state vector a controller is sent
(`state_vector`). The loop that applies them is cap_control.controller.executor's.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Sequence

import numpy as np

from cap_control import kinematics
from cap_controllers import plants
from cap_ros_common.parameters import parameter
from cap_controllers.plants import ArmState, PlantSpec


@dataclasses.dataclass(frozen=True)
class Reading:
    """The plant's joints at one instant: time [s], positions and velocities in the plant's joint order."""

    time: float
    positions: np.ndarray
    velocities: np.ndarray


class ControllerFailure(Exception):
    """One call of the controller failed; `kind` is the exception's type name, or 'ControllerOverrun'."""

    def __init__(self, kind: str, message: str) -> None:
        super().__init__(message)
        self.kind = kind


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


__all__ = ['ControllerFailure', 'ControllerNodeConfig', 'Limits', 'Reading', 'Run', 'RunError', 'check_output',
           'make_run', 'state_vector', 'state_violation']
