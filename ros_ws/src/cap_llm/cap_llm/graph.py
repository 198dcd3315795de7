"""Bring up the whole table-top graph in one process: sim bridge, perception, pick-and-place and lmp_node.

`cap up`, the demo, the integration tests and the benchmark all start the graph through `bring_up`, so they run
the same nodes with the same parameters (each package's config/*.yaml, then the overrides given here). Nodes are
composed in one process; the simulator steps in its own thread. Two executors spin them, each in a thread:
- a multi-threaded executor for the nodes whose callbacks block (action goals that last a whole motion or program);
- an events executor (callbacks dispatched from C++, without a Python wait set rebuilt at every wake-up) for the
  quick request-response path of generated code: perception's services and the robot API's clients. A robot API
  call then never waits for the busy executor, neither for its request nor for its answer.
"""
from __future__ import annotations

import atexit
import pathlib
import threading
from dataclasses import dataclass, field
from typing import Any

import yaml
from ament_index_python.packages import PackageNotFoundError, get_package_share_directory
import rclpy
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.experimental import EventsExecutor
from rclpy.parameter import Parameter

# (node name, package, its config file, module, class), in start order: the simulator first, lmp_node last.
NODES = (
    ('sim_bridge', 'cap_sim_bridge', 'sim_bridge.yaml', 'cap_sim_bridge.bridge_node', 'SimBridgeNode'),
    ('perception_node', 'cap_perception', 'perception.yaml', 'cap_perception.perception_node', 'PerceptionNode'),
    ('pick_place', 'cap_control', 'pick_place.yaml', 'cap_control.pick_place_node', 'PickPlaceNode'),
    ('lmp_node', 'cap_llm', 'lmp_node.yaml', 'cap_llm.lmp_node', 'LmpNode'),
)


def is_quick(node_name: str, parameters: dict[str, Any]) -> bool:
    """Whether every callback of the node is quick, so that it may share the single-threaded events executor.

    The RGB-D detector analyses frames in perception's callbacks, which would hold its services up on that one
    thread: with that source perception stays on the multi-threaded executor.
    """
    return node_name == 'perception_node' and parameters.get('source', 'ground_truth') != 'rgbd'


@dataclass
class GraphOptions:
    """What a user chooses when bringing the graph up; everything else comes from the config files."""

    seed: int = 0
    objects: str = ''  # comma-separated object names; empty = the seed's default episode
    real_time: bool = False  # True: simulated time follows the wall clock
    perception: str = 'ground_truth'  # or 'rgbd'
    llm_backend: str = 'cassette'  # or 'http'
    cassette: str = ''  # empty = the packaged reference cassette
    record_cassette: bool = False
    camera_rate: float = 10.0  # [Hz of simulated time]; 0 = no images
    extra: dict[str, dict[str, Any]] = field(default_factory=dict)  # node name -> {parameter: value}

    def overrides(self) -> dict[str, dict[str, Any]]:
        lmp = {'llm_backend': self.llm_backend, 'record_cassette': self.record_cassette}
        if self.cassette:
            lmp['cassette'] = str(pathlib.Path(self.cassette).resolve())
        values = {
            'sim_bridge': {'seed': self.seed, 'objects': self.objects, 'real_time': self.real_time,
                           'camera_rate': self.camera_rate},
            'perception_node': {'source': self.perception},
            # A camera sees a fresh stack only once the tool has moved out of its line of sight.
            'pick_place': {'clear_view': self.perception == 'rgbd'},
            'lmp_node': lmp,
        }
        for node, parameters in self.extra.items():
            values.setdefault(node, {}).update(parameters)
        return values


def config_parameters(package: str, filename: str) -> dict[str, dict[str, Any]]:
    """{node name: {parameter: value}} from a package's installed config file (empty if there is none)."""
    try:
        path = pathlib.Path(get_package_share_directory(package)) / 'config' / filename
    except PackageNotFoundError:
        return {}
    if not path.exists():
        return {}
    document = yaml.safe_load(path.read_text(encoding='utf-8')) or {}
    return {node: dict((body or {}).get('ros__parameters') or {}) for node, body in document.items()}


class EventsSpinner:
    """An events executor spinning in a thread of its own until `close()` or the context's shutdown.

    It spins in short slices and stops on a flag: its `shutdown()` blocks while another thread is inside `spin()`.
    """

    def __init__(self, context, name: str) -> None:
        self.context = context
        self.executor = EventsExecutor(context=context)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._spin, name=name, daemon=True)
        self._closed = False

    def start(self) -> None:
        self._thread.start()
        # A thread left inside the C++ spin when the interpreter finalises aborts the process: stop it at exit
        # even when the owner never called close() (a script that died of an exception).
        atexit.register(self.close)

    def _spin(self) -> None:
        try:
            while not self._stop.is_set() and self.context.ok():
                self.executor.spin_once(timeout_sec=0.1)
        except ExternalShutdownException:  # the context was shut down first: nothing left to serve
            pass

    def close(self, timeout_s: float = 5.0) -> None:
        if self._closed:
            return
        self._closed = True
        atexit.unregister(self.close)
        self._stop.set()
        self.executor.wake()
        if self._thread.is_alive():
            self._thread.join(timeout=timeout_s)
        self.executor.shutdown(timeout_sec=timeout_s)
        # Destroy the C++ executor now, not at some later collection (possibly while the interpreter finalises).
        self.executor = None


class Graph:
    """The running nodes; `close()` shuts them down (also on Ctrl-C in `cap up`)."""

    def __init__(self, context, options: GraphOptions, num_threads: int = 8) -> None:
        import importlib

        self.context = context
        self.nodes: dict[str, Any] = {}
        overrides = options.overrides()
        self.executor = MultiThreadedExecutor(num_threads=num_threads, context=context)
        self._quick = EventsSpinner(context, 'graph_events_executor')
        self.api_node = None  # the robot API's clients, on the events executor
        self.control_clients_node = None  # pick-and-place's perception clients, on the events executor
        try:
            for node_name, package, config_file, module_name, class_name in NODES:
                node_class = getattr(importlib.import_module(module_name), class_name)
                from_config = config_parameters(package, config_file)
                values = {**from_config.get('/**', {}), **from_config.get(node_name, {}),
                          **overrides.get(node_name, {})}
                node = node_class(context=context, parameter_overrides=[
                    Parameter(name, value=value) for name, value in values.items()])
                self.nodes[node_name] = node
                (self._quick.executor if is_quick(node_name, values) else self.executor).add_node(node)
            # Perception's answers reach every client of its services in the process, waking each client's
            # executor: all of them live on the events executor, where a wake-up for another client is cheap.
            self.api_node = rclpy.create_node('lmp_node_robot_api', context=context)
            self._quick.executor.add_node(self.api_node)
            self.nodes['lmp_node'].robot.bind_clients(self.api_node)
            self.control_clients_node = rclpy.create_node('pick_place_perception_clients', context=context)
            self._quick.executor.add_node(self.control_clients_node)
            self.nodes['pick_place'].bind_perception_clients(self.control_clients_node)
        except Exception:
            self._quick.close()
            self._destroy_nodes()
            raise
        self._thread = threading.Thread(target=self.executor.spin, name='graph_executor', daemon=True)
        self._thread.start()
        self._quick.start()

    @property
    def world(self):
        """The simulator's world (for images and ground truth in demos and checks)."""
        return self.nodes['sim_bridge'].world

    def _destroy_nodes(self) -> None:
        nodes = list(self.nodes.values()) + [node for node in (self.control_clients_node, self.api_node)
                                             if node is not None]
        for node in reversed(nodes):
            try:
                node.destroy_node()
            except Exception:  # shutting down: keep going with the other nodes
                pass

    def close(self) -> None:
        self.executor.shutdown(timeout_sec=5.0)
        self._thread.join(timeout=5.0)
        self._quick.close(timeout_s=5.0)
        self._destroy_nodes()
