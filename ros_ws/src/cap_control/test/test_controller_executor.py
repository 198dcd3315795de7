"""The control loop against the MuJoCo world (its ports bound to the world directly, no ROS) and plain Python
controllers: a PD controller balances the cart-pole, an impedance controller holds the tool against a push, and
every way a controller can fail ends the run with a clear message and the plant made safe."""
from __future__ import annotations

import threading

import numpy as np
import pytest

from cap_control.controller.executor import ControlLoop, Outcome, PlantError
from cap_control.controller.plan import ControllerFailure, Reading, check_output, make_run
from cap_controllers import plants
from cap_controllers.plants import ArmState
from cap_sim_bridge.lockstep import Lockstep
from cap_sim_bridge.scenes import controllers as controller_scene
from cap_sim_bridge.world import World


class WorldPlant:
    """The loop's Plant port on the world itself, through the simulator's own lockstep (what ControlStep serves)."""

    def __init__(self, world: World, spec: plants.PlantSpec) -> None:
        self.world, self.spec = world, spec
        self.lockstep = Lockstep(world, 0.0, timeout_s=60.0)
        self.released = False

    def start(self):
        return self._answer(self.lockstep.start, self.spec.joints, self.spec.actuators)

    def step(self, efforts, duration):
        return self._answer(self.lockstep.step, self.spec.joints, self.spec.actuators, efforts, duration)

    def release(self):
        self.lockstep.release()
        self.released = True

    @staticmethod
    def _answer(request, *arguments):
        try:
            now, positions, velocities, _ = request(*arguments)
        except ValueError as refusal:  # what the ControlStep service answers with success = false
            raise PlantError(str(refusal)) from None
        return Reading(now, positions, velocities)


class PythonController:
    """The Controller port on a plain function of the state vector."""

    def __init__(self, function) -> None:
        self.function = function

    def call(self, state, budget_s):
        return self.function(state), 0.0


def pd_balance(state):
    x, x_dot, theta, theta_dot = plants.cartpole_state(state)
    return 1.0 * x + 2.0 * x_dot + 30.0 * theta + 6.0 * theta_dot


@pytest.fixture(scope='module')
def world():
    world = World(controller_scene.NAME, seed=1)
    yield world
    world.close()


def run_cartpole(world, function, seed=1, duration=2.0, stop=None, **options):
    world.reset(seed)
    plant = WorldPlant(world, plants.CARTPOLE)
    run = make_run('the controller', 'cartpole', 100.0, duration, 0.0, **options)
    return ControlLoop(plant, PythonController(function)).run(run, stop or threading.Event()), plant


@pytest.mark.parametrize('seed', [1, 2, 3])
def test_a_pd_controller_balances_the_cartpole_for_30_seconds(world, seed):
    result, plant = run_cartpole(world, pd_balance, seed=seed, duration=30.0)
    assert result.outcome is Outcome.SUCCESSFUL, result.message
    assert result.calls == 3000 and abs(result.simulated_time - 30.0) < 1e-6
    x, _, theta, _ = plants.cartpole_state(result.final_state)
    assert abs(theta) < 0.01 and abs(x) < 0.1
    assert plant.released


def test_without_a_controller_the_pole_falls_and_the_run_stops_at_the_limit(world):
    result, plant = run_cartpole(world, lambda state: 0.0, seed=1, duration=10.0)
    assert result.outcome is Outcome.LIMIT_VIOLATED and 'the pole leaned' in result.message
    assert plant.released
    force = world.controls([plants.CART_ACTUATOR])
    assert force[0] == 0.0  # the cart's motor is idle once the run ended


@pytest.mark.parametrize('output, words', [
    (float('nan'), 'not a finite number'), ('left', "returned 'left', not a number"), ([1.0, 2.0], 'returned 2 values'),
])
def test_a_bad_output_stops_the_run_with_a_clear_error(world, output, words):
    result, plant = run_cartpole(world, lambda state: output)
    assert result.outcome is Outcome.CONTROLLER_ERROR and words in result.message, result.message
    assert result.calls == 0 and plant.released


def test_an_exception_or_an_overrun_of_a_call_ends_the_run(world):
    def raising(state):
        raise ControllerFailure('ZeroDivisionError', 'ZeroDivisionError: division by zero (line 2 of ...)')

    result, plant = run_cartpole(world, raising)
    assert result.outcome is Outcome.CONTROLLER_ERROR and 'ZeroDivisionError' in result.message and plant.released

    def slow(state):
        raise ControllerFailure('ControllerOverrun', 'the controller took longer than its time budget of 5 ms')

    result, plant = run_cartpole(world, slow)
    assert result.outcome is Outcome.OVERRUN and 'time budget' in result.message and plant.released


def test_outputs_are_clamped_and_absurd_ones_stop_the_run(world):
    result, _ = run_cartpole(world, lambda state: 40.0 if state[0] < 0.045 else 0.0)  # 4x the motor: clamped
    assert result.saturated_calls == 5 and result.outcome is Outcome.LIMIT_VIOLATED
    result, _ = run_cartpole(world, lambda state: 1e6)
    assert result.outcome is Outcome.LIMIT_VIOLATED and 'more than 5 times its limit of 10' in result.message


def test_a_stop_request_ends_the_run_at_the_next_tick(world):
    stop = threading.Event()
    calls = []

    def stopping(state):
        calls.append(state[0])
        if len(calls) == 50:
            stop.set()
        return pd_balance(state)

    result, plant = run_cartpole(world, stopping, duration=10.0, stop=stop)
    assert result.outcome is Outcome.STOPPED and result.simulated_time <= 0.5 + 1e-9 and plant.released


def test_a_plant_that_fails_ends_the_run():
    class Broken:
        def start(self):
            return Reading(0.0, np.zeros(2), np.zeros(2))

        def step(self, efforts, duration):
            raise PlantError('the simulator did not answer within 1 s')

        def release(self):
            pass

    run = make_run('f', 'cartpole', 100.0, 1.0, 0.0)
    result = ControlLoop(Broken(), PythonController(pd_balance)).run(run, threading.Event())
    assert result.outcome is Outcome.PLANT_ERROR and 'did not answer' in result.message


def test_a_run_after_a_run_in_which_the_pole_fell_starts_at_the_seeded_start_and_balances(world):
    result, _ = run_cartpole(world, lambda state: 0.0, seed=2, duration=10.0)  # lets the pole fall
    assert result.outcome is Outcome.LIMIT_VIOLATED and 'the pole leaned' in result.message
    world.run_for(2.0)  # released, the pole falls on
    (_, fallen), _ = world.joint_state(plants.CARTPOLE_JOINTS)
    assert abs(fallen) > 0.5
    firsts = []

    def balancing(state):
        if not firsts:
            firsts.append(plants.cartpole_state(state))
        return pd_balance(state)

    for _ in range(2):  # no reset in between: each run starts from the seeded start
        firsts.clear()
        plant = WorldPlant(world, plants.CARTPOLE)
        result = ControlLoop(plant, PythonController(balancing)).run(
            make_run('the controller', 'cartpole', 100.0, 10.0, 0.0), threading.Event())
        assert result.outcome is Outcome.SUCCESSFUL, result.message
        assert firsts[0] == pytest.approx(controller_scene.initial_cartpole_state(2), abs=1e-9)


def test_a_plant_that_cannot_be_put_at_its_start_runs_nothing():
    class Unresettable:
        released = False

        def start(self):
            raise PlantError('a real cart-pole cannot be put back at a start')

        def step(self, efforts, duration):
            raise AssertionError('stepped a plant that did not start')

        def release(self):
            self.released = True

    called = []
    plant = Unresettable()
    run = make_run('balance()', 'cartpole', 100.0, 1.0, 0.0)
    result = ControlLoop(plant, PythonController(lambda state: called.append(state) or 0.0)).run(
        run, threading.Event())
    assert result.outcome is Outcome.PLANT_ERROR and result.calls == 0 and not called and plant.released
    assert result.message == ('balance() did not run: the plant could not be put at its start (a real cart-pole '
                              'cannot be put back at a start)')


def test_runs_out_of_range_are_refused_and_limits_only_tighten():
    with pytest.raises(ValueError, match='unknown plant'):
        make_run('f', 'pendulum', 100.0, 1.0, 0.0)
    with pytest.raises(ValueError, match='rate'):
        make_run('f', 'cartpole', 5000.0, 1.0, 0.0)
    with pytest.raises(ValueError, match='time budget'):
        make_run('f', 'cartpole', 100.0, 1.0, 0.5)
    run = make_run('f', 'cartpole', 0.0, 1.0, 0.0, max_pole_angle=1.0, max_effort=[4.0])
    assert run.rate == plants.DEFAULT_RATE and run.time_budget == pytest.approx(0.005)
    assert run.limits.max_pole_angle == plants.POLE_ANGLE_LIMIT and run.limits.effort == (4.0,)
    clamped, saturated = check_output(plants.CARTPOLE, 'f', 7.0, run.limits)
    assert clamped.tolist() == [4.0] and saturated


def impedance(goal: np.ndarray, stiffness: float = 500.0, damping: float = 60.0):
    def control(vector):
        state = ArmState.unpack(vector)
        error = plants.pose_error(goal, state.ee_pose)
        force = np.concatenate([stiffness * error[:3] - damping * state.ee_velocity[:3],
                                30.0 * error[3:] - 2.0 * state.ee_velocity[3:]])
        return state.jacobian.T @ force
    return control


def test_an_impedance_controller_yields_to_a_push_with_its_stiffness_and_returns(world):
    world.reset(1)
    goal = world.tcp_pose()
    plant = WorldPlant(world, plants.ARM)
    pushed = {}

    def controller(vector):
        elapsed = vector[0]
        if 'at' not in pushed and elapsed >= 0.5:
            world.push_tool([0.0, 20.0, 0.0], 2.0)
            pushed['at'] = elapsed
        if 2.4 <= elapsed < 2.41:
            pushed['displacement'] = ArmState.unpack(vector).ee_pose[:3, 3] - goal[:3, 3]
        return impedance(goal)(vector)

    result = ControlLoop(plant, PythonController(controller)).run(
        make_run('impedance', 'arm', 100.0, 4.0, 0.0), threading.Event())
    assert result.outcome is Outcome.SUCCESSFUL, result.message
    stiffness = 20.0 / pushed['displacement'][1]
    assert stiffness == pytest.approx(500.0, rel=0.10)
    final = ArmState.unpack(result.final_state).ee_pose[:3, 3]
    assert np.linalg.norm(final - goal[:3, 3]) < 0.005
    assert not world.arm_torque_mode  # released: back on the servos, holding
