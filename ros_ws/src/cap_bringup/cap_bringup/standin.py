"""A hardware stand-in: a second simulator playing the robot a hardware profile describes, for a graph in hardware
mode to drive (`cap standin PROFILE`, or `StandIn` in a test's process).

It runs, in one process and on its own wall clock (no /clock, real time), what the real robot's side would run:
- the sim bridge as that robot's drivers (cap_sim_bridge.standin): the arm's trajectory controller, the gripper's
  action controller in the profile's units, the joint states, and the camera's colour, depth (16UC1, noisy) and
  camera_info under the profile's names, the camera driver's frames on tf; with objects, masses, friction, the
  camera's mount and depth that differ from the graph's own simulator; no ground truth, no reset service;
- robot_state, as the driver's robot_state_publisher: the robot's links on /tf;
- on a mobile robot, the navigation node as nav2: NavigateToPose and NavigateThroughPoses, the global costmap, and
  (from the bridge) map -> odom -> base_link.
The graph publishes the calibration's camera mount itself, as it would on the real robot. Whoever owns the stand-in
(a test) sees the world through `world` and resets it with `reset`; nothing of that is on the ROS graph.
"""
from __future__ import annotations

from typing import Any

from rclpy.executors import MultiThreadedExecutor
from rclpy.parameter import Parameter

from cap_bringup.graph import Spinner
from cap_hardware.profile import load_profile
from cap_lmp_ros.domains.registry import get_domain
from cap_lmp_ros.thread_watch import ThreadWatch
from cap_perception.config import PerceptionConfig


def standin_parameters(profile_path: str, seed: int = 0, objects: str = '', perturbation_seed: int = 0,
                       serve_gripper: bool = True) -> dict[str, dict[str, Any]]:
    """{node name: {parameter: value}} of the stand-in's nodes (the navigation node's only for a mobile robot)."""
    profile = load_profile(profile_path)
    domain = get_domain(profile.domain)
    camera = dict(domain.rgbd_perception).get('camera', PerceptionConfig().camera)
    arm, gripper = profile.arm, profile.gripper
    values = {
        'sim_bridge': {'scene': domain.scene, 'seed': seed, 'objects': objects, 'real_time': True,
                       'real_time_factor': 1.0, 'profile': str(profile.path), 'standin_camera': camera,
                       'perturbation_seed': perturbation_seed, 'serve_gripper': serve_gripper,
                       'arm_controller_action': arm.controller_action, 'joint_states_topic': arm.joint_states,
                       'gripper_action': gripper.action, 'gripper_open_position': gripper.open_position,
                       'gripper_closed_position': gripper.closed_position},
        'robot_state': {'scene': domain.scene, 'joint_states_topic': arm.joint_states},
    }
    if profile.navigation is not None:
        navigation = profile.navigation
        values['navigation'] = {'navigate_to_pose_action': navigation.navigate_to_pose,
                                'navigate_through_poses_action': navigation.navigate_through_poses,
                                'costmap_topic': navigation.costmap, 'joint_states_topic': arm.joint_states}
    return values


class StandIn:
    """The stand-in's nodes on `context`, spinning in a thread of their own until `close()`."""

    def __init__(self, context, profile_path: str, seed: int = 0, objects: str = '', perturbation_seed: int = 0,
                 serve_gripper: bool = True) -> None:
        from cap_control.navigation.node import NavigationNode
        from cap_sim_bridge.bridge_node import SimBridgeNode
        from cap_sim_bridge.robot_state_node import RobotStateNode

        classes = {'sim_bridge': SimBridgeNode, 'robot_state': RobotStateNode, 'navigation': NavigationNode}
        self.nodes: dict[str, Any] = {}
        self._watch = ThreadWatch(on_death=lambda failure: None)
        self.executor = MultiThreadedExecutor(num_threads=8, context=context)
        try:
            for name, values in standin_parameters(profile_path, seed, objects, perturbation_seed,
                                                   serve_gripper).items():
                node = classes[name](context=context, parameter_overrides=[
                    Parameter(key, value=value) for key, value in values.items()])
                self.nodes[name] = node
                self.executor.add_node(node)
        except BaseException:
            self.close()
            raise
        self._spinner = Spinner(self.executor, context, 'standin_executor', self._watch)
        self._spinner.start()

    @property
    def failure(self) -> str:
        """Why the stand-in's executor thread died ('' while it runs): a robot whose drivers stopped answering."""
        return self._watch.failure

    @property
    def world(self):
        """The stand-in's world: the truth about the robot and the objects, for the owner only."""
        return self.nodes['sim_bridge'].world

    def reset(self, seed: int, specs=None) -> list:
        """Put the objects (specs, or the seed's episode) on the table and the robot at home."""
        return self.nodes['sim_bridge'].reset_world(seed, specs)

    def close(self) -> None:
        spinner = getattr(self, '_spinner', None)
        if spinner is not None:
            spinner.stop(5.0)
            spinner.finish(5.0)
        for node in reversed(list(self.nodes.values())):
            try:
                node.destroy_node()
            except Exception:  # shutting down: keep going with the other nodes
                pass
        self.nodes.clear()


__all__ = ['StandIn', 'standin_parameters']
