"""robot_state: the robot's links on /tf from /joint_states and its URDF, as robot_state_publisher does.

Publishes /robot_description (std_msgs/String, latched: robot_state_publisher's QoS) with the URDF written from the
simulator's model of the configured `scene` (cap_sim_bridge.urdf) unless `robot_description` gives one, the fixed
joints once on /tf_static, and the moving joints on /tf for every /joint_states message, stamped as that message.
The simulator stands in for a robot's drivers, and robot_state_publisher belongs to them: on a regular ROS 2
install `ros2 run robot_state_publisher robot_state_publisher` with the same URDF (`cap urdf`) publishes the same
transforms, and a real robot's driver brings its own.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from cap_interfaces.msg import GraphNames
from cap_ros_common.nodes import spin_node
from cap_ros_common.parameters import declare_config, parameter
from cap_ros_common.qos import LATCHED_QOS
from cap_ros_common.tf import TfBroadcaster
from cap_ros_common.time import to_seconds
from cap_sim_bridge.robot_state import RobotState
from cap_sim_bridge.scenes import DEFAULT_SCENE, build_model
from cap_sim_bridge.urdf import robot_urdf

JOINT_STATES_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)


@dataclass(frozen=True)
class RobotStateConfig:
    scene: str = parameter(DEFAULT_SCENE, 'Simulator scene whose robot model is described (when robot_description '
                                          'is empty).')
    robot_description: str = parameter('', 'The robot\'s URDF; empty: written from the scene\'s model.')
    joint_states_topic: str = parameter(GraphNames.JOINT_STATES_TOPIC, 'sensor_msgs/JointState topic of the '
                                        'robot\'s joints.')


class RobotStateNode(Node):
    """See the module docstring."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('robot_state', **kwargs)
        config = self.config = declare_config(self, RobotStateConfig)
        self.urdf = config.robot_description or robot_urdf(build_model([], config.scene))
        self.state = RobotState(self.urdf)
        self._description = self.create_publisher(String, GraphNames.ROBOT_DESCRIPTION_TOPIC, LATCHED_QOS)
        self._description.publish(String(data=self.urdf))
        self.tf = TfBroadcaster(self)
        self.tf.send_static(self.state.fixed_transforms())
        self.create_subscription(JointState, config.joint_states_topic, self._on_joint_states, JOINT_STATES_QOS)

    def _on_joint_states(self, message: JointState) -> None:
        if len(message.position) != len(message.name):
            return  # a joint state without positions names no pose
        self.tf.send(self.state.moving_transforms(message.name, message.position, to_seconds(message.header.stamp)))


def main(args=None) -> None:
    spin_node(RobotStateNode, args)


if __name__ == '__main__':
    main()
