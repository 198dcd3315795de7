"""Parameters of perception_node: the one home of their defaults (declared with declare_config)."""
from __future__ import annotations

import dataclasses

from cap_ros_common.parameters import parameter
from cap_interfaces.msg import GraphNames
from cap_tabletop.cameras import DEFAULT_CAMERA

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
                                          'head camera: camera head), or another package\'s.')
    camera: str = parameter(DEFAULT_CAMERA, 'Camera whose images the detector reads: the topics '
                                            '<camera namespace>/<camera>/{color,depth,camera_info} unless the '
                                            'three topic parameters below name others.')
    color_topic: str = parameter('', 'Colour image topic (rgb8, bgr8); empty: <camera namespace>/<camera>/color.')
    depth_topic: str = parameter('', 'Depth image topic aligned with the colour image (32FC1 in metres or 16UC1 '
                                     'in millimetres); empty: <camera namespace>/<camera>/depth.')
    camera_info_topic: str = parameter('', 'Intrinsics of the colour image; empty: '
                                           '<camera namespace>/<camera>/camera_info.')
    world_frame: str = parameter('world', 'Frame objects are reported in. The camera\'s pose is looked up on tf: '
                                          'the images\' frame in this frame at the images\' stamp.')

    def topic(self, kind: str) -> str:
        """The topic of the camera's `kind` ('color', 'depth', 'camera_info')."""
        return getattr(self, f'{kind}_topic') or f'{GraphNames.CAMERA_NAMESPACE}/{self.camera}/{kind}'

    def validate(self) -> None:
        if self.source not in SOURCES:
            raise ValueError(f'parameter source={self.source!r} is not one of {", ".join(SOURCES)}')
        if self.source == 'stub' and not self.stub_file:
            raise ValueError('parameter stub_file is required when source=stub')
        if self.detector not in (known := detector_names()):
            raise ValueError(f'parameter detector={self.detector!r} is not one of {", ".join(known)}')
        if not self.world_frame:
            raise ValueError('parameter world_frame names no frame')
