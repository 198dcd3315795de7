"""The reactive-controller domain's LMPs and the functions its generated code calls (no rclpy: the sandbox process
builds this engine).

`run_controller(controller, rate, duration, plant)` hands the program's controller function to controller_node
through the robot function `start_controller` (which takes functions: lmp_node receives a handle and lets
controller_node call it, tick by tick, in this process under the sandbox's rules). Each tick's call goes through
`tick` here: it sets the state the node sent as the current one, so that the state functions (get_cartpole_state,
get_ee_pose, ...) read it without a robot call, calls the controller with the arguments its plant gives, and
returns its output as a list of numbers. Outside a controller, the state functions ask controller_node
(`read_plant_state`). Plants and state layouts: cap_controllers.plants.
"""
from __future__ import annotations

import inspect
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np

from cap_controllers import plants
from cap_controllers.plants import ArmState
from cap_lmp.engine import Engine, LMPConfig
from cap_lmp.errors import RobotApiError
from cap_lmp.llm import LLMClient
from cap_lmp.prompts import load_prompt
from cap_lmp.sandbox import SandboxLimits

PROMPTS_DIR = Path(__file__).resolve().parent / 'prompts'


class _Tick:
    """The state of the tick being computed (None between ticks and outside a controller)."""

    def __init__(self) -> None:
        self.state: np.ndarray | None = None
        self.plant = ''


def _arguments(controller: Callable[..., Any], plant: str) -> str:
    """How `controller` is called: 'state' (x, x_dot, theta, theta_dot), 'time' (t) or 'none'."""
    try:
        parameters = inspect.signature(controller).parameters.values()
    except (TypeError, ValueError):
        return 'none'
    required = [p for p in parameters if p.default is p.empty and p.kind in (p.POSITIONAL_ONLY,
                                                                              p.POSITIONAL_OR_KEYWORD)]
    if len(required) == 4 and plant == plants.CARTPOLE.name:
        return 'state'
    if len(required) == 1:
        return 'time'
    if not required:
        return 'none'
    takes = '(x, x_dot, theta, theta_dot), (t) or nothing' if plant == plants.CARTPOLE.name else '(t) or nothing'
    raise TypeError(f'a {plant} controller takes {takes}, not {len(required)} arguments')


def controller_functions(api: Mapping[str, Callable[..., Any]]) -> dict[str, Callable[..., Any]]:
    """run_controller and the state functions over the robot functions `api` (start_controller, read_plant_state)."""
    tick = _Tick()

    def read(plant: str) -> np.ndarray:
        if tick.state is not None:
            if tick.plant != plant:
                raise RobotApiError(f'this controller drives the {tick.plant}; the {plant} cannot be read in it')
            return tick.state
        return np.asarray(api['read_plant_state'](plant), dtype=float)

    def get_cartpole_state() -> np.ndarray:
        """np.array([x, x_dot, theta, theta_dot]): the cart's position [m] and speed, the pole's lean [rad] and
        its rate (theta > 0 leans the pole's top towards +x)."""
        return plants.cartpole_state(read(plants.CARTPOLE.name))

    def arm() -> ArmState:
        return ArmState.unpack(read(plants.ARM.name))

    def get_ee_pose() -> np.ndarray:
        """The tool's pose, a 4x4 matrix in the world frame (position in the last column)."""
        return arm().ee_pose

    def get_ee_velocity() -> np.ndarray:
        """The tool's velocity: [vx, vy, vz] in m/s, then [wx, wy, wz] in rad/s (world frame)."""
        return arm().ee_velocity

    def get_jacobian() -> np.ndarray:
        """The 6x6 Jacobian of the tool: get_ee_velocity() = get_jacobian() @ get_joint_velocities()."""
        return arm().jacobian

    def get_joint_positions() -> np.ndarray:
        return arm().q

    def get_joint_velocities() -> np.ndarray:
        return arm().qd

    def run_controller(controller: Callable[..., Any], rate: float = plants.DEFAULT_RATE, duration: float = 10.0,
                       plant: str = plants.CARTPOLE.name, time_budget: float = 0.0) -> Any:
        """Call `controller` at `rate` Hz for `duration` seconds on the plant; the robot stops it on a limit, a bad
        output, an exception or a call past its time budget (default: half the period)."""
        if not callable(controller):
            raise TypeError(f'run_controller needs a function, not {type(controller).__name__}')
        if plant not in plants.PLANTS:
            raise ValueError(f'unknown plant {plant!r}; the plants are: {", ".join(sorted(plants.PLANTS))}')
        how = _arguments(controller, plant)
        name = str(getattr(controller, '__name__', 'controller'))

        def call(vector: list[float]) -> list[float]:
            tick.state, tick.plant = np.asarray(vector, dtype=float), plant
            try:
                if how == 'state':
                    value = controller(*(float(v) for v in plants.cartpole_state(tick.state)))
                elif how == 'time':
                    value = controller(float(tick.state[0]))
                else:
                    value = controller()
            finally:
                tick.state = None
            try:
                return np.asarray(value, dtype=float).reshape(-1).tolist()
            except (TypeError, ValueError):
                raise TypeError(f'{name} returned {type(value).__name__}, not a number') from None

        call.__name__ = name
        return api['start_controller'](call, plant, float(rate), float(duration), float(time_budget))

    return {'run_controller': run_controller, 'get_cartpole_state': get_cartpole_state, 'get_ee_pose': get_ee_pose,
            'get_ee_velocity': get_ee_velocity, 'get_jacobian': get_jacobian,
            'get_joint_positions': get_joint_positions, 'get_joint_velocities': get_joint_velocities,
            'pose_error': plants.pose_error}


def controllers_lmp_configs() -> list[LMPConfig]:
    """The controller domain's LMPs: the UI with a session, and function generation."""
    return [
        LMPConfig('controllers_ui', load_prompt(PROMPTS_DIR, 'controllers_ui'), stop=('#',), maintain_session=True),
        LMPConfig('fgen', load_prompt(PROMPTS_DIR, 'fgen'), stop=('# define', '# example'), max_tokens=1024,
                  signature_style='parameters'),
    ]


def build_engine(api: Mapping[str, Callable[..., Any]], client: LLMClient, limits: SandboxLimits | None = None,
                 **engine_options: Any) -> Engine:
    """An Engine with the controller LMPs; generated code sees `say`, run_controller and the state functions, not
    the robot functions behind them."""
    names: dict[str, Any] = {'say': api['say'], **controller_functions(api)}
    return Engine(controllers_lmp_configs(), client, names, limits=limits, default_lmp='controllers_ui',
                  **engine_options)


__all__ = ['PROMPTS_DIR', 'build_engine', 'controller_functions', 'controllers_lmp_configs']
