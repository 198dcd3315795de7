"""Generated controllers through the whole graph: the simulator (MuJoCo), controller_node, lmp_node and its sandbox
process, over DDS. The programs come from a cassette (the domain's reference programs, written by hand, plus the
misbehaving controllers below); the function generation LMP writes the PD controller and the impedance law.

What a user notices: the pole stays up for 30 s from several seeded starts, and again in the next run after it fell
(every run starts from the seeded start); a controller that returns NaN, raises
or takes too long is stopped with a message that says so, the cart's motor is switched off and the next command
runs; /cap/stop halts a controller within 0.5 s of simulated time; a tool held by impedance control yields to a
20 N push by 20 N / K and returns to within 5 mm of its goal.
"""
from __future__ import annotations

import threading
import time

import numpy as np
import pytest
import rclpy
from geometry_msgs.msg import Vector3
from rclpy.action import ActionClient
from sensor_msgs.msg import JointState
from std_msgs.msg import Empty, String

from cap_bringup.graph import Graph, GraphOptions
from cap_control import kinematics
from cap_controllers import plants
from cap_interfaces.action import ExecuteCommand
from cap_interfaces.msg import GraphNames
from cap_interfaces.srv import PushTool, ResetScene
from cap_lmp.cassette import ANY_CONTEXT, Cassette, CassetteEntry
from cap_lmp_ros.domains.controllers.domain import DOMAIN
from cap_ros_common.time import to_seconds

BALANCE = 'keep the pole upright with a PD controller for 30 seconds'
HOLD_SOFTLY = 'hold the tool softly for 20 seconds'
STIFFNESS = 500.0  # [N/m] of the test's impedance program
PUSH = 20.0  # [N]
MISBEHAVING = {
    'run a controller that returns nan': (
        'def controller(x, x_dot, theta, theta_dot):\n    return np.nan * theta\n'
        "run_controller(controller, rate=100, duration=5, plant='cartpole')"),
    'run a controller that divides by zero': (
        'def controller(x, x_dot, theta, theta_dot):\n    gain = 1.0 / (x - x)\n    return gain * theta\n'
        "run_controller(controller, rate=100, duration=5, plant='cartpole')"),
    'run a controller that takes its time': (
        'def controller(x, x_dot, theta, theta_dot):\n    n = 0\n    while n < 10 ** 9:\n        n += 1\n'
        "    return 0.0\nrun_controller(controller, rate=100, duration=5, plant='cartpole')"),
    'run a controller that lets the pole fall': (
        'def controller(x, x_dot, theta, theta_dot):\n    return 0.0\n'
        "run_controller(controller, rate=100, duration=5, plant='cartpole')"),
    HOLD_SOFTLY: (
        'goal_pose = get_ee_pose()\ndef controller(t):\n'
        f'    return ee_impedance_control(goal_pose, stiffness={STIFFNESS:g}, damping=60)\n'
        "run_controller(controller, rate=100, duration=20, plant='arm')"),
}


class User:
    """A client of the graph: commands through /cap/execute, /joint_states and what the robot says, recorded."""

    def __init__(self, context, graph: Graph) -> None:
        self.node = rclpy.create_node('controller_test_user', context=context)
        graph.executor.add_node(self.node)
        self.execute = ActionClient(self.node, ExecuteCommand, GraphNames.EXECUTE_ACTION)
        self.reset = self.node.create_client(ResetScene, GraphNames.SIM_RESET_SERVICE)
        self.push = self.node.create_client(PushTool, GraphNames.SIM_PUSH_TOOL_SERVICE)
        self.stop = self.node.create_publisher(Empty, GraphNames.STOP_TOPIC, 10)
        self.said: list[str] = []
        self.states: list[tuple[float, dict[str, tuple[float, float, float]]]] = []  # (time, name -> q, qd, effort)
        self._lock = threading.Lock()
        self.node.create_subscription(String, GraphNames.SAY_TOPIC, lambda m: self.said.append(m.data), 10)
        self.node.create_subscription(JointState, GraphNames.JOINT_STATES_TOPIC, self._on_joints, 100)
        assert wait(self.execute.server_is_ready) and wait(self.reset.service_is_ready)

    def _on_joints(self, message: JointState) -> None:
        joints = {name: (q, qd, effort) for name, q, qd, effort in
                  zip(message.name, message.position, message.velocity, message.effort)}
        with self._lock:
            self.states.append((to_seconds(message.header.stamp), joints))

    def latest(self) -> tuple[float, dict[str, tuple[float, float, float]]]:
        with self._lock:
            return self.states[-1] if self.states else (0.0, {})

    def since(self, start: float) -> list[tuple[float, dict[str, tuple[float, float, float]]]]:
        with self._lock:
            return [entry for entry in self.states if entry[0] >= start]

    def send(self, command: str):
        box = {}
        self.execute.send_goal_async(ExecuteCommand.Goal(command=command)).add_done_callback(
            lambda future: box.update(handle=future.result()))
        assert wait(lambda: 'handle' in box)
        return box['handle'].get_result_async()

    def run(self, command: str, timeout: float = 300.0) -> ExecuteCommand.Result:
        result = self.send(command)
        assert wait(result.done, timeout), f'{command!r} did not end'
        return result.result().result

    def reset_scene(self, seed: int) -> None:
        """Resets the scene and returns once the simulator has published the reset world twice (the first state
        may have left before the reset; a test reads `latest()` right after)."""
        with self._lock:
            published = len(self.states)
        future = self.reset.call_async(ResetScene.Request(seed=seed))
        assert wait(future.done) and future.result().success
        assert wait(lambda: len(self.states) >= published + 2), 'no joint states after the reset'

    def close(self) -> None:
        self.node.destroy_node()


def wait(predicate, timeout: float = 60.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.005)
    return predicate()


def tool_position(joints: dict[str, tuple[float, float, float]]) -> np.ndarray:
    return kinematics.forward_kinematics([joints[name][0] for name in plants.ARM_JOINTS])[:3, 3]


@pytest.fixture
def controllers(ros_context, tmp_path):
    """The controllers graph with the reference cassette and the misbehaving programs; a user of it."""
    cassette = Cassette.load(DOMAIN.cassette)
    cassette.path = tmp_path / 'controllers.yaml'
    for command, program in MISBEHAVING.items():
        cassette.add(CassetteEntry(lmp='controllers_ui', query=command, context=ANY_CONTEXT, completion=program,
                                   source='written by hand for the controller tests'))
    cassette.save()
    graph = Graph(ros_context, GraphOptions(domain='controllers', cassette=str(cassette.path)))
    user = User(ros_context, graph)
    try:
        yield graph, user
    finally:
        user.close()
        graph.close()


def test_a_generated_pd_controller_balances_the_pole_for_30_seconds_from_seeded_starts(controllers):
    _, user = controllers
    for seed in (1, 2, 3):
        user.reset_scene(seed)
        answer = user.run(BALANCE)
        assert answer.outcome == ExecuteCommand.Result.OUTCOME_DONE, f'seed {seed}: {answer.message}'
        assert 'keep_pole_upright_with_pd_control' in answer.code  # written by function generation
        assert user.said[-1] == 'The pole stayed up for 30.0 s'


def test_a_run_after_a_run_in_which_the_pole_fell_balances_again(controllers):
    _, user = controllers
    user.reset_scene(2)
    answer = user.run('run a controller that lets the pole fall')
    assert answer.outcome == ExecuteCommand.Result.OUTCOME_ERROR and 'the pole leaned' in answer.message

    def lean() -> float:
        return abs(user.latest()[1].get(plants.POLE_JOINT, (0.0, 0.0, 0.0))[0])

    assert wait(lambda: lean() > 0.5)  # the pole lies fallen: no reset of the scene from here on
    for _ in range(2):  # the cassette's PD program twice in a row, each from the seeded start
        answer = user.run(BALANCE)
        assert answer.outcome == ExecuteCommand.Result.OUTCOME_DONE, answer.message
        assert user.said[-1] == 'The pole stayed up for 30.0 s'


def test_a_misbehaving_controller_is_stopped_with_a_clear_error_and_the_cart_left_idle(controllers):
    _, user = controllers
    expected = {'run a controller that returns nan': 'returned [nan], which is not a finite number',
                'run a controller that divides by zero': 'ZeroDivisionError: float division by zero (line 2',
                'run a controller that takes its time': 'took longer than its time budget of 5 ms'}
    for command, words in expected.items():
        user.reset_scene(1)
        answer = user.run(command)
        assert answer.outcome == ExecuteCommand.Result.OUTCOME_ERROR, answer.message
        assert words in answer.message and "the cart's motor was switched off" in answer.message, answer.message
        ended, _ = user.latest()
        assert wait(lambda: any(t > ended for t, _ in user.states))
        later = [joints for t, joints in user.since(ended) if plants.CART_JOINT in joints]
        assert later and all(joints[plants.CART_JOINT][2] == 0.0 for joints in later)  # the motor is off
    # The session and the graph go on: the next controller balances.
    user.reset_scene(2)
    assert user.run(BALANCE).outcome == ExecuteCommand.Result.OUTCOME_DONE


def test_stop_halts_a_running_controller_within_half_a_second_of_simulated_time(controllers):
    _, user = controllers
    user.reset_scene(3)
    result = user.send(BALANCE)
    started, _ = user.latest()

    def pushing_for_a_second() -> bool:
        now, joints = user.latest()
        return now > started + 1.0 and joints.get(plants.CART_JOINT, (0, 0, 0))[2] != 0.0

    assert wait(pushing_for_a_second, 120)
    sent, _ = user.latest()  # the simulator was at `sent` or later when the stop went out
    user.stop.publish(Empty())
    assert wait(result.done, 60)
    answer = result.result().result
    assert answer.outcome == ExecuteCommand.Result.OUTCOME_CANCELLED, answer.message
    assert "the cart's motor was switched off" in answer.message
    assert wait(lambda: any(joints.get(plants.CART_JOINT, (0, 0, 1))[2] == 0.0 for _, joints in user.since(sent)))
    halted = min(t for t, joints in user.since(sent) if joints.get(plants.CART_JOINT, (0, 0, 1))[2] == 0.0)
    assert halted - sent <= 0.5


def test_an_impedance_controller_yields_to_a_push_by_its_stiffness_and_returns_to_its_goal(controllers):
    _, user = controllers
    user.reset_scene(1)
    before, joints = user.latest()
    goal = tool_position(joints)
    result = user.send(HOLD_SOFTLY)
    assert wait(lambda: user.latest()[0] > before + 1.5, 120)  # the controller holds the tool
    pushed = user.push.call_async(PushTool.Request(force=Vector3(x=0.0, y=PUSH, z=0.0), duration=3.0))
    assert wait(pushed.done) and pushed.result().success
    assert wait(result.done, 300)
    answer = result.result().result
    assert answer.outcome == ExecuteCommand.Result.OUTCOME_DONE, answer.message
    track = [(t, tool_position(joints) - goal) for t, joints in user.since(before)
             if all(name in joints for name in plants.ARM_JOINTS)]
    push_start = min(t for t, offset in track if offset[1] > 0.001)
    steady = [offset[1] for t, offset in track if push_start + 1.5 <= t <= push_start + 2.8]
    assert len(steady) > 10
    stiffness = PUSH / float(np.median(steady))
    assert stiffness == pytest.approx(STIFFNESS, rel=0.10)
    _, final = track[-1]
    assert np.linalg.norm(final) < 0.005  # back at its goal (and held there by the servos since)
