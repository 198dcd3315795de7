"""The mobile domain through the real graph: commands in language drive the simulated base around the kitchen.

The graph is `cap up --domain mobile`'s (cap_bringup.graph): the MuJoCo bridge with the kitchen scene, the
navigation node, and lmp_node replaying the packaged reference programs (the paper's navigation commands) and one
written here. Where the base went is read from the simulator while the commands run.
"""
from __future__ import annotations

import math
import threading
import time

import numpy as np
import pytest
import rclpy
from cap_mobile import layout, objects
from rclpy.action import ActionClient
from std_msgs.msg import String

from cap_bringup.graph import Graph, GraphOptions
from cap_interfaces.action import ExecuteCommand
from cap_interfaces.msg import GraphNames
from cap_lmp.cassette import ANY_CONTEXT, Cassette, CassetteEntry
from cap_lmp_ros.domains.registry import get_domain


def _wait(predicate, timeout: float = 60.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.01)
    return bool(predicate())


def _call(future, timeout: float = 60.0):
    assert _wait(future.done, timeout), 'no answer in time'
    return future.result()


def _graph_with(ros_context, cassette: Cassette, **options):
    """The mobile graph replaying `cassette`, and a user node on its executor; closed after the test."""
    cassette.save()
    options = {'camera_rate': 0.0, **options}  # no images unless a test needs them
    graph = Graph(ros_context, GraphOptions(domain='mobile', cassette=str(cassette.path), **options))
    user = rclpy.create_node('mobile_user', context=ros_context)
    graph.executor.add_node(user)
    try:
        yield graph, user
    finally:
        user.destroy_node()
        graph.close()


@pytest.fixture
def mobile(ros_context, tmp_path):
    """The mobile graph on the packaged cassette plus a command that sends the base into the table."""
    packaged = Cassette.load(get_domain('mobile').cassette)
    entries = packaged.entries() + [CassetteEntry(
        lmp='mobile_ui', query='drive onto the table', context=ANY_CONTEXT, completion="goto_pos(get_loc_pos('table'))",
        source='written by hand for the mobile graph test')]
    yield from _graph_with(ros_context, Cassette(tmp_path / 'mobile.yaml', entries))


def _execute(user, command: str):
    client = getattr(user, '_execute_client', None) or ActionClient(user, ExecuteCommand, GraphNames.EXECUTE_ACTION)
    user._execute_client = client
    assert _wait(client.server_is_ready)
    handle = _call(client.send_goal_async(ExecuteCommand.Goal(command=command)))
    return _call(handle.get_result_async(), 300).result


class PathRecorder:
    """The base's (x, y) every 20 ms of wall time while a command runs."""

    def __init__(self, world):
        self.world, self.points, self._stop = world, [], threading.Event()
        self._thread = threading.Thread(target=self._record, daemon=True)

    def _record(self):
        while not self._stop.is_set():
            self.points.append(self.world.base_pose()[:2].copy())
            time.sleep(0.02)

    def __enter__(self):
        self._thread.start()
        return self

    def __exit__(self, *_):
        self._stop.set()
        self._thread.join()


def test_commands_drive_the_base_to_a_place_and_around_a_rectangle_and_a_goal_in_furniture_is_refused(mobile):
    graph, user = mobile
    world = graph.world
    result = _execute(user, 'go to the table')
    assert result.outcome == ExecuteCommand.Result.OUTCOME_DONE, result.message
    goal = layout.location('table').approach()
    assert math.dist(world.base_pose()[:2], goal[:2]) < 0.05

    with PathRecorder(world) as recorder:
        result = _execute(user, 'move in a 3m by 2m rectangle around the office chair')
    assert result.outcome == ExecuteCommand.Result.OUTCOME_DONE, result.message
    path = np.array(recorder.points)
    centre = np.array(layout.location('office chair').centre)
    for corner in centre + np.array([[-1.5, -1.0], [1.5, -1.0], [1.5, 1.0], [-1.5, 1.0]]):
        assert np.linalg.norm(path - corner, axis=1).min() < 0.05, f'the base never reached the corner {corner}'
    # Around the chair, never through it: the whole path keeps the base's footprint off the chair's.
    x_min, y_min, x_max, y_max = layout.location('office chair').footprint
    gaps = np.hypot(np.maximum(0, np.maximum(x_min - path[:, 0], path[:, 0] - x_max)),
                    np.maximum(0, np.maximum(y_min - path[:, 1], path[:, 1] - y_max)))
    assert gaps.min() > layout.BASE_RADIUS

    before = world.base_pose()
    result = _execute(user, 'drive onto the table')
    assert result.outcome == ExecuteCommand.Result.OUTCOME_ERROR
    assert 'inside an obstacle' in result.message
    assert math.dist(world.base_pose()[:2], before[:2]) < 0.005, 'the base moved for a refused goal'
    result = _execute(user, 'how far are you from the desk')
    assert result.outcome == ExecuteCommand.Result.OUTCOME_DONE, result.message


def test_the_robot_counts_the_snacks_it_sees_on_the_table(mobile):
    """Perception answers from the head camera's view (a ray test in the simulator): the robot drives to the table,
    looks, and says how many snacks are there, as the simulator has them."""
    graph, user = mobile
    said = []
    user.create_subscription(String, GraphNames.SAY_TOPIC, lambda msg: said.append(msg.data), 10)
    world = graph.world
    snacks_on_table = [s.name for s in world.object_states() if objects.GROUPS[s.name] == objects.GROUP_SNACK
                       and objects.surface_of(*s.position[:2]) == 'table']
    assert snacks_on_table, 'the seed puts a snack on the table'
    result = _execute(user, 'how many snacks are on the table?')
    assert result.outcome == ExecuteCommand.Result.OUTCOME_DONE, result.message
    assert _wait(lambda: said, 10)
    assert f' {len(snacks_on_table)} snack' in said[-1]
    hidden = [s.name for s in world.object_states() if not s.visible]
    assert hidden, 'from the table the camera does not see everything'


COUNTER = layout.location('countertop')
COUNTER_SPOT = (COUNTER.centre[0] + 0.5, COUNTER.footprint[1] + 0.15)


@pytest.fixture
def fetch(ros_context, tmp_path):
    """The mobile graph with a coke can on the table and a program that brings it to the countertop."""
    program = f"pick_obj('coke can')\nplace_at_pos(np.array({list(COUNTER_SPOT)}))"
    cassette = Cassette(tmp_path / 'fetch.yaml', [CassetteEntry(
        lmp='mobile_ui', query='bring the coke can to the countertop', context=ANY_CONTEXT, completion=program,
        source='written by hand for the mobile graph test')])
    yield from _graph_with(ros_context, cassette, objects='coke can, apple, chips bag', seed=4)


def test_a_can_is_fetched_from_where_it_stands_and_put_down_on_the_countertop(fetch):
    """Fetch-and-place through the real graph: the base drives within reach of the can, the arm picks it, the base
    carries it across the kitchen, the arm sets it down; judged on the simulator's final state."""
    graph, user = fetch
    world = graph.world
    others = {s.name: s.position for s in world.object_states() if s.name != 'coke can'}
    result = _execute(user, 'bring the coke can to the countertop')
    assert result.outcome == ExecuteCommand.Result.OUTCOME_DONE, result.message
    world.run_for(0.5)
    can = world.object_state('coke can')
    assert math.dist(can.position[:2], COUNTER_SPOT) < 0.03
    assert can.bbox_min[2] == pytest.approx(COUNTER.top, abs=0.01), 'standing on the countertop'
    for name, position in others.items():
        assert math.dist(world.object_state(name).position, position) < 0.01, f'the {name} was moved'


@pytest.fixture
def rgbd(ros_context, tmp_path):
    """The mobile graph with perception from the kitchen's RGB-D detector on the head camera, and a program that
    drives to the table and says what it sees there and where."""
    program = ("goto_loc('table')\n"
               "for name in get_visible_obj_names():\n"
               "    x, y = get_obj_pos(name)\n"
               "    say(f'{name} at {x:.3f} {y:.3f}')\n"
               "say('that is all')")
    pick_and_put_back = ("name = sorted(get_visible_obj_names())[0]\n"
                         "start = get_obj_pos(name)\n"
                         "pick_obj(name)\n"
                         "place_at_pos(start)\n"
                         "say(name)")
    cassette = Cassette(tmp_path / 'look.yaml', [
        CassetteEntry(lmp='mobile_ui', query='what do you see on the table', context=ANY_CONTEXT, completion=program,
                      source='written by hand for the mobile graph test'),
        CassetteEntry(lmp='mobile_ui', query='pick up the first thing you see and put it back', context=ANY_CONTEXT,
                      completion=pick_and_put_back, source='written by hand for the mobile graph test')])
    yield from _graph_with(ros_context, cassette, seed=1, perception='rgbd', camera_rate=5.0)


def test_with_the_rgbd_detector_the_robot_sees_at_the_table_what_the_simulators_ray_test_sees(rgbd):
    """The API's visible objects come from the detector on the head camera's frames (analysed with the pose the
    camera had at each frame, while the base drives): at the table they are the objects the simulator's ray test
    says the camera sees, where the simulator has them."""
    graph, user = rgbd
    said = []
    user.create_subscription(String, GraphNames.SAY_TOPIC, lambda msg: said.append(msg.data), 10)
    result = _execute(user, 'what do you see on the table')
    assert result.outcome == ExecuteCommand.Result.OUTCOME_DONE, result.message
    assert _wait(lambda: said and said[-1] == 'that is all', 10)
    world = graph.world
    seen = {s.name: s.position for s in world.object_states() if s.visible}
    assert len(seen) >= 2, 'the seed puts objects in view at the table'
    reported = {}
    for line in said[:-1]:
        name, _, coordinates = line.rpartition(' at ')
        reported[name] = tuple(float(v) for v in coordinates.split())
    assert set(reported) == set(seen)
    for name, xy in reported.items():
        assert math.dist(xy, seen[name][:2]) < 0.02, name
    # Picked where the detector placed it, lifted over the base, and put back where it was.
    thing = sorted(reported)[0]
    start, others = world.object_state(thing).position, {n: p for n, p in seen.items() if n != thing}
    highest, done = [start[2]], threading.Event()

    def watch() -> None:
        while not done.is_set():
            highest[0] = max(highest[0], world.object_state(thing).position[2])
            time.sleep(0.05)

    watcher = threading.Thread(target=watch, daemon=True)
    watcher.start()
    try:
        result = _execute(user, 'pick up the first thing you see and put it back')
    finally:
        done.set()
        watcher.join()
    assert result.outcome == ExecuteCommand.Result.OUTCOME_DONE, result.message
    assert highest[0] > start[2] + 0.2, f'the {thing} was not lifted'
    assert math.dist(world.object_state(thing).position[:2], start[:2]) < 0.03
    for name, position in others.items():
        assert math.dist(world.object_state(name).position[:2], position[:2]) < 0.01, f'the {name} was moved'
