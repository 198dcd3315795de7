"""A toy robot domain for tests: one LMP and one robot function, `ring_bell(times)`, whose ROS binding publishes
std_msgs/String 'ring x<times>' on the relative topic `toy/bell`. It shows what a domain needs, and that lmp_node
runs any registered domain. No rclpy at import: the sandbox process imports this module to build its engine."""
from __future__ import annotations

import threading
from pathlib import Path
from typing import Any, Callable, Mapping

from cap_lmp.engine import Engine, LMPConfig
from cap_lmp.llm import LLMClient
from cap_lmp.sandbox import SandboxLimits
from cap_lmp_ros.domains.registry import Domain

BELL_TOPIC = 'toy/bell'
TOY_PROMPT = '''# ring the bell once.
ring_bell(1)
# ring the bell three times.
ring_bell(3)
'''


def build_engine(api: Mapping[str, Callable[..., Any]], client: LLMClient, limits: SandboxLimits | None = None,
                 **engine_options: Any) -> Engine:
    """An Engine with the one toy LMP over `api`."""
    toy_ui = LMPConfig('toy_ui', TOY_PROMPT, stop=('#',), maintain_session=True)
    return Engine([toy_ui], client, dict(api), limits=limits, default_lmp='toy_ui', **engine_options)


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
        if not isinstance(times, int) or isinstance(times, bool) or not 1 <= times <= 10:
            raise ValueError('ring_bell(times) takes a whole number from 1 to 10')
        self._bell.publish(self._string(data=f'ring x{times}'))

    def stop(self) -> None:
        self.stop_requested.set()


def toy_domain(cassette: Path, name: str = 'toy') -> Domain:
    """The toy domain, replaying `cassette` when lmp_node is given none."""
    return Domain(name=name, build_engine=build_engine, robot_functions=('ring_bell',), robot_api=RosToyApi,
                  scene='toy', cassette=Path(cassette))
