import math

import numpy as np
import pytest

from cap_controllers import plants
from cap_controllers.plants import ArmState


def _rotation(axis, angle):
    axis = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    skew = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle) * skew + (1 - math.cos(angle)) * skew @ skew


def test_an_arm_state_travels_as_one_flat_vector_and_back():
    state = ArmState(1.5, np.arange(6.0), -np.arange(6.0), np.eye(4), np.ones(6), np.arange(36.0).reshape(6, 6))
    vector = state.pack()
    assert vector.shape == (plants.ARM.state_size,)
    back = ArmState.unpack(vector)
    assert back.time == 1.5 and np.array_equal(back.jacobian, state.jacobian) and np.array_equal(back.qd, state.qd)
    with pytest.raises(ValueError):
        ArmState.unpack(vector[:-1])


def test_the_cartpole_state_is_its_four_values_after_the_time():
    vector = plants.cartpole_vector(2.0, 0.1, 0.2, 0.3, 0.4)
    assert vector.shape == (plants.CARTPOLE.state_size,) and plants.cartpole_state(vector).tolist() == [0.1, 0.2, 0.3,
                                                                                                         0.4]


@pytest.mark.parametrize('angle', [1e-6, 0.3, 2.0, math.pi])
def test_the_rotation_error_turns_the_actual_orientation_into_the_goal(angle):
    axis = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    actual = _rotation([1, 2, 3], 0.7)
    goal = _rotation(axis, angle) @ actual
    error = plants.rotation_error(goal, actual)
    assert np.linalg.norm(error) == pytest.approx(angle, abs=1e-6)
    assert np.allclose(_rotation(error, np.linalg.norm(error)) @ actual, goal, atol=1e-6) if angle > 1e-3 else True


def test_the_pose_error_is_the_position_difference_then_the_rotation():
    goal, pose = np.eye(4), np.eye(4)
    goal[:3, 3] = [0.1, 0.0, -0.2]
    assert np.allclose(plants.pose_error(goal, pose), [0.1, 0.0, -0.2, 0.0, 0.0, 0.0])


def test_unknown_plants_are_named_with_the_known_ones():
    with pytest.raises(ValueError, match='arm, cartpole'):
        plants.plant('pendulum')
    assert plants.default_budget(100.0) == pytest.approx(0.005)
