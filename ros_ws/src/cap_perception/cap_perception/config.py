"""Parameters of perception_node: the one home of their defaults (declared with declare_config)."""
from __future__ import annotations

import dataclasses

from cap_ros_common.parameters import parameter
from cap_tabletop.cameras import CAMERAS, DEFAULT_CAMERA, optical_orientation_xyzw

from cap_perception.detectors import detector_names

SOURCES = ('ground_truth', 'rgbd', 'stub')


@dataclasses.dataclass(frozen=True)
class PerceptionConfig:
    source: str = parameter('ground_truth', 'Where objects come from: ground_truth (simulator object array), rgbd '
                                            '(colour detector on camera images) or stub (YAML file).')
    stub_file: str = parameter('', 'YAML file of objects for source=stub.')
    # For source=rgbd. The defaults are the table top's detector and the simulated camera it reads.
    detector: str = parameter('tabletop', 'Which domain\'s detector the rgbd source runs (cap_perception.detectors): '
                                          'tabletop (the blocks and bowls on the table, best from the top camera), '
                                          'mobile (the kitchen\'s objects on its furniture, from the mobile base\'s '
                                          'head camera: camera head, camera_moves true), or another package\'s.')
    camera: str = parameter(DEFAULT_CAMERA, 'Camera whose images the detector reads '
                                            '(topics <camera namespace>/<camera>/{color,depth,camera_info,pose}).')
    camera_pose_from_topic: bool = parameter(True, 'Take the camera pose from the latched <camera>/pose topic (the '
                                                   'sim bridge publishes it); false: use the camera_position and '
                                                   'camera_orientation parameters.')
    camera_moves: bool = parameter(False, 'The camera moves with the robot (the mobile base\'s head camera): each '
                                          'frame is analysed with the <camera>/pose message stamped as the frame '
                                          '(the sim bridge sends one with every frame of a moving camera); false: '
                                          'with the latest pose.')
    camera_position: tuple[float, ...] = parameter(
        tuple(CAMERAS[DEFAULT_CAMERA].position),
        'Camera optical frame origin in the world frame [m] (extrinsic calibration).')
    camera_orientation: tuple[float, ...] = parameter(
        tuple(float(v) for v in optical_orientation_xyzw(CAMERAS[DEFAULT_CAMERA])),
        'Camera optical frame orientation in the world frame, quaternion x, y, z, w (ROS optical convention: '
        '+z forward, +y down).')

    def validate(self) -> None:
        if self.source not in SOURCES:
            raise ValueError(f'parameter source={self.source!r} is not one of {", ".join(SOURCES)}')
        if self.source == 'stub' and not self.stub_file:
            raise ValueError('parameter stub_file is required when source=stub')
        if self.detector not in (known := detector_names()):
            raise ValueError(f'parameter detector={self.detector!r} is not one of {", ".join(known)}')
        if self.camera_moves and not self.camera_pose_from_topic:
            raise ValueError('a moving camera (camera_moves) needs camera_pose_from_topic: its pose comes with '
                             'each frame')
        if len(self.camera_position) != 3 or len(self.camera_orientation) != 4:
            raise ValueError('camera_position needs x, y, z and camera_orientation x, y, z, w')
