"""Parameters of perception_node: the one home of their defaults (declared with declare_config)."""
from __future__ import annotations

import dataclasses

from cap_ros_common.parameters import parameter
from cap_tabletop.cameras import CAMERAS, DEFAULT_CAMERA, optical_orientation_xyzw

SOURCES = ('ground_truth', 'rgbd', 'stub')


@dataclasses.dataclass(frozen=True)
class PerceptionConfig:
    source: str = parameter('ground_truth', 'Where objects come from: ground_truth (simulator object array), rgbd '
                                            '(colour detector on camera images) or stub (YAML file).')
    stub_file: str = parameter('', 'YAML file of objects for source=stub.')
    # For source=rgbd. The defaults are the simulated camera the detector reads by default.
    camera: str = parameter(DEFAULT_CAMERA, 'Camera whose images the detector reads '
                                            '(topics <camera namespace>/<camera>/{color,depth,camera_info,pose}).')
    camera_pose_from_topic: bool = parameter(True, 'Take the camera pose from the latched <camera>/pose topic (the '
                                                   'sim bridge publishes it); false: use the camera_position and '
                                                   'camera_orientation parameters.')
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
        if len(self.camera_position) != 3 or len(self.camera_orientation) != 4:
            raise ValueError('camera_position needs x, y, z and camera_orientation x, y, z, w')
