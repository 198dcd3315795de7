"""What GraphOptions asks of the nodes for the chosen perception (no graph is brought up here)."""
import pytest
from cap_mobile import robot

from cap_bringup.graph import GraphOptions
from cap_perception.config import PerceptionConfig


def _perception(**options) -> dict:
    parameters = GraphOptions(**options).overrides()['perception_node']
    parameters.pop('use_sim_time')
    return parameters


def test_rgbd_perception_of_the_mobile_domain_runs_the_kitchens_detector_on_the_moving_head_camera():
    parameters = _perception(domain='mobile', perception='rgbd')
    assert parameters == {'source': 'rgbd', 'detector': 'mobile', 'camera': robot.HEAD_CAMERA}
    PerceptionConfig(**parameters).validate()
    assert _perception(domain='mobile') == {'source': 'ground_truth'}


def test_rgbd_perception_of_the_table_top_keeps_the_defaults_the_table_tops_detector_and_top_camera():
    assert _perception(perception='rgbd') == {'source': 'rgbd'}
    config = PerceptionConfig(source='rgbd')
    assert (config.detector, config.camera, config.world_frame) == ('tabletop', 'top', 'world')


def test_rgbd_perception_without_camera_images_is_refused():
    with pytest.raises(ValueError, match='camera_rate'):
        GraphOptions(domain='mobile', perception='rgbd', camera_rate=0.0).overrides()
