"""The stand-in's differences from the graph's simulator: objects' friction and mass within their ranges, a camera
placed exactly where asked (so its error is exactly the one drawn), depth noisy and in whole millimetres."""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from cap_sim_bridge.standin import LINK_TO_OPTICAL, Perturbation, place_camera
from cap_sim_bridge.world import World


def test_objects_get_other_masses_and_friction_drawn_from_the_seed():
    plain = World(seed=2)
    perturbation = Perturbation(seed=5)
    bodies = lambda model: [model.body(name).id for name in plain.objects_in_model()]  # noqa: E731
    perturbed = World(seed=2, adjust_model=lambda model: perturbation.perturb_objects(model, bodies(model)))
    for name in plain.objects_in_model():
        mass = perturbed.model.body(name).mass[0] / plain.model.body(name).mass[0]
        assert perturbation.mass_range[0] <= mass <= perturbation.mass_range[1]
        geom = perturbed.model.body(name).id
        friction = perturbed.model.geom_friction[perturbed.model.geom_bodyid == geom, 0] / \
            plain.model.geom_friction[plain.model.geom_bodyid == geom, 0]
        assert np.all((friction >= perturbation.friction_range[0]) & (friction <= perturbation.friction_range[1]))
    assert not np.allclose(perturbed.model.body_mass, plain.model.body_mass)
    plain.close()
    perturbed.close()


def test_a_camera_is_placed_where_its_optical_frame_is_asked_for():
    mount = np.eye(4)
    mount[:3, :3] = Rotation.from_euler('y', 90, degrees=True).as_matrix()  # looking straight down
    mount[:3, 3] = [0.02, -0.48, 0.9]
    error = Perturbation(seed=1).camera_error()
    wanted = mount @ error @ LINK_TO_OPTICAL
    world = World(seed=0, adjust_model=lambda model: place_camera(model, 'top', wanted))  # top is on the world body
    assert np.allclose(world.camera_pose('top'), wanted, atol=1e-9)
    assert 0.9 * 0.004 < np.linalg.norm(error[:3, 3]) < 1.1 * 0.004
    # The optical frame's usual quaternion (x, y, z, w) in its link, up to sign.
    quaternion = Rotation.from_matrix(LINK_TO_OPTICAL[:3, :3]).as_quat()
    assert abs(np.dot(quaternion, [-0.5, 0.5, -0.5, 0.5])) == pytest.approx(1)
    world.close()


def test_depth_is_noisy_in_whole_millimetres_and_keeps_its_holes():
    depth = np.full((100, 100), 1.0, np.float32)
    depth[0, 0] = np.nan
    measured = Perturbation(seed=3, depth_noise=0.002).noisy_depth(depth, frame=7)
    assert measured.dtype == np.uint16 and measured[0, 0] == 0
    assert np.std(measured[1:, 1:].astype(float)) == pytest.approx(2.0, rel=0.2)
    assert abs(np.mean(measured[1:, 1:]) - 1000.0) < 0.5
