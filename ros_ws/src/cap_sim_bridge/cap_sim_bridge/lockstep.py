"""Lockstep stepping of a plant by a controller (the ControlStep service's logic; no ROS here).

While a controller steps the world, the simulator's own physics loop pauses and simulated time advances only by
the controller's requests: every step applies the controller's efforts for exactly one period, however long the
controller took to compute them, so the loop runs at a fixed rate in simulated time (as fast as possible, or paced
to the wall clock in real time).

A run begins with `start()`: the plant is put at its defined start, then taken over, in one request under one lock
(so nothing moves it in between): the scene's own joints (a cart-pole) back at the seeded start of the last reset,
at rest and held (World.restart_plant), the arm on its position servos and at rest where it is (within
ARM_SETTLE_LIMIT_S of simulated time). A plant that cannot be put there is refused with the reason, and nothing is
taken over: a run never starts from whatever the last run left (a fallen pole, an arm still swinging). Taking over
releases the scene's holds (a held pole) and, when the arm's actuators are named, puts the arm under torque control;
a first `step()` without `start()` takes over where the plant is. `release()` makes the plant safe: the named motors
idle, the arm back on its position servos holding where it is; the physics loop then runs freely again. A controller
that stops asking for `timeout_s` of wall time is released the same way (a crashed node must not leave the
simulation frozen with its last torques applied).
"""
from __future__ import annotations

import math
import threading
import time
from typing import Sequence

import numpy as np
from cap_controllers import plants

from cap_sim_bridge.pacing import Pacer
from cap_sim_bridge.world import ARM_JOINT_NAMES, World

MAX_STEP_DURATION = 1.0  # [s] of simulated time in one request
SETTLE_STEP = 0.01  # [s] of simulated time between looks at a settling arm


class Lockstep:
    def __init__(self, world: World, real_time_factor: float, timeout_s: float) -> None:
        self.world = world
        self.timeout_s = timeout_s
        self._pacer = Pacer(real_time_factor)
        self._lock = threading.Lock()  # one request at a time
        self._actuators: list[str] = []
        self._last_request = 0.0
        self.active = False
        self._dropped = ''  # why the last controller lost the plant for its silence (told at its next step)
        self.rest_speed = plants.ARM_REST_SPEED  # [rad/s] an arm slower than this is at rest
        self.settle_limit_s = plants.ARM_SETTLE_LIMIT_S  # [s of simulated time] for the arm to come to rest

    def start(self, joints: Sequence[str], actuators: Sequence[str]) -> tuple[float, np.ndarray, np.ndarray,
                                                                              np.ndarray]:
        """Put the plant of `joints` and `actuators` at its defined start and take it over (module docstring);
        (time, positions and velocities of `joints`, what the actuators apply), as `step` returns. ValueError
        saying why when it cannot be put there, a controller holds it already, or a name is unknown."""
        world = self.world
        with self._lock:
            if self.active:
                raise ValueError(f'a controller already drives {", ".join(self._actuators) or "the plant"}')
            self._dropped = ''  # a new run: the silent one's plant was made safe, and this one starts afresh
            with world.lock:
                self._check_names(joints, actuators)
                own = set(world.scene_joint_names())
                if own & set(joints):
                    world.restart_plant()
                if set(ARM_JOINT_NAMES) & set(joints) or set(world.arm_actuator_names) & set(actuators):
                    self._settle_arm()
                self._take_over(actuators)
                reading = self._read(joints, actuators)
            self._last_request = time.monotonic()
        return reading

    def _settle_arm(self) -> None:
        """The arm on its position servos, holding, at rest; ValueError when it is not within settle_limit_s."""
        world = self.world
        world.hold()
        settled = 0.0
        while (fastest := float(np.max(np.abs(world.joint_velocities())))) >= self.rest_speed:
            if settled >= self.settle_limit_s:
                raise ValueError(f'the arm did not come to rest on its servos within {self.settle_limit_s:g} s '
                                 f'(a joint still turned at {fastest:.3f} rad/s)')
            world.run_for(SETTLE_STEP)
            settled += SETTLE_STEP

    def step(self, joints: Sequence[str], actuators: Sequence[str], efforts: Sequence[float],
             duration: float) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
        """Apply `efforts` to `actuators` for `duration` seconds of simulated time; (time, positions and velocities
        of `joints`, what the actuators apply). ValueError for unknown names or malformed values."""
        efforts = np.asarray(efforts, dtype=float)
        if efforts.size and efforts.shape != (len(actuators),):
            raise ValueError(f'{efforts.size} efforts for {len(actuators)} actuators')
        if not np.all(np.isfinite(efforts)):
            raise ValueError('efforts must be finite numbers')
        if not (math.isfinite(duration) and 0 <= duration <= MAX_STEP_DURATION):
            raise ValueError(f'a step lasts 0 to {MAX_STEP_DURATION:g} s of simulated time, not {duration}')
        world = self.world
        with self._lock:
            if self._dropped:
                # The controller that fell silent must not carry on as if nothing happened; a new run starts with
                # a step that only reads (no efforts) or a start, which clears this.
                dropped, self._dropped = self._dropped, ''
                if efforts.size:
                    raise ValueError(dropped)
            with world.lock:
                self._check_names(joints, actuators)
                if not self.active:
                    self._take_over(actuators)
                elif list(actuators) != self._actuators and actuators:
                    raise ValueError(f'a controller already drives {", ".join(self._actuators)}')
                if efforts.size:
                    world.set_controls(actuators, efforts)
                world.run_for(duration)
                now, positions, velocities, applied = self._read(joints, actuators)
            self._last_request = time.monotonic()
            delay = self._pacer.delay(now)
        if delay > 0:  # real time: the next step waits for the wall clock (outside the lock: a release may come)
            time.sleep(delay)
        return now, positions, velocities, applied

    def _check_names(self, joints: Sequence[str], actuators: Sequence[str]) -> None:
        try:
            for name in joints:
                self.world.model.joint(name)
            for name in actuators:
                self.world.model.actuator(name)
        except KeyError as error:
            raise ValueError(f'unknown joint or actuator: {error}') from None
        arm = set(self.world.arm_actuator_names)
        if set(actuators) & arm and not set(actuators) <= arm:
            raise ValueError('the arm is stepped on its own')

    def _read(self, joints: Sequence[str], actuators: Sequence[str]) -> tuple[float, np.ndarray, np.ndarray,
                                                                               np.ndarray]:
        world = self.world
        positions, velocities = world.joint_state(joints)
        applied = world.controls(actuators) if actuators else np.zeros(0)
        return world.time, positions, velocities, applied

    def _take_over(self, actuators: Sequence[str]) -> None:
        world = self.world
        world.release_holds()
        if set(actuators) & set(world.arm_actuator_names):
            world.set_arm_torque_mode(True)
        self._actuators = list(actuators)
        self._pacer.restart()
        self._last_request = time.monotonic()  # before `active`: the physics loop reads both without the lock
        self.active = True

    def release(self, silent: bool = False) -> bool:
        """Make the plant safe and hand the world back to the physics loop; False if nothing was stepped.
        `silent`: the controller stopped asking (its next step is refused, saying so)."""
        with self._lock:
            if not self.active:
                return False
            if silent:
                self._dropped = (f'the plant was made safe after {self.timeout_s:g} s without a step from its '
                                 'controller')
            world = self.world
            with world.lock:
                arm = set(world.arm_actuator_names)
                motors = [name for name in self._actuators if name not in arm]
                if motors:
                    world.set_controls(motors, [0.0] * len(motors))
                if world.arm_torque_mode:
                    world.set_arm_torque_mode(False)
            self._actuators = []
            self.active = False
            return True

    def expired(self) -> bool:
        """True when a controller holds the world but has not asked for a step for `timeout_s` of wall time."""
        return self.active and time.monotonic() - self._last_request > self.timeout_s
