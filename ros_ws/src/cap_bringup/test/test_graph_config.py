"""The graph reads the packages' parameter files as ROS does: nested maps as dotted names, any node-key spelling."""
from __future__ import annotations

import yaml

from cap_bringup.graph import parameters_of
from cap_bringup.namespaces import normalise_namespace

DOCUMENT = """
/**:
  ros__parameters:
    use_sim_time: true
/**/pick_place:
  ros__parameters:
    velocity_scale: 0.5
    workspace:
      y_min: -0.7
      x_max: 0.25
/sim_bridge:
  ros__parameters: {}
lmp_node:
  ros__parameters:
    time_limit_s: 60.0
"""


def test_nested_overrides_become_dotted_names_and_node_keys_lose_their_prefixes():
    assert parameters_of(yaml.safe_load(DOCUMENT)) == {
        '/**': {'use_sim_time': True},
        'pick_place': {'velocity_scale': 0.5, 'workspace.y_min': -0.7, 'workspace.x_max': 0.25},
        'sim_bridge': {},
        'lmp_node': {'time_limit_s': 60.0},
    }


def test_namespaces_are_normalised_or_refused_in_one_line():
    assert normalise_namespace('') == ''
    assert normalise_namespace('robot1') == '/robot1'
    assert normalise_namespace('/fleet/robot_2/') == '/fleet/robot_2'
    for bad in ('1robot', 'robot-1', 'a//b'):
        try:
            normalise_namespace(bad)
        except ValueError as error:
            assert '\n' not in str(error) and 'namespace' in str(error)
        else:
            raise AssertionError(f'{bad!r} was accepted')
