"""Navigation through ROS: nav2's NavigateToPose action, as the navigation node serves it under nav2's name, drives
the simulated mobile base in the kitchen.

The graph is the real one: the MuJoCo sim bridge with the kitchen scene (the base on its servos, the furniture it
collides with) and the navigation node, over DDS, at twice real time. Outcomes are judged on the simulator's state.
"""
from __future__ import annotations

import math

import pytest
from action_msgs.msg import GoalStatus
from cap_mobile import layout
from cap_ros_common.qos import LATCHED_QOS
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import OccupancyGrid
from rclpy.action import ActionClient
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from std_msgs.msg import Empty

from cap_control import ros_conversions as conv
from cap_control.navigation.plan import NavigateErrorCode, wrap_angle
from cap_control.navigation.node import NavigationNode
from cap_interfaces.msg import GraphNames
from nav2_msgs.action import NavigateToPose
from cap_sim_bridge.bridge_node import SimBridgeNode

WAIT = 60.0  # [s] wall time, far beyond a drive across the kitchen at twice real time
Result = NavigateErrorCode


@pytest.fixture
def graph(ros_context, spin_until):
    context = ros_context
    bridge = SimBridgeNode(context=context, parameter_overrides=[
        Parameter('scene', value='mobile'), Parameter('camera_rate', value=0.0),
        Parameter('real_time', value=True), Parameter('real_time_factor', value=2.0)])
    navigation = NavigationNode(context=context, parameter_overrides=[Parameter('use_sim_time', value=True)])
    client = Node('navigation_test_client', context=context)
    action = ActionClient(client, NavigateToPose, GraphNames.NAVIGATE_TO_POSE_ACTION)
    stop = client.create_publisher(Empty, GraphNames.STOP_TOPIC, 10)
    executor = MultiThreadedExecutor(num_threads=8, context=context)
    for node in (bridge, navigation, client):
        executor.add_node(node)
    assert spin_until(executor, lambda: action.server_is_ready(), timeout=30.0)
    yield executor, bridge.world, action, stop, client
    executor.shutdown()
    for node in (client, navigation, bridge):
        node.destroy_node()


def send(spin_until, executor, action, feedback: list | None = None, **fields):
    future = action.send_goal_async(NavigateToPose.Goal(**fields), feedback_callback=(
        lambda msg: feedback.append(msg.feedback)) if feedback is not None else None)
    assert spin_until(executor, future.done, timeout=10.0)
    handle = future.result()
    assert handle.accepted
    return handle


def finish(spin_until, executor, handle):
    future = handle.get_result_async()
    assert spin_until(executor, future.done, timeout=WAIT)
    return future.result()


def pose_goal(x: float, y: float, yaw: float) -> PoseStamped:
    goal = PoseStamped()
    goal.header.frame_id = 'map'
    goal.pose.position.x, goal.pose.position.y = x, y
    goal.pose.orientation.z, goal.pose.orientation.w = math.sin(yaw / 2), math.cos(yaw / 2)
    return goal


def place(name: str) -> PoseStamped:
    """A named location's approach pose: what the robot API sends for goto_loc(name)."""
    return pose_goal(*layout.location(name).approach())


def test_the_base_drives_to_a_named_place_within_5_cm_and_0_05_rad_with_feedback(graph, spin_until):
    executor, world, action, *_ = graph
    feedback = []
    response = finish(spin_until, executor, send(spin_until, executor, action, feedback, pose=place('table')))
    assert response.status == GoalStatus.STATUS_SUCCEEDED, response.result.error_msg
    assert response.result.error_code == Result.NONE
    x, y, yaw = world.base_pose()
    goal = layout.location('table').approach()
    assert math.dist((x, y), goal[:2]) < 0.05
    assert abs(wrap_angle(yaw - goal[2])) < 0.05
    assert feedback, 'no feedback while driving'
    distances = [f.distance_remaining for f in feedback]
    assert distances[0] > 1.0 and distances[-1] < distances[0]
    assert all(f.current_pose.header.frame_id == 'world' for f in feedback)
    assert feedback[-1].navigation_time.sec + feedback[-1].navigation_time.nanosec > 0


def test_a_goal_inside_furniture_is_refused_as_unreachable_and_the_base_stays(graph, spin_until):
    executor, world, action, *_ = graph
    before = world.base_pose()
    table = layout.location('table')
    response = finish(spin_until, executor, send(spin_until, executor, action,
                                                 pose=pose_goal(table.centre[0], table.centre[1], 0.0)))
    assert response.status == GoalStatus.STATUS_ABORTED
    assert response.result.error_code == Result.UNREACHABLE
    assert 'inside an obstacle' in response.result.error_msg
    elsewhere = place('desk')
    elsewhere.header.frame_id = 'odom_of_another_robot'
    response = finish(spin_until, executor, send(spin_until, executor, action, pose=elsewhere))
    assert response.result.error_code == Result.TF_ERROR
    assert 'odom_of_another_robot' in response.result.error_msg, 'the frame is named'
    assert math.dist(world.base_pose()[:2], before[:2]) < 0.005


def test_the_map_reaches_a_late_subscriber_with_the_table_where_the_base_cannot_stand(graph, spin_until):
    executor, world, _, _, client = graph
    maps = []
    client.create_subscription(OccupancyGrid, GraphNames.COSTMAP_TOPIC, maps.append, LATCHED_QOS)
    assert spin_until(executor, lambda: maps, timeout=10.0)
    grid = conv.occupancy_grid(maps[0])
    table = layout.location('table')
    assert not grid.is_free(table.centre) and grid.is_free(world.base_pose()[:2])
    assert not grid.is_free((table.centre[0], table.footprint[1] - layout.BASE_RADIUS + 0.02)), 'inflated by the base'


def test_stop_halts_the_base_within_half_a_second_of_simulated_time(graph, spin_until):
    executor, world, action, stop, _ = graph
    handle = send(spin_until, executor, action, pose=place('desk'))
    assert spin_until(executor, lambda: math.hypot(*world.base_velocity()[:2]) > 0.3, timeout=WAIT), \
        'the base never got going'
    stopped_at = world.time
    stop.publish(Empty())
    response = finish(spin_until, executor, handle)
    assert response.status == GoalStatus.STATUS_ABORTED
    assert response.result.error_code == Result.CANCELLED
    assert spin_until(executor, lambda: world.time >= stopped_at + 0.5, timeout=10.0)
    halted = world.base_pose()
    assert math.hypot(*world.base_velocity()[:2]) < 0.01
    assert spin_until(executor, lambda: world.time >= stopped_at + 1.0, timeout=10.0)
    assert math.dist(world.base_pose()[:2], halted[:2]) < 0.002, 'the base still moved after 0.5 s'
    # The node serves the next goal.
    response = finish(spin_until, executor, send(spin_until, executor, action, pose=place('office chair')))
    assert response.result.error_code == Result.NONE, response.result.error_msg
