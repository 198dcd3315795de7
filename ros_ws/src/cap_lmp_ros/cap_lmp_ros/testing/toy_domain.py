"""The toy domain over ROS, for tests: its one ROS robot function, `ring_bell(times)`, publishes std_msgs/String
'ring x<times>' on the relative topic `toy/bell`; the prompts, LMPs and engine builder are cap_lmp's toy domain
(cap_lmp.testing.toy_domain). It shows what a domain needs, and that lmp_node runs any registered domain. No rclpy at
import: the sandbox process imports this module to build its engine."""
from __future__ import annotations

import threading
from pathlib import Path
from typing import Any, Callable

from cap_lmp.testing.toy_domain import TOY_PROMPT, build_engine
from cap_lmp.testing.toy_world import bell_rings
from cap_lmp_ros.domains.registry import Domain

BELL_TOPIC = 'toy/bell'


class RosToyApi:
    """ring_bell over ROS: one String per call on BELL_TOPIC."""

    def __init__(self, node: Any, say_publisher: Any, service_timeout_s: float = 5.0,
                 motion_timeout_s: float = 180.0) -> None:
        from std_msgs.msg import String

        self._string = String
        self._bell = node.create_publisher(String, BELL_TOPIC, 10)
        self.service_timeout_s = service_timeout_s
        self.motion_timeout_s = motion_timeout_s
        self.stop_requested = threading.Event()

    def functions(self) -> dict[str, Callable[..., Any]]:
        return {'ring_bell': self.ring_bell}

    def ring_bell(self, times: int) -> None:
        """Ring the bell `times` times (1 to 10)."""
        self._bell.publish(self._string(data=f'ring x{bell_rings(times)}'))

    def stop(self) -> None:
        self.stop_requested.set()


def toy_domain(cassette: Path, name: str = 'toy') -> Domain:
    """The toy domain, replaying `cassette` when lmp_node is given none."""
    return Domain(name=name, build_engine=build_engine, robot_functions=('ring_bell',), robot_api=RosToyApi,
                  scene='toy', cassette=Path(cassette))


__all__ = ['BELL_TOPIC', 'TOY_PROMPT', 'RosToyApi', 'build_engine', 'toy_domain']
