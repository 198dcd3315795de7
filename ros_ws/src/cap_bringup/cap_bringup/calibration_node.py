"""calibration: a hardware profile's calibration on /tf_static (the camera's mount on the robot), as a
static_transform_publisher would; the camera's driver publishes the rest of the camera's frames.

    ros2 run cap_bringup calibration --ros-args -p profile:=/path/to/profile.yaml
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from rclpy.node import Node

from cap_bringup.preflight import calibration_transforms
from cap_hardware.profile import load_profile
from cap_ros_common.nodes import spin_node
from cap_ros_common.parameters import declare_config, parameter
from cap_ros_common.tf import TfBroadcaster


@dataclass(frozen=True)
class CalibrationConfig:
    profile: str = parameter('', 'The hardware profile (a YAML file, or a shipped profile\'s name) whose '
                                 'calibration is published.')


class CalibrationNode(Node):
    def __init__(self, **kwargs: Any) -> None:
        super().__init__('calibration', **kwargs)
        config = declare_config(self, CalibrationConfig)
        if not config.profile:
            raise ValueError('parameter profile names no hardware profile')
        self.profile = load_profile(config.profile)
        self.tf = TfBroadcaster(self)
        self.tf.send_static(calibration_transforms(self.profile))
        mount = self.profile.calibration.camera_mount
        self.get_logger().info(f'{mount.parent} -> {mount.child} from {self.profile.path}')


def main(args=None) -> None:
    spin_node(CalibrationNode, args)


if __name__ == '__main__':
    main()
