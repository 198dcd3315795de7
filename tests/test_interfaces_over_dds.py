"""The built cap_interfaces work over DDS from Python: a command topic and a cancellable action with feedback."""
from __future__ import annotations

import os
import threading

from action_msgs.msg import GoalStatus
from rclpy.action import ActionClient, ActionServer, CancelResponse, GoalResponse
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from std_msgs.msg import String

from cap_interfaces.action import ExecuteCommand
from cap_interfaces.msg import GraphNames, StatusEvent

COMMAND_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)


def test_every_test_is_isolated_on_localhost(ros_isolation):
    assert os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'LOCALHOST'
    assert 1 <= int(os.environ['ROS_DOMAIN_ID']) <= 101


def test_command_published_on_cap_command_is_received(ros_context, spin_until):
    sender = Node('command_sender', context=ros_context)
    receiver = Node('command_receiver', context=ros_context)
    executor = MultiThreadedExecutor(num_threads=4, context=ros_context)
    executor.add_node(sender)
    executor.add_node(receiver)
    received: list[str] = []
    receiver.create_subscription(String, GraphNames.COMMAND_TOPIC, lambda m: received.append(m.data), COMMAND_QOS)
    publisher = sender.create_publisher(String, GraphNames.COMMAND_TOPIC, COMMAND_QOS)
    try:
        assert spin_until(executor, lambda: publisher.get_subscription_count() == 1)
        publisher.publish(String(data='put the blocks in the bowls with matching colors'))
        assert spin_until(executor, lambda: received)
        assert received == ['put the blocks in the bowls with matching colors']
    finally:
        executor.shutdown()
        sender.destroy_node()
        receiver.destroy_node()


class _StagedCommandServer:
    """An ExecuteCommand server that reports three stages, then succeeds unless cancelled between stages."""

    def __init__(self, node: Node) -> None:
        self.may_finish = threading.Event()
        self.server = ActionServer(
            node, ExecuteCommand, GraphNames.EXECUTE_ACTION, self.execute,
            goal_callback=lambda goal: GoalResponse.ACCEPT,
            # The default cancel callback rejects every request.
            cancel_callback=lambda goal_handle: CancelResponse.ACCEPT)

    def execute(self, goal_handle):
        for stage in (StatusEvent.STAGE_RECEIVED, StatusEvent.STAGE_GENERATING, StatusEvent.STAGE_EXECUTING):
            feedback = ExecuteCommand.Feedback()
            feedback.status.command = goal_handle.request.command
            feedback.status.stage = stage
            goal_handle.publish_feedback(feedback)
        # Wait for the test's go-ahead or a cancel request, whichever comes first.
        while not self.may_finish.wait(0.01):
            if goal_handle.is_cancel_requested:
                goal_handle.canceled()
                return ExecuteCommand.Result(success=False, message='cancelled')
        goal_handle.succeed()
        return ExecuteCommand.Result(success=True, code="say('done')", message='done')


def _bring_up(ros_context):
    server_node = Node('execute_server', context=ros_context)
    client_node = Node('execute_client', context=ros_context)
    server = _StagedCommandServer(server_node)
    client = ActionClient(client_node, ExecuteCommand, GraphNames.EXECUTE_ACTION)
    executor = MultiThreadedExecutor(num_threads=4, context=ros_context)
    executor.add_node(server_node)
    executor.add_node(client_node)
    return server, client, executor, (server_node, client_node)


def _send(client, executor, spin_until, command, feedback):
    assert spin_until(executor, lambda: client.server_is_ready())
    goal_future = client.send_goal_async(ExecuteCommand.Goal(command=command),
                                         feedback_callback=lambda m: feedback.append(m.feedback.status.stage))
    assert spin_until(executor, goal_future.done)
    goal_handle = goal_future.result()
    assert goal_handle.accepted
    return goal_handle


def test_execute_action_sends_feedback_and_result(ros_context, spin_until):
    server, client, executor, nodes = _bring_up(ros_context)
    feedback: list[int] = []
    try:
        goal_handle = _send(client, executor, spin_until, 'say hello', feedback)
        assert spin_until(executor, lambda: len(feedback) == 3)
        server.may_finish.set()
        result_future = goal_handle.get_result_async()
        assert spin_until(executor, result_future.done)
        result = result_future.result()
        assert result.status == GoalStatus.STATUS_SUCCEEDED
        assert result.result.success and result.result.code == "say('done')"
        assert feedback == [StatusEvent.STAGE_RECEIVED, StatusEvent.STAGE_GENERATING, StatusEvent.STAGE_EXECUTING]
    finally:
        server.may_finish.set()
        executor.shutdown()
        for node in nodes:
            node.destroy_node()


def test_execute_action_can_be_cancelled(ros_context, spin_until):
    server, client, executor, nodes = _bring_up(ros_context)
    feedback: list[int] = []
    try:
        goal_handle = _send(client, executor, spin_until, 'stack all the blocks', feedback)
        assert spin_until(executor, lambda: len(feedback) == 3)
        cancel_future = goal_handle.cancel_goal_async()
        assert spin_until(executor, cancel_future.done)
        assert len(cancel_future.result().goals_canceling) == 1
        result_future = goal_handle.get_result_async()
        assert spin_until(executor, result_future.done)
        assert result_future.result().status == GoalStatus.STATUS_CANCELED
        assert result_future.result().result.success is False
    finally:
        server.may_finish.set()
        executor.shutdown()
        for node in nodes:
            node.destroy_node()


def test_graph_names_are_relative_so_a_namespace_moves_them(ros_context):
    names = {name: getattr(GraphNames, name) for name in dir(GraphNames)
             if name.isupper() and isinstance(getattr(GraphNames, name), str)}
    assert names and all(not value.startswith('/') for key, value in names.items() if key != 'CLOCK_TOPIC')
    assert GraphNames.CLOCK_TOPIC == '/clock'  # rclpy's time source subscribes to it by this name
    node = Node('names_check', namespace='/robot1', context=ros_context)
    try:
        publisher = node.create_publisher(String, GraphNames.COMMAND_TOPIC, COMMAND_QOS)
        assert publisher.topic_name == '/robot1/cap/command'
    finally:
        node.destroy_node()
