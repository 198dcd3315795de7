"""The robot domains lmp_node can run, each as one unit: its engine, its robot API over ROS, its scene, its cassette.

Every domain is an entry point of the group `cap_ros.domains` (value: a Domain). This package's setup.py offers
each sub-package of cap_lmp_ros.domains that has a `domain.py` defining `DOMAIN`, so adding a domain here is adding
a folder; another package adds a line to its own setup.py. No rclpy here, nor in what a Domain names for the sandbox
process (`build_engine` and its module); only `robot_api`, called in the node, may reach it.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping, Protocol

from cap_lmp.approval import PlannedCall
from cap_ros_common.plugins import PluginGroup
from cap_lmp.engine import Engine
from cap_lmp.isolated_engine import builder_reference
from cap_lmp_ros.plan_steps import PlanStep, describe_as_call


class RobotBinding(Protocol):
    """A domain's robot API bound to the graph, as lmp_node uses it."""

    service_timeout_s: float  # settable while the node runs
    motion_timeout_s: float
    stop_requested: Any  # a threading.Event, set by stop() and cleared before each command

    def functions(self) -> dict[str, Callable[..., Any]]:
        """The names generated code sees, bound to the graph."""
        ...

    def stop(self) -> None:
        """Stop waiting for the robot and cancel the motion in progress (thread-safe)."""
        ...

    # Optional: `begin_command()`, called before each command (the table top remembers what the last one moved).
    # Optional: `bind_clients(node)` moves the binding's service and action clients onto another node; the
    # one-process graph calls it, when the binding has it, to keep those clients on its fast executor.
    # Optional: `bind_engine(engine)`, called by lmp_node with its engine (a binding that calls the program's
    # functions, see Domain.function_arguments).


# build_engine(api: Mapping[str, Callable], client: LLMClient, limits: SandboxLimits | None, **options) -> Engine:
# a module-level function, so the sandbox process can import it.
EngineBuilder = Callable[..., Engine]
# robot_api(node, say_publisher, service_timeout_s, motion_timeout_s) -> RobotBinding
RobotApiFactory = Callable[[Any, Any, float, float], RobotBinding]


@dataclass(frozen=True)
class NodeSpec:
    """A node a domain's graph runs between the simulator and lmp_node (perception, a control node).

    Named by strings, so that a domain is described without importing its nodes (nor rclpy): `node_class`
    ('module:Class') is what the one-process graph builds, `executable` what a launch file starts, and
    `config_file` the parameter file in the package's share/config folder. `stand_in`: the node plays a server a
    real robot brings (the navigation node plays nav2), so hardware mode does not start it.
    """

    name: str
    package: str
    executable: str
    node_class: str
    config_file: str
    stand_in: bool = False


# The nodes of the table top, which other domains reuse: perception of the objects, and pick-and-place.
PERCEPTION_NODE = NodeSpec('perception_node', 'cap_perception', 'perception_node',
                           'cap_perception.perception_node:PerceptionNode', 'perception.yaml')
PICK_PLACE_NODE = NodeSpec('pick_place', 'cap_control', 'pick_place', 'cap_control.pick_place.node:PickPlaceNode',
                           'pick_place.yaml')


@dataclass(frozen=True)
class Domain:
    """One robot domain. `robot_functions` are the names `robot_api(...).functions()` binds over ROS; `scene` names
    the simulator scene it runs in; `cassette` is the replay cassette used when none is configured; `nodes` are the
    perception and control nodes its robot API talks to, started between the simulator and lmp_node.

    For approval (lmp_node's require_approval): `query_functions` are the robot functions that only read the world;
    a plan-only run calls them and records every other robot function instead of calling it (so a domain that
    declares none has every call recorded: nothing moves while planning). `describe_call` says what a recorded
    call means (plan_steps.PlanStep).
    """

    name: str
    build_engine: EngineBuilder
    robot_functions: tuple[str, ...]
    robot_api: RobotApiFactory
    scene: str
    cassette: Path
    nodes: tuple[NodeSpec, ...] = (PERCEPTION_NODE,)
    # Robot functions that take a function of the program (a controller): they receive a handle to it, which the
    # binding calls through the engine's invoke (IsolatedEngine).
    function_arguments: tuple[str, ...] = ()
    query_functions: tuple[str, ...] = ()
    describe_call: Callable[[PlannedCall], PlanStep] = describe_as_call
    # perception_node's parameters when its objects come from the RGB-D detector (`cap up --perception rgbd`): which
    # detector and camera, as (name, value) pairs; none: the table top's detector on the top camera.
    rgbd_perception: tuple[tuple[str, Any], ...] = ()

    @property
    def plan_functions(self) -> tuple[str, ...]:
        """The robot functions a plan-only run records instead of calling."""
        return tuple(name for name in self.robot_functions if name not in self.query_functions)

    def __post_init__(self) -> None:
        builder_reference(self.build_engine)  # a one-line ValueError now, not when the sandbox process starts
        names = [node.name for node in self.nodes]
        if len(set(names)) != len(names) or {'sim_bridge', 'lmp_node'} & set(names):
            raise ValueError(f'domain {self.name!r}: node names must be unique and not sim_bridge or lmp_node: '
                             f'{names}')


# Every domain, this package's own included, is an entry point of this group (name = the domain's name).
ENTRY_POINT_GROUP = 'cap_ros.domains'
_domains: PluginGroup[Domain] = PluginGroup(ENTRY_POINT_GROUP, 'domain', lambda value: isinstance(value, Domain))


def get_domain(name: str) -> Domain:
    """The domain called `name`; ValueError (one line, naming the known domains) if there is none."""
    domain = _domains.get(name)
    if domain.name != name:
        raise ValueError(f'the domain offered as {name!r} calls itself {domain.name!r}')
    return domain


def domain_names() -> list[str]:
    """The names of every known domain, sorted."""
    return _domains.names()


def engine_api(domain: Domain, functions: Mapping[str, Callable[..., Any]]) -> dict[str, Callable[..., Any]]:
    """The robot functions of `domain` out of a binding's `functions()`; ValueError naming any that are missing."""
    missing = [name for name in domain.robot_functions if name not in functions]
    if missing:
        raise ValueError(f'the robot API of domain {domain.name!r} lacks {", ".join(missing)}')
    return {name: functions[name] for name in domain.robot_functions}


def prompt_heads(domain: Domain) -> list[tuple[str, str]]:
    """(LMP name, the start every prompt of that LMP shares) for each LMP of the domain: what a model server's
    prompt cache can hold before the first command. Built in this process, with inert robot functions."""
    inert = {name: (lambda *args, **kwargs: None) for name in domain.robot_functions}
    engine = domain.build_engine(inert, None)
    return [(name, config.prompt.rstrip('\n') + '\n') for name, config in engine.lmps.items()]


__all__ = ['Domain', 'ENTRY_POINT_GROUP', 'EngineBuilder', 'NodeSpec', 'PERCEPTION_NODE', 'PICK_PLACE_NODE',
           'RobotApiFactory', 'RobotBinding', 'domain_names', 'engine_api', 'get_domain']
