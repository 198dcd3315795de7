"""The 'controllers' scene: the UR5e free to move and a cart-pole behind it (models/controllers.xml).

A reset with seed s places the cart-pole at a start drawn from s: the cart's x and the pole's
theta each uniform in +-INITIAL_STATE_RANGE (cap_controllers.plants), at rest. Two equality constraints (the
holds, `cart_hold` and `pole_hold`) keep it there until a controller takes it over
(World.release_holds); from then on only the cart's motor and gravity move it.
"""
from __future__ import annotations

from typing import Sequence

import mujoco
import numpy as np
from cap_controllers import plants

from cap_sim_bridge import objects as objects_module
from cap_sim_bridge.objects import ObjectSpec
from cap_sim_bridge.scenes import MODELS_DIR, SceneSpec, spec_from_mjcf

NAME = 'controllers'


def initial_cartpole_state(seed: int) -> np.ndarray:
    """[x, x_dot, theta, theta_dot] the cart-pole starts from after a reset with `seed` (at rest: it is held)."""
    x, theta = np.random.default_rng(seed).uniform(-plants.INITIAL_STATE_RANGE, plants.INITIAL_STATE_RANGE, 2)
    return np.array([x, 0.0, theta, 0.0])


def _build(objects: Sequence[ObjectSpec]) -> mujoco.MjSpec:
    return objects_module.add_objects(spec_from_mjcf((MODELS_DIR / 'controllers.xml').read_text(encoding='utf-8')),
                                      objects)


def _initialize(model: mujoco.MjModel, data: mujoco.MjData, seed: int) -> None:
    x, _, theta, _ = initial_cartpole_state(seed)
    for joint, hold, value in ((plants.CART_JOINT, 'cart_hold', x), (plants.POLE_JOINT, 'pole_hold', theta)):
        data.qpos[model.joint(joint).qposadr[0]] = value
        equality = model.equality(hold).id
        model.eq_data[equality, 0] = value  # polycoef[0]: where the hold keeps the joint
        data.eq_active[equality] = 1


SCENE = SceneSpec(NAME, build=_build, initialize=_initialize,
                  description='the UR5e free to move, and a cart-pole on a rail behind it')
