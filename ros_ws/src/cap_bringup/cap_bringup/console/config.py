"""Parameters of the console node: the one home of their defaults (declared with declare_config)."""
from __future__ import annotations

from dataclasses import dataclass

from cap_ros_common.parameters import parameter


@dataclass(frozen=True)
class ConsoleConfig:
    port: int = parameter(8765, 'TCP port of the page on 127.0.0.1; 0: a free one (the URL is logged).')
    max_stream_fps: float = parameter(10.0, 'Most frames per second one browser gets of one camera; what arrives '
                                      'faster is skipped, not encoded.')
    jpeg_quality: int = parameter(80, 'JPEG quality of the camera streams (1-100).')
    history_size: int = parameter(50, 'Commands the page keeps in its history.')
    discovery_period_s: float = parameter(2.0, 'How often the node looks for new image topics under cap/sim [s].')
