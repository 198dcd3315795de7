import pathlib

import pytest
import yaml
from cap_ros_common.parameters import parameter_names

from cap_sim_bridge.config import DEFAULT_CAMERAS, SimBridgeConfig, cameras_to_publish

CONFIG = pathlib.Path(__file__).resolve().parents[1] / 'config' / 'sim_bridge.yaml'


def test_yaml_overrides_only_declared_parameters():
    document = yaml.safe_load(CONFIG.read_text(encoding='utf-8'))
    overrides = document['/**/sim_bridge']['ros__parameters'] or {}
    assert set(overrides) <= set(parameter_names(SimBridgeConfig))


def test_the_graph_parameters_keep_their_names():
    assert {'scene', 'seed', 'objects', 'real_time', 'camera_rate', 'cameras'} <= set(parameter_names(SimBridgeConfig))


def test_cameras_default_to_the_scenes_own():
    assert cameras_to_publish(DEFAULT_CAMERAS, ('front', 'top'), ('front', 'top')) == ['front', 'top']
    assert cameras_to_publish(DEFAULT_CAMERAS, ('overhead',), ('overhead',)) == ['overhead']
    assert cameras_to_publish(('top',), ('front', 'top'), ('front', 'top')) == ['top']
    with pytest.raises(ValueError, match='unknown cameras'):
        cameras_to_publish(('side',), ('front', 'top'), ('front', 'top'))
