"""The controller domain without ROS: it is registered, its reference programs run in the engine against a plant
given as plain functions (function generation writes the PD controller and the impedance law), and run_controller
hands the node a function that feeds the controller the tick's state."""
from __future__ import annotations

import numpy as np
import pytest

from cap_control import kinematics
from cap_controllers import plants
from cap_controllers.plants import ArmState
from cap_lmp.cassette import CassetteClient
from cap_lmp_ros.domains.controllers import lmps
from cap_lmp_ros.domains.controllers.domain import DOMAIN
from cap_lmp_ros.domains.registry import domain_names, get_domain

HOME = np.array([0.8413, -2.2842, 1.7017, -0.9883, -1.5708, -0.7295])


class Plant:
    """start_controller calls the controller for three ticks of a fixed state; read_plant_state answers it."""

    def __init__(self) -> None:
        jacobian = kinematics.jacobian(HOME)
        self.arm = ArmState(0.0, HOME, np.zeros(6), kinematics.forward_kinematics(HOME), np.zeros(6), jacobian).pack()
        self.cartpole = plants.cartpole_vector(0.0, 0.1, 0.0, 0.02, 0.0)
        self.outputs: list[list[float]] = []
        self.said: list[str] = []

    def start_controller(self, call, plant, rate, duration, budget):
        for tick in range(3):
            state = (self.arm if plant == 'arm' else self.cartpole).copy()
            state[0] = tick / rate
            self.outputs.append(call(state.tolist()))
        return {'simulated_time': duration, 'calls': 3}

    def read_plant_state(self, plant):
        return self.arm if plant == 'arm' else self.cartpole

    def api(self):
        return {'start_controller': self.start_controller, 'read_plant_state': self.read_plant_state,
                'say': self.said.append}


@pytest.fixture
def plant_and_engine():
    plant = Plant()
    return plant, lmps.build_engine(plant.api(), CassetteClient(DOMAIN.cassette))


def test_the_domain_is_registered_with_its_control_node():
    assert 'controllers' in domain_names()
    domain = get_domain('controllers')
    assert [node.name for node in domain.nodes] == ['controller_node']
    assert domain.function_arguments == ('start_controller',)


def test_the_pd_reference_is_generated_and_pushes_the_cart_under_the_pole(plant_and_engine):
    plant, engine = plant_and_engine
    result = engine.run('keep the pole upright with a PD controller for 30 seconds')
    assert result.success, result.message
    assert result.generated_functions == ['keep_pole_upright_with_pd_control']
    assert plant.outputs[-1] == [pytest.approx(30.0 * 0.02 + 1.0 * 0.1)]  # leaning towards +x: push towards +x
    assert plant.said == ['The pole stayed up for 30.0 s']


def test_the_impedance_reference_holds_the_pose_it_read(plant_and_engine):
    plant, engine = plant_and_engine
    assert engine.run('hold the tool where it is with impedance control for 10 seconds').success
    assert np.allclose(plant.outputs[-1], 0.0)  # at its goal and at rest: no torque


def test_the_state_functions_read_the_plant_outside_a_controller(plant_and_engine):
    plant, engine = plant_and_engine
    assert engine.run('what is the angle of the pole?').success
    assert plant.said == ['The pole leans 1.1 degrees']


def test_a_controller_with_the_wrong_arguments_is_refused_before_it_runs():
    with pytest.raises(TypeError, match=r'takes \(x, x_dot, theta, theta_dot\), \(t\) or nothing'):
        lmps.controller_functions(Plant().api())['run_controller'](lambda a, b: 0.0)
