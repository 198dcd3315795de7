"""The sim bridge over real DDS: a client resets the scene, reads ground truth, moves the arm and the gripper
through the actions, and receives /clock, /joint_states and camera images of the configured size and encoding.
(Arm targets come from the control package's inverse kinematics.)"""
from __future__ import annotations

import os
import pathlib
import subprocess
import sys

import numpy as np
import pytest
from action_msgs.msg import GoalStatus
from builtin_interfaces.msg import Duration
from geometry_msgs.msg import Point
from rclpy.action import ActionClient
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import CameraInfo, Image, JointState
from trajectory_msgs.msg import JointTrajectoryPoint

from cap_control.kinematics import HOME_JOINTS, inverse_kinematics, top_down_pose
from cap_interfaces.msg import GraphNames, ObjectArray, ObjectSpec
from control_msgs.action import FollowJointTrajectory, GripperCommand
from control_msgs.msg import GripperCommand as GripperCommandMsg, JointTolerance
from cap_interfaces.srv import ResetScene
from cap_ros_common.tf import TfListener
from cap_sim_bridge.bridge_node import SimBridgeNode
from cap_sim_bridge.world import ARM_JOINT_NAMES, GRIPPER_JOINT_NAMES
from cap_tabletop.cameras import CAMERA_NAMES

WIDTH, HEIGHT = 320, 240
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
WAIT = 30.0  # [s] upper bound of any wait; the usual wait is far shorter
PROCESS_START_WAIT = 120.0  # [s] a new Python process importing ROS and MuJoCo on a busy 2-core machine
ROOT = pathlib.Path(__file__).resolve().parents[1]


class Client:
    """A test node that listens to everything the bridge publishes and talks to its service and actions."""

    def __init__(self, context) -> None:
        self.node = Node('sim_bridge_test_client', context=context)
        self.latest: dict[str, object] = {}
        self.objects: list[ObjectArray] = []
        node = self.node

        def keep(key):
            return lambda msg: self.latest.__setitem__(key, msg)

        node.create_subscription(Clock, GraphNames.CLOCK_TOPIC, keep('clock'), 10)
        node.create_subscription(JointState, GraphNames.JOINT_STATES_TOPIC, keep('joints'), 10)
        node.create_subscription(ObjectArray, GraphNames.SIM_OBJECTS_TOPIC, self.objects.append, LATCHED)
        for camera in CAMERA_NAMES:
            prefix = f'{GraphNames.CAMERA_NAMESPACE}/{camera}'
            # Sensor-data QoS, as a perception node would subscribe: it must work with the bridge's choice.
            node.create_subscription(Image, f'{prefix}/color', keep(f'{camera}/color'), qos_profile_sensor_data)
            node.create_subscription(Image, f'{prefix}/depth', keep(f'{camera}/depth'), qos_profile_sensor_data)
            node.create_subscription(CameraInfo, f'{prefix}/camera_info', keep(f'{camera}/info'), 10)
        self.tf = TfListener(node)
        self.reset = node.create_client(ResetScene, GraphNames.SIM_RESET_SERVICE)
        self.trajectory = ActionClient(node, FollowJointTrajectory, GraphNames.SIM_FOLLOW_JOINT_TRAJECTORY_ACTION)
        self.gripper = ActionClient(node, GripperCommand, GraphNames.SIM_GRIPPER_ACTION)

    def arm_positions(self) -> np.ndarray:
        joints = self.latest['joints']
        return np.array([joints.position[list(joints.name).index(n)] for n in ARM_JOINT_NAMES])


@pytest.fixture
def graph(ros_context):
    bridge = SimBridgeNode(context=ros_context, parameter_overrides=[
        Parameter('real_time', value=True), Parameter('real_time_factor', value=4.0),
        Parameter('image_width', value=WIDTH), Parameter('image_height', value=HEIGHT),
        Parameter('camera_rate', value=5.0)])
    client = Client(ros_context)
    executor = MultiThreadedExecutor(num_threads=6, context=ros_context)
    executor.add_node(bridge)
    executor.add_node(client.node)
    yield executor, bridge, client
    executor.shutdown()
    client.node.destroy_node()
    bridge.destroy_node()


def wait_for(spin_until, executor, future):
    assert spin_until(executor, future.done, timeout=WAIT)
    return future.result()


def send_goal(spin_until, executor, action_client, goal, feedback=None):
    assert action_client.wait_for_server(timeout_sec=WAIT)
    handle = wait_for(spin_until, executor, action_client.send_goal_async(goal, feedback_callback=feedback))
    assert handle.accepted
    return handle


def trajectory_goal(names, points):
    goal = FollowJointTrajectory.Goal()
    goal.trajectory.joint_names = list(names)
    for seconds, positions in points:
        goal.trajectory.points.append(JointTrajectoryPoint(
            positions=list(positions), time_from_start=Duration(sec=int(seconds),
                                                                nanosec=int(round(seconds % 1 * 1e9)))))
    return goal


def test_reset_ground_truth_trajectory_gripper_and_images(graph, spin_until):
    executor, _, client = graph
    assert spin_until(executor, lambda: 'clock' in client.latest and 'joints' in client.latest, timeout=WAIT)
    joints = client.latest['joints']
    assert list(joints.name) == list(ARM_JOINT_NAMES + GRIPPER_JOINT_NAMES)

    # Reset to a chosen scene; ground truth comes back in the response and on the objects topic.
    assert client.reset.wait_for_service(timeout_sec=WAIT)
    request = ResetScene.Request(seed=5, objects=[
        ObjectSpec(name='red block', category='block', color_name='red', use_position=True,
                   position=Point(x=0.0, y=-0.5, z=0.0)),
        ObjectSpec(name='blue bowl', category='bowl', color_name='blue')])
    response = wait_for(spin_until, executor, client.reset.call_async(request))
    assert response.success, response.message
    assert [o.name for o in response.objects] == ['red block', 'blue bowl']
    red = response.objects[0]
    assert (red.position.x, red.position.y) == pytest.approx((0.0, -0.5), abs=0.003)
    assert spin_until(executor, lambda: client.objects and
                      [o.name for o in client.objects[-1].objects] == ['red block', 'blue bowl'], timeout=WAIT)
    assert client.objects[-1].header.frame_id == 'world'

    # A joint trajectory through the action lowers the open gripper around the block: feedback while moving,
    # success, and /joint_states at the goal.
    above = inverse_kinematics(top_down_pose([0.0, -0.5, 0.15]), HOME_JOINTS)
    around = inverse_kinematics(top_down_pose([0.0, -0.5, red.position.z]), above)
    feedback = []
    handle = send_goal(spin_until, executor, client.trajectory,
                       trajectory_goal(ARM_JOINT_NAMES, [(2.0, above), (3.5, around)]),
                       lambda msg: feedback.append(msg.feedback))
    result = wait_for(spin_until, executor, handle.get_result_async())
    assert result.status == GoalStatus.STATUS_SUCCEEDED
    assert result.result.error_code == FollowJointTrajectory.Result.SUCCESSFUL
    assert feedback and list(feedback[-1].joint_names) == list(ARM_JOINT_NAMES)
    assert spin_until(executor, lambda: np.abs(client.arm_positions() - around).max() < 0.002, timeout=WAIT)

    # The gripper closes on the 4 cm block (stalls there, squeezing), then opens to 8 cm (reaches it).
    for opening, stalled_at in ((0.0, 0.04), (0.08, None)):
        handle = send_goal(spin_until, executor, client.gripper,
                           GripperCommand.Goal(command=GripperCommandMsg(position=opening, max_effort=10.0)))
        result = wait_for(spin_until, executor, handle.get_result_async())
        assert result.status == GoalStatus.STATUS_SUCCEEDED
        if stalled_at is None:
            assert result.result.reached_goal and not result.result.stalled
            assert result.result.position == pytest.approx(opening, abs=0.002)
        else:
            assert result.result.stalled and not result.result.reached_goal
            assert result.result.position == pytest.approx(stalled_at, abs=0.002)
            assert result.result.effort == pytest.approx(10.0, rel=0.05)
    joints = client.latest['joints']
    fingers = [joints.position[list(joints.name).index(n)] for n in GRIPPER_JOINT_NAMES]
    assert sum(fingers) == pytest.approx(0.08, abs=0.002)

    # Images of every camera with the configured size and encodings, matching camera_info, the pose on tf.
    keys = [f'{c}/{kind}' for c in CAMERA_NAMES for kind in ('color', 'depth', 'info')]
    assert spin_until(executor, lambda: all(k in client.latest for k in keys), timeout=WAIT)
    for camera in CAMERA_NAMES:
        color, depth = client.latest[f'{camera}/color'], client.latest[f'{camera}/depth']
        info = client.latest[f'{camera}/info']
        assert (color.width, color.height, color.encoding, color.step) == (WIDTH, HEIGHT, 'rgb8', WIDTH * 3)
        assert (depth.width, depth.height, depth.encoding, depth.step) == (WIDTH, HEIGHT, '32FC1', WIDTH * 4)
        assert len(color.data) == WIDTH * HEIGHT * 3 and len(depth.data) == WIDTH * HEIGHT * 4
        assert color.header.frame_id == depth.header.frame_id == info.header.frame_id == f'{camera}_optical_frame'
        assert (info.width, info.height) == (WIDTH, HEIGHT)
        assert info.k[2] == pytest.approx((WIDTH - 1) / 2) and info.k[5] == pytest.approx((HEIGHT - 1) / 2)
        metres = np.frombuffer(bytes(depth.data), dtype='<f4')
        assert np.all(np.isfinite(metres)) and 0.3 < float(np.median(metres)) < 3.0
        pixels = np.frombuffer(bytes(color.data), dtype=np.uint8).reshape(HEIGHT, WIDTH, 3)
        assert pixels.std() > 10, 'a real picture, not a blank frame'
    assert spin_until(executor, lambda: client.tf.buffer.can_transform('world', 'top_optical_frame'), timeout=WAIT)
    top_pose = client.tf.buffer.lookup('world', 'top_optical_frame')
    assert top_pose[:2, 3] == pytest.approx((0.0, -0.5))
    # Optical frame of a camera looking straight down: a half turn about x.
    assert np.allclose(top_pose[:3, :3], np.diag([1.0, -1.0, -1.0]), atol=1e-6)
    # Sim time is the time base: /clock is ahead of the start and images are stamped with it.
    clock = client.latest['clock'].clock
    assert clock.sec + clock.nanosec * 1e-9 > 2.0


def test_cancel_stops_the_arm_and_bad_goals_are_refused_with_a_reason(graph, spin_until):
    executor, _, client = graph
    assert spin_until(executor, lambda: 'joints' in client.latest, timeout=WAIT)
    start = client.arm_positions()
    far = start + np.array([1.0, 0.0, 0.0, 0.0, 0.0, 1.0])
    feedback = []
    handle = send_goal(spin_until, executor, client.trajectory, trajectory_goal(ARM_JOINT_NAMES, [(6.0, far)]),
                       lambda msg: feedback.append(msg.feedback))
    assert spin_until(executor, lambda: len(feedback) > 3 and
                      abs(client.arm_positions()[0] - start[0]) > 0.05, timeout=WAIT)
    wait_for(spin_until, executor, handle.cancel_goal_async())
    result = wait_for(spin_until, executor, handle.get_result_async())
    assert result.status == GoalStatus.STATUS_CANCELED
    assert spin_until(executor, lambda: np.abs(client.latest['joints'].velocity[:6]).max() < 1e-3, timeout=WAIT)
    stopped = client.arm_positions()
    clock_then = client.latest['clock'].clock.sec
    assert spin_until(executor, lambda: client.latest['clock'].clock.sec >= clock_then + 1, timeout=WAIT)
    assert np.abs(client.arm_positions() - stopped).max() < 0.002, 'the arm holds where it stopped'
    assert abs(stopped[0] - far[0]) > 0.3

    # A subset of joints is fine (the others hold); an unknown joint, a limit violation or a missed goal is not.
    handle = send_goal(spin_until, executor, client.trajectory,
                       trajectory_goal(['wrist_3_joint'], [(0.5, [stopped[5] + 0.2])]))
    result = wait_for(spin_until, executor, handle.get_result_async())
    assert result.status == GoalStatus.STATUS_SUCCEEDED
    handle = send_goal(spin_until, executor, client.trajectory,
                       trajectory_goal(['elbow_joint', 'gripper_joint'], [(1.0, [0.0, 0.0])]))
    result = wait_for(spin_until, executor, handle.get_result_async())
    assert result.status == GoalStatus.STATUS_ABORTED
    assert result.result.error_code == FollowJointTrajectory.Result.INVALID_JOINTS
    assert 'gripper_joint' in result.result.error_string
    handle = send_goal(spin_until, executor, client.trajectory, trajectory_goal(['elbow_joint'], [(1.0, [4.0])]))
    result = wait_for(spin_until, executor, handle.get_result_async())
    assert result.result.error_code == FollowJointTrajectory.Result.INVALID_GOAL
    assert 'limits' in result.result.error_string
    # A fast move whose micrometre tolerance must hold the instant it ends fails with GOAL_TOLERANCE_VIOLATED.
    rushed = trajectory_goal(ARM_JOINT_NAMES, [(0.3, client.arm_positions() + [0.4, 0, 0, 0, 0, 0])])
    rushed.goal_tolerance = [JointTolerance(name=n, position=1e-6) for n in ARM_JOINT_NAMES]
    rushed.goal_time_tolerance = Duration(sec=0, nanosec=1)
    handle = send_goal(spin_until, executor, client.trajectory, rushed)
    result = wait_for(spin_until, executor, handle.get_result_async())
    assert result.result.error_code == FollowJointTrajectory.Result.GOAL_TOLERANCE_VIOLATED
    assert 'shoulder_pan_joint' in result.result.error_string

    # A reset naming an unknown colour fails with the reason.
    response = wait_for(spin_until, executor, client.reset.call_async(ResetScene.Request(
        seed=1, objects=[ObjectSpec(name='violet block')])))
    assert not response.success and 'violet' in response.message


def test_a_camera_is_rendered_only_while_somebody_watches_it(ros_context, spin_until):
    """Rendering costs the physics thread more than the physics: no subscriber, no rendering; a colour subscriber
    to one camera gets frames of that camera, and depth is not rendered for it."""
    bridge = SimBridgeNode(context=ros_context, parameter_overrides=[
        Parameter('real_time', value=False), Parameter('image_width', value=WIDTH),
        Parameter('image_height', value=HEIGHT), Parameter('camera_rate', value=10.0)])
    rendered = []
    render = bridge.world.render

    def counted_render(camera, *args, **kwargs):  # the real renderer, counted
        rendered.append((camera, kwargs.get('with_depth')))
        return render(camera, *args, **kwargs)

    bridge.world.render = counted_render
    node = Node('camera_watcher', context=ros_context)
    executor = MultiThreadedExecutor(num_threads=4, context=ros_context)
    executor.add_node(bridge)
    executor.add_node(node)
    try:
        start = bridge.world.time
        assert spin_until(executor, lambda: bridge.world.time > start + 2.0, timeout=WAIT)
        assert rendered == [], 'cameras rendered with nobody watching'
        frames = []
        camera = CAMERA_NAMES[0]
        node.create_subscription(Image, f'{GraphNames.CAMERA_NAMESPACE}/{camera}/color', frames.append,
                                 qos_profile_sensor_data)
        assert spin_until(executor, lambda: len(frames) >= 3, timeout=WAIT)
        assert set(rendered) == {(camera, False)}
    finally:
        executor.shutdown()
        node.destroy_node()
        bridge.destroy_node()


def test_installed_entry_point_runs_as_fast_as_possible_with_the_packaged_parameter_file(ros_context, spin_until,
                                                                                         tmp_path):
    executable = ROOT / 'ros_ws' / 'install' / 'cap_sim_bridge' / 'lib' / 'cap_sim_bridge' / 'sim_bridge'
    params = ROOT / 'ros_ws' / 'install' / 'cap_sim_bridge' / 'share' / 'cap_sim_bridge' / 'config' / \
        'sim_bridge.yaml'
    log = (tmp_path / 'sim_bridge.log').open('wb')
    process = subprocess.Popen([sys.executable, str(executable), '--ros-args', '--params-file', str(params),
                                '-p', 'camera_rate:=0.0', '-p', 'seed:=4', '-p', 'real_time:=false'],
                               env=dict(os.environ), stdout=log, stderr=subprocess.STDOUT)
    node = Node('entry_point_probe', context=ros_context)
    executor = MultiThreadedExecutor(num_threads=4, context=ros_context)
    executor.add_node(node)
    received = []
    node.create_subscription(ObjectArray, GraphNames.SIM_OBJECTS_TOPIC, received.append, LATCHED)
    clocks = []
    node.create_subscription(Clock, GraphNames.CLOCK_TOPIC, clocks.append, 10)
    try:
        assert spin_until(executor, lambda: received and len(clocks) > 10, timeout=PROCESS_START_WAIT), \
            'no messages from the sim_bridge process'
        assert 6 <= len(received[-1].objects) <= 8
    finally:
        process.terminate()
        try:
            returncode = process.wait(timeout=WAIT)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
            returncode = None
        executor.shutdown()
        node.destroy_node()
        log.close()
    output = (tmp_path / 'sim_bridge.log').read_text()
    assert returncode == 0, output
    assert 'Traceback' not in output, output
