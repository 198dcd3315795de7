"""declare_config declares every field of a config dataclass once, with its default, description and overrides."""
from __future__ import annotations

from dataclasses import dataclass, field

import pytest

from cap_ros_common.parameters import declare_config, parameter, parameter_names
from cap_ros_common.time import duration_msg, time_msg, to_seconds


@dataclass(frozen=True)
class Inner:
    x_min: float = parameter(-0.3, 'lower x bound [m]')


@dataclass(frozen=True)
class Config:
    rate: float = parameter(10.0, 'rate [Hz]')
    cameras: tuple[str, ...] = parameter(('top', 'front'), 'cameras to publish')
    name: str = parameter('tabletop', 'scene name')
    inner: Inner = field(default_factory=Inner)
    kept: float | None = None


def test_defaults_descriptions_and_overrides(ros_context):
    from rclpy.node import Node
    from rclpy.parameter import Parameter

    node = Node('config_test', context=ros_context, parameter_overrides=[
        Parameter('rate', value=20.0), Parameter('inner.x_min', value=-0.5)])
    try:
        config = declare_config(node, Config, skip=('kept',))
        assert config == Config(rate=20.0, cameras=('top', 'front'), inner=Inner(x_min=-0.5))
        assert isinstance(config.cameras, tuple)
        assert node.describe_parameter('rate').description == 'rate [Hz]'
        assert not node.has_parameter('kept')
        assert parameter_names(Config) == ['rate', 'cameras', 'name', 'inner.x_min', 'kept']
    finally:
        node.destroy_node()


@pytest.mark.parametrize('seconds', [0.0, 1.5, 12.999999999, 1796155661.399181854])
def test_time_round_trip(seconds):
    assert to_seconds(time_msg(seconds)) == pytest.approx(seconds, abs=1e-9 * max(1.0, seconds) * 10)
    assert 0 <= time_msg(seconds).nanosec < 1_000_000_000
    assert to_seconds(duration_msg(-1.0)) == 0.0
