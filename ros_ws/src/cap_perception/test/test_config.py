import pathlib

import pytest
import yaml
from cap_ros_common.parameters import parameter_names

from cap_perception.config import PerceptionConfig

CONFIG = pathlib.Path(__file__).resolve().parents[1] / 'config' / 'perception.yaml'


def test_yaml_overrides_only_declared_parameters():
    document = yaml.safe_load(CONFIG.read_text(encoding='utf-8'))
    overrides = document['/**/perception_node']['ros__parameters'] or {}
    assert set(overrides) <= set(parameter_names(PerceptionConfig))


def test_defaults_are_the_simulated_top_camera():
    config = PerceptionConfig()
    assert config.camera == 'top' and config.world_frame == 'world'
    assert config.topic('color') == 'cap/sim/cameras/top/color'
    assert PerceptionConfig(depth_topic='/camera/depth/image_rect_raw').topic('depth') == '/camera/depth/image_rect_raw'
    config.validate()


@pytest.mark.parametrize('changes', [{'source': 'sonar'}, {'source': 'stub'}, {'world_frame': ''},
                                     {'detector': 'sonar'}])
def test_invalid_configs_are_refused(changes):
    with pytest.raises(ValueError):
        PerceptionConfig(**changes).validate()
