"""/tf and /tf_static of the simulated graph, as RViz and a real robot's tools read them: every link of the robot where
the simulator has its body, to a millimetre, with the arm moved (and in the kitchen the base driven) to poses drawn
from a seed; the cameras' optical frames where the simulator renders from; map -> odom -> base_link for the base."""
from __future__ import annotations

import time

import numpy as np
import pytest
import rclpy

from cap_bringup.graph import Graph, GraphOptions
from cap_ros_common.tf import TfListener
from cap_ros_common.transforms import TransformError
from cap_sim_bridge.robot_state import RobotState
from cap_sim_bridge.urdf import robot_urdf

WAIT = 60.0


def _wait(predicate, timeout: float = WAIT) -> bool:
    deadline = time.monotonic() + timeout
    while not predicate() and time.monotonic() < deadline:
        time.sleep(0.02)
    return predicate()


def _at_rest(world) -> bool:
    arm = np.max(np.abs(world.joint_velocities())) < 1e-4
    return arm and (world.base is None or np.max(np.abs(world.base_velocity())) < 1e-4)


def _body_pose(world, name: str) -> np.ndarray:
    with world.lock:
        pose = np.eye(4)
        pose[:3, :3], pose[:3, 3] = world.data.body(name).xmat.reshape(3, 3), world.data.body(name).xpos
        return pose


def _tf_matches_the_bodies(tf, world, links) -> list[str]:
    """The links whose pose on tf (newest) is off the simulator's body by more than 1 mm or 1 mrad."""
    off = []
    for link in links:
        try:
            on_tf = tf.buffer.lookup('world', link)
        except TransformError as error:
            off.append(f'{link}: {error}')
            continue
        body = _body_pose(world, link)
        error_m = np.linalg.norm(on_tf[:3, 3] - body[:3, 3])
        angle = np.arccos(np.clip((np.trace(on_tf[:3, :3].T @ body[:3, :3]) - 1) / 2, -1, 1))
        if error_m > 1e-3 or angle > 1e-3:
            off.append(f'{link}: {error_m * 1000:.2f} mm, {angle * 1000:.2f} mrad')
    return off


@pytest.mark.parametrize('domain', ['tabletop', 'mobile'])
def test_every_link_on_tf_is_where_the_simulator_has_it(ros_context, domain):
    graph = Graph(ros_context, GraphOptions(domain=domain, camera_rate=1.0))
    user = rclpy.create_node('tf_test_listener', context=ros_context)
    graph.executor.add_node(user)
    tf = TfListener(user)
    world = graph.world
    try:
        links = [joint.child for joint in RobotState(robot_urdf(world.model)).joints]
        assert {'base', 'shoulder_link', 'wrist_3_link', 'flange', 'left_finger'} <= set(links)
        rng = np.random.default_rng(7)
        for _ in range(2):
            joints = world.joint_positions() + rng.uniform(-0.3, 0.3, 6)
            world.follow_trajectory([2.0], [joints])
            if world.base is not None:
                x, y, yaw = world.base_pose()
                world.follow_base_trajectory([4.0], [[x + rng.uniform(-0.4, 0.4), y + rng.uniform(-0.4, 0.4),
                                                      yaw + rng.uniform(-1.0, 1.0)]])
            _wait(lambda: not _at_rest(world), 5.0)
            assert _wait(lambda: _at_rest(world))
            # The newest transforms are of the world at rest once a few joint states have gone by.
            settled = world.time
            assert _wait(lambda: world.time > settled + 0.5)
            assert _wait(lambda: not _tf_matches_the_bodies(tf, world, links), 10.0), \
                _tf_matches_the_bodies(tf, world, links)
        for camera in world.scene.camera_names:  # the optical frames the images are stamped with
            assert _wait(lambda: tf.buffer.can_transform('world', f'{camera}_optical_frame'), 10.0), camera
            pose = tf.buffer.lookup('world', f'{camera}_optical_frame')
            assert np.allclose(pose, world.camera_pose(camera), atol=1e-4), camera
        if world.base is not None:  # REP-105: map -> odom -> base_link, base_link on the floor under the base
            x, y, yaw = world.base_pose()
            base_link = tf.buffer.lookup('map', 'base_link')
            assert np.allclose(base_link[:2, 3], (x, y), atol=1e-3) and abs(base_link[2, 3]) < 1e-9
            assert np.isclose(np.arctan2(base_link[1, 0], base_link[0, 0]), np.arctan2(np.sin(yaw), np.cos(yaw)),
                              atol=1e-3)
    finally:
        user.destroy_node()
        graph.close()
