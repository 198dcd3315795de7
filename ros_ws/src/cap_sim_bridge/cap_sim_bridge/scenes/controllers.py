"""The 'controllers' scene: the UR5e free to move and a cart-pole behind it (models/controllers.xml).

A reset with seed s places the cart-pole at a start drawn from s: the cart's x and the pole's
theta each uniform in +-INITIAL_STATE_RANGE (cap_controllers.plants), at rest. Two equality constraints (the
holds, `cart_hold` and `pole_hold`) keep it there until a controller takes it over
(World.release_holds); from then on only the cart's motor and gravity move it. Every controller run puts it back
there first (the scene's restart_plant, through the simulator's lockstep): a pole that fell in one run stands at the
same seeded start for the next.
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


def _start_cartpole(model: mujoco.MjModel, data: mujoco.MjData, seed: int) -> None:
    """The cart-pole at its seeded start: at rest, held there, its motor idle (at a reset and before every run)."""
    x, _, theta, _ = initial_cartpole_state(seed)
    for joint, hold, value in ((plants.CART_JOINT, 'cart_hold', x), (plants.POLE_JOINT, 'pole_hold', theta)):
        found = model.joint(joint)
        data.qpos[found.qposadr[0]] = value
        data.qvel[found.dofadr[0]] = 0.0
        equality = model.equality(hold).id
        model.eq_data[equality, 0] = value  # polycoef[0]: where the hold keeps the joint
        data.eq_active[equality] = 1
    data.ctrl[model.actuator(plants.CART_ACTUATOR).id] = 0.0


SCENE = SceneSpec(NAME, build=_build, initialize=_start_cartpole, restart_plant=_start_cartpole,
                  description='the UR5e free to move, and a cart-pole on a rail behind it')
