"""The whiteboard through the real graph: commands draw and erase, the ink shows it, bad paths and stops are safe.

The graph is `cap up --domain whiteboard`'s (cap_bringup.graph): the MuJoCo bridge with the whiteboard scene, whose
ink is laid by the marker's contacts in the physics, perception on ground truth, follow_path, and lmp_node replaying
reference programs from a cassette written here. The ink is read the way a user reads it: from the bridge's GetInk
service (a PNG) and its ink topic, and in the top camera's image.
"""
from __future__ import annotations

import time

import cv2
import numpy as np
import pytest
import rclpy
from geometry_msgs.msg import Point
from rclpy.action import ActionClient
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Image
from std_msgs.msg import Empty

from cap_bench.whiteboard.ink_check import MAX_P95_MM, MIN_COVERAGE, check_drawing, check_erased
from cap_bench.whiteboard.shapes import square_around
from cap_bringup.graph import Graph, GraphOptions
from cap_interfaces.action import ExecuteCommand, FollowPath
from cap_interfaces.msg import GraphNames, Stroke
from cap_interfaces.srv import GetInk
from cap_lmp.cassette import Cassette, CassetteEntry, ANY_CONTEXT

SQUARE = square_around((0.05, -0.5), 0.03)
OBJECTS = 'red block, apple'  # placed by the seed away from the middle


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


@pytest.fixture
def whiteboard(ros_context, tmp_path, request):
    """The whiteboard graph with a cassette that draws and erases a 6 cm square, and a user node; simulating in
    real time with the indirect parameter True (a stop's latency is then milliseconds of simulated time too)."""
    program = f'square_pts = np.array({SQUARE.round(4).tolist()})\ndraw(square_pts)'
    entries = [CassetteEntry(lmp='whiteboard_ui', query='draw a 6 cm square right of the middle', context=ANY_CONTEXT,
                             completion=program, source='written by hand for the whiteboard test'),
               CassetteEntry(lmp='whiteboard_ui', query='erase the square', context=ANY_CONTEXT,
                             completion='erase(square_pts)', source='written by hand for the whiteboard test'),
               CassetteEntry(lmp='whiteboard_ui', query='draw a line off the board', context=ANY_CONTEXT,
                             completion='draw(np.array([[0.0, -0.5], [0.4, -0.5]]))',
                             source='written by hand for the whiteboard test')]
    cassette = Cassette(tmp_path / 'whiteboard.yaml', entries)
    cassette.save()
    graph = Graph(ros_context, GraphOptions(domain='whiteboard', cassette=str(cassette.path), objects=OBJECTS,
                                            seed=2, camera_rate=0.0, real_time=getattr(request, 'param', False)))
    user = rclpy.create_node('whiteboard_user', context=ros_context)
    graph.executor.add_node(user)
    try:
        yield graph, user
    finally:
        user.destroy_node()
        graph.close()


def _execute(user, command: str):
    client = getattr(user, '_execute_client', None) or ActionClient(user, ExecuteCommand, GraphNames.EXECUTE_ACTION)
    user._execute_client = client
    assert _wait(client.server_is_ready)
    handle = _call(client.send_goal_async(ExecuteCommand.Goal(command=command)))
    return _call(handle.get_result_async(), 300).result


def _ink(user) -> np.ndarray:
    client = user.create_client(GetInk, GraphNames.SIM_GET_INK_SERVICE)
    try:
        assert _wait(client.service_is_ready)
        answer = _call(client.call_async(GetInk.Request()))
        assert answer.success and answer.image.format == 'png'
        return cv2.imdecode(np.frombuffer(bytes(answer.image.data), np.uint8), cv2.IMREAD_GRAYSCALE)
    finally:
        user.destroy_client(client)


def test_a_square_drawn_by_a_command_is_in_the_ink_erase_removes_it_and_a_path_off_the_board_moves_nothing(
        whiteboard):
    graph, user = whiteboard
    topic_images = []
    user.create_subscription(Image, GraphNames.SIM_INK_TOPIC, topic_images.append,
                             QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                                        durability=DurabilityPolicy.TRANSIENT_LOCAL))
    before = graph.world.render('top', 320, 240)[0]

    result = _execute(user, 'draw a 6 cm square right of the middle')
    assert result.outcome == ExecuteCommand.Result.OUTCOME_DONE, result.message
    verdict = check_drawing(_ink(user), [SQUARE])
    assert verdict.success, verdict.reason
    assert verdict.p95_mm <= MAX_P95_MM and verdict.coverage >= MIN_COVERAGE
    # The ink topic carries the same drawing, and the top camera sees it on the board.
    assert _wait(lambda: topic_images and int((np.frombuffer(bytes(topic_images[-1].data), np.uint8) > 0).sum())
                 == verdict.ink_pixels, 10)
    after = graph.world.render('top', 320, 240)[0]
    assert int((np.abs(after.astype(int) - before.astype(int)).sum(axis=2) > 120).sum()) > 50

    result = _execute(user, 'erase the square')
    assert result.outcome == ExecuteCommand.Result.OUTCOME_DONE, result.message
    erased = check_erased(_ink(user))
    assert erased.success, erased.reason

    joints = graph.world.joint_positions()
    result = _execute(user, 'draw a line off the board')
    assert result.outcome == ExecuteCommand.Result.OUTCOME_ERROR
    assert 'off the board' in result.message and '(0.400, -0.500)' in result.message, result.message
    assert np.max(np.abs(graph.world.joint_positions() - joints)) < 1e-3, 'the arm moved'
    assert check_erased(_ink(user)).success


@pytest.mark.parametrize('whiteboard', [True], indirect=True)
def test_stop_halts_the_tool_within_half_a_second_of_simulated_time(whiteboard):
    graph, user = whiteboard
    world = graph.world
    client = ActionClient(user, FollowPath, GraphNames.FOLLOW_PATH_ACTION)
    stop = user.create_publisher(Empty, GraphNames.STOP_TOPIC, 10)
    assert _wait(client.server_is_ready)
    feedback = []
    line = [Point(x=-0.15, y=-0.45), Point(x=0.05, y=-0.45)]
    goal = FollowPath.Goal(strokes=[Stroke(points=line)], tool=FollowPath.Goal.TOOL_MARKER, speed=0.05)
    handle = _call(client.send_goal_async(goal, feedback_callback=lambda msg: feedback.append(msg.feedback)))
    assert handle.accepted
    # Mid-stroke: the pen on the board, drawing.
    assert _wait(lambda: feedback and feedback[-1].stage == 'follow' and feedback[-1].progress > 0.3, 120)
    stopped_at = world.time
    stop.publish(Empty())
    samples = []  # (simulated time, tool position) until 1.5 s after the stop
    while world.time < stopped_at + 1.5:
        samples.append((world.time, world.flange_pose()[:3, 3]))
        time.sleep(0.001)
    result = _call(handle.get_result_async(), 30).result
    assert result.error_code == FollowPath.Result.CANCELLED, result.error_msg
    rest = samples[-1][1]
    moving = [t for t, position in samples if np.linalg.norm(position - rest) > 0.0005]
    assert not moving or max(moving) - stopped_at <= 0.5, f'still moving {max(moving) - stopped_at:.3f} s after'
    # Nothing more was drawn, and the stroke ends short of its end point (0.05, -0.45).
    ink = world.ink_canvas.image()
    assert _wait(lambda: world.time > stopped_at + 2.5, 30)
    assert int((world.ink_canvas.image() != ink).sum()) == 0, 'ink was laid after the stop'
    inked_columns = np.nonzero(ink.any(axis=0))[0]
    assert len(inked_columns) and -0.25 + (inked_columns.max() + 1) * 0.001 < 0.05 - 0.02, 'not interrupted'
