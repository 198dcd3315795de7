"""Bring up a domain's whole graph in one process: the sim bridge and robot_state (standing in for a robot's drivers),
the domain's perception and control nodes (for the table top: perception and pick-and-place), lmp_node and the
visualization node (RViz's /cap/markers); in hardware mode (`GraphOptions(hardware=PROFILE)`) the robot's own
drivers instead of the first two (cap_bringup.hardware). When lmp_node rehearses programs (its `rehearse`), the
twin's simulator, perception and control nodes too, under <namespace>/twin (cap_bringup.nodes.twin_nodes).

`cap up`, the demo, the integration tests and the benchmark all start the graph as a `Graph`, so they run the same
nodes with the same parameters (each node's defaults from its config dataclass, then its package's config/*.yaml,
then the options given here: what GraphOptions sets wins over the YAML files). Nodes are
composed in one process; the simulator steps in its own thread. Two executors spin them, each in a thread:
- a multi-threaded executor for the nodes whose callbacks block (action goals that last a whole motion or program);
- an events executor (callbacks dispatched from C++, without a Python wait set rebuilt at every wake-up) for the
  quick request-response path of generated code: perception's services and the robot API's clients. A robot API
  call then never waits for the busy executor, neither for its request nor for its answer.

Shutting down is quiet and complete however the owner's process ends (see Graph and Spinner): `with Graph(...)`,
`close()`, the end of the script, an exception or SIGTERM.
"""
from __future__ import annotations

import atexit
import pathlib
import signal
import sys
import threading
import time
from dataclasses import dataclass, field
from typing import Any

import yaml
from ament_index_python.packages import PackageNotFoundError, get_package_share_directory
import rclpy
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.experimental import EventsExecutor
from rclpy.parameter import Parameter

from cap_bringup.cpu_affinity import pin_to_one_cpu
from cap_bringup.namespaces import normalise_namespace
from cap_bringup.nodes import LMP_NODE, SIM_BRIDGE_NODE, graph_nodes, node_class, twin_nodes, twin_parameters
from cap_bringup.qos_events import drop_default_event_handlers
from cap_interfaces.msg import GraphNames
from cap_lmp_ros.domains.registry import get_domain
from cap_lmp_ros.twin import twin_namespace
from cap_lmp_ros.thread_watch import ThreadWatch



def namespace_arguments(namespace: str) -> dict[str, Any]:
    """Node options that put a node under `namespace` ('' or '/robot1') with the clock of that namespace's simulator.

    The graph's names are relative, so the namespace moves all of them; /clock is absolute (rclpy's time source
    subscribes to it by that name), so it is remapped to <namespace>/clock: each graph has a simulator, and time,
    of its own.
    """
    namespace = normalise_namespace(namespace)
    if not namespace:
        return {}
    return {'namespace': namespace,
            'cli_args': ['--ros-args', '-r', f'{GraphNames.CLOCK_TOPIC}:={namespace}{GraphNames.CLOCK_TOPIC}']}


def is_quick(node_name: str, parameters: dict[str, Any]) -> bool:
    """Whether every callback of the node is quick, so that it may share the single-threaded events executor.

    The RGB-D detector analyses frames in perception's callbacks, which would hold its services up on that one
    thread: with that source perception stays on the multi-threaded executor. The visualization node only sends
    requests and handles answers, and its perception clients are woken by every perception answer of the process
    (see Graph.__init__): it belongs there too, as robot_state (a joint state in, transforms out) and the calibration
    (transforms sent once).
    """
    if node_name in ('visualization', 'robot_state', 'calibration'):
        return True
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
    cpu: int | None = 0  # the process is pinned to this one of its allowed CPUs (cpu_affinity.py); None: not pinned
    namespace: str = ''  # e.g. 'robot1': every name of the graph under /robot1 (two graphs side by side)
    domain: str = 'tabletop'  # the domain (cap_lmp_ros.domains) whose prompts, robot API and scene run
    # A hardware profile (cap_hardware; a file or a shipped profile's name): no simulator, the profile's robot
    # instead, its domain, RGB-D perception; the options above that concern the simulator are not used.
    hardware: str = ''
    # Rehearse programs on a twin (lmp_node's rehearse: always, on_approval, off); empty: always in hardware mode,
    # off in simulation. When not off, the twin's nodes run under <namespace>/twin.
    rehearse: str = ''

    def rehearse_mode(self) -> str:
        return self.rehearse or ('always' if self.hardware else 'off')

    def profile(self):
        """The hardware profile (None in simulation)."""
        if not self.hardware:
            return None
        from cap_hardware.profile import load_profile
        return load_profile(self.hardware)

    def domain_name(self) -> str:
        profile = self.profile()
        return profile.domain if profile is not None else self.domain

    def overrides(self) -> dict[str, dict[str, Any]]:
        """{node name: {parameter: value}} for the nodes of the domain's graph."""
        profile = self.profile()
        if profile is not None:
            from cap_bringup.hardware import hardware_overrides
            domain, values = get_domain(profile.domain), hardware_overrides(profile)
            values['lmp_node'].update({'llm_backend': self.llm_backend, 'record_cassette': self.record_cassette})
            if self.cassette:
                values['lmp_node']['cassette'] = str(pathlib.Path(self.cassette).resolve())
            values = {spec.name: values.get(spec.name, {'use_sim_time': False})
                      for spec in graph_nodes(domain, hardware=True)}
            if self.rehearse:
                values['lmp_node']['rehearse'] = self.rehearse
            for node, parameters in self.extra.items():
                values.setdefault(node, {}).update(parameters)
            return values
        domain = get_domain(self.domain)
        if self.perception == 'rgbd' and self.camera_rate <= 0:
            raise ValueError('perception rgbd reads camera images: camera_rate must be above 0')
        lmp = {'llm_backend': self.llm_backend, 'record_cassette': self.record_cassette, 'domain': self.domain,
               'rehearse': self.rehearse_mode()}
        if self.cassette:
            lmp['cassette'] = str(pathlib.Path(self.cassette).resolve())
        chosen = {
            'sim_bridge': {'seed': self.seed, 'objects': self.objects, 'real_time': self.real_time,
                           'camera_rate': self.camera_rate, 'scene': domain.scene},
            'perception_node': {'source': self.perception,
                                **(dict(domain.rgbd_perception) if self.perception == 'rgbd' else {})},
            # A camera sees a fresh stack only once the tool has moved out of its line of sight.
            'pick_place': {'clear_view': self.perception == 'rgbd'},
            'lmp_node': lmp,
            'robot_state': {'scene': domain.scene},
        }
        values: dict[str, dict[str, Any]] = {}
        for spec in graph_nodes(domain):
            values[spec.name] = dict(chosen.get(spec.name, {}))
            if spec is not SIM_BRIDGE_NODE:
                values[spec.name]['use_sim_time'] = True
        for node, parameters in self.extra.items():
            values.setdefault(node, {}).update(parameters)
        return values

    def twin_overrides(self) -> dict[str, dict[str, Any]]:
        """{node name: {parameter: value}} of the twin's nodes (cap_bringup.nodes.twin_parameters), with the extra
        parameters given for them under 'twin/<node name>'."""
        values = twin_parameters(get_domain(self.domain_name()))
        for name, parameters in values.items():
            parameters.update(self.extra.get(f'twin/{name}', {}))
        return values


def config_parameters(package: str, filename: str) -> dict[str, dict[str, Any]]:
    """{node name: {parameter: value}} from a package's installed config file (empty if there is none).

    Node keys may be written `pick_place`, `/pick_place` or `/**/pick_place` (the last matches the node under any
    namespace, as the launch file needs); `/**` applies to every node. Nested maps become dotted parameter names
    (`workspace: {y_min: -0.8}` is `workspace.y_min`), as ROS reads them from a parameter file.
    """
    try:
        path = pathlib.Path(get_package_share_directory(package)) / 'config' / filename
    except PackageNotFoundError:
        return {}
    if not path.exists():
        return {}
    return parameters_of(yaml.safe_load(path.read_text(encoding='utf-8')) or {})


def parameters_of(document: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """{node name: {dotted parameter name: value}} of a parameter file's document (see config_parameters)."""
    nodes: dict[str, dict[str, Any]] = {}
    for key, body in document.items():
        node = '/**' if key == '/**' else str(key).removeprefix('/**/').lstrip('/')
        nodes.setdefault(node, {}).update(flat_parameters((body or {}).get('ros__parameters') or {}))
    return nodes


def flat_parameters(values: dict[str, Any], prefix: str = '') -> dict[str, Any]:
    """Nested parameter maps as dotted names: {'workspace': {'y_min': -0.8}} -> {'workspace.y_min': -0.8}."""
    flat: dict[str, Any] = {}
    for name, value in values.items():
        if isinstance(value, dict):
            flat.update(flat_parameters(value, f'{prefix}{name}.'))
        else:
            flat[f'{prefix}{name}'] = value
    return flat


class Spinner:
    """An executor spinning in a watched thread of its own until `stop()` or the context's shutdown.

    It spins in short slices and stops on a flag. rclpy's own `Executor.shutdown()` must not be called while
    another thread spins: it destroys the executor's guard condition under the spinning thread (which then dies on
    "'NoneType' object has no attribute 'handle'"), and in rclpy 7.1.x it does not wait for the callbacks in
    flight (its wait is skipped), whose nodes are then destroyed under them ("cannot use Destroyable because
    destruction was requested", printed later as an exception never retrieved). So Graph.close() lets the
    callbacks in flight end while the executors still spin, then stops the spinning and joins the thread
    (`stop`), waits for the worker pool and shuts the executor down (`finish`), and only then destroys the nodes.
    """

    SLICE_S = 0.2  # longest wait inside one spin_once; bounds how long stop() waits for the thread

    def __init__(self, executor, context, name: str, watch: ThreadWatch) -> None:
        self.executor, self.context, self.name, self._watch = executor, context, name, watch
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> None:
        self._thread = self._watch.start(self._spin, self.name)

    def _spin(self) -> None:
        try:
            while not self._stop.is_set() and self.context.ok():
                self.executor.spin_once(timeout_sec=self.SLICE_S)
        except ExternalShutdownException:  # the context was shut down first: nothing left to serve
            pass

    def stop(self, timeout_s: float) -> bool:
        """Stop spinning and wait for the thread; True when it ended within `timeout_s`."""
        self._stop.set()
        try:
            self.executor.wake()
        except Exception:  # its guard condition is gone already: the thread is not waiting on it
            pass
        if self._thread is not None:
            self._thread.join(timeout=timeout_s)
            return not self._thread.is_alive()
        return True

    def finish(self, timeout_s: float) -> None:
        """After stop(): wait (within `timeout_s`) for the worker pool's last callbacks, then shut the executor down."""
        pool = getattr(self.executor, '_executor', None)  # a multi-threaded executor's worker threads
        if pool is not None:
            pool.shutdown(wait=False, cancel_futures=True)
            deadline = time.monotonic() + timeout_s
            for worker in list(getattr(pool, '_threads', ())):
                worker.join(timeout=max(0.0, deadline - time.monotonic()))
        _retrieve_exceptions(self.executor)
        try:  # newer rclpy waits here for the worker threads, which are joined (or given up on) already
            self.executor.shutdown(timeout_sec=0, wait_for_threads=False)
        except TypeError:
            self.executor.shutdown(timeout_sec=0)


def _retrieve_exceptions(executor) -> None:
    """Fetch the outcome of every finished callback task the executor holds.

    A task that failed after the last spin (while the graph shut down) would otherwise print "The following
    exception was never retrieved" when collected; a failure during normal running reached the spinning thread.
    """
    tasks = [task for task, *_ in list(getattr(executor, '_tasks', ()))] + list(getattr(executor, '_futures', ()))
    for task in tasks:
        try:
            if task.done():
                task.exception()
        except Exception:  # a task that cannot tell: nothing to print either
            pass


_OPEN_GRAPHS: set['Graph'] = set()  # closed at interpreter exit; a graph leaves the set when it closes
_exit_hook = threading.Lock()
_exit_hook_registered = False


def _close_open_graphs() -> None:
    for graph in list(_OPEN_GRAPHS):
        graph.close()


def _close_at_exit(graph: 'Graph') -> None:
    """Close `graph` when the interpreter exits, before any thread pool is joined or any thread is frozen.

    Plain atexit handlers run too late: by then the interpreter has joined the executor's worker pool (a worker
    inside a long callback blocks the exit) and refuses new work (the spinning thread dies on "cannot schedule new
    futures after interpreter shutdown"), and threads still inside rclpy's C++ code while the interpreter
    finalises crash the process. threading's exit hooks run first, newest first. The set holds the graph strongly:
    a script that dropped its last reference to a running graph still gets it closed.
    """
    global _exit_hook_registered
    with _exit_hook:
        _OPEN_GRAPHS.add(graph)
        if not _exit_hook_registered:
            register = getattr(threading, '_register_atexit', None)
            (register or atexit.register)(_close_open_graphs)
            _exit_hook_registered = True


class Graph:
    """The running nodes. Use it as a context manager, or call `close()`; exiting without either is safe too.

        with Graph(context, GraphOptions(seed=3)) as graph:
            ...

    However the process ends (the end of the script, an exception, SIGTERM, interpreter exit), the graph closes:
    commands and motions stop, the executors' threads end, then the nodes are destroyed and the sandbox process is
    reaped. If SIGTERM still has its default action when the graph is built in the main thread, the graph makes it
    raise SystemExit(143) there, so that the script unwinds (and closes the graph) instead of dying on the spot.
    If a thread the graph depends on dies (an executor's, lmp_node's worker), `failed` is set and `failure` says
    which and why (also printed on stderr, one line): the graph no longer answers and its owner should end (`cap up`
    exits with thread_watch.FATAL_EXIT_CODE).

    `node_arguments` ({node name: {argument: value}}) are passed to those nodes' constructors besides their
    parameters: what tests put in that no parameter offers (lmp_node's sandbox_command).
    """

    CLOSE_TIMEOUT_S = 5.0  # per stage: spinning threads, callbacks in flight

    def __init__(self, context, options: GraphOptions, num_threads: int = 8,
                 node_arguments: dict[str, dict[str, Any]] | None = None) -> None:
        if options.cpu is not None:
            pin_to_one_cpu(options.cpu)  # before the graph's threads start, so that they inherit it
        self.context = context
        self.nodes: dict[str, Any] = {}
        self._closed = False
        self._close_lock = threading.Lock()
        self._watch = ThreadWatch(on_death=self._on_thread_death)
        overrides = options.overrides()
        self.namespace = normalise_namespace(options.namespace)
        placed = namespace_arguments(self.namespace)
        self.executor = MultiThreadedExecutor(num_threads=num_threads, context=context)
        self._spinners = [Spinner(self.executor, context, 'graph_executor', self._watch),
                          Spinner(EventsExecutor(context=context), context, 'graph_events_executor', self._watch)]
        quick = self._spinners[1].executor
        self.api_node = None  # the robot API's clients, on the events executor
        self.client_nodes: list[Any] = []  # nodes holding other nodes' perception clients, on the events executor
        profile = options.profile()
        self.hardware = profile is not None
        try:
            self.domain = get_domain(options.domain_name())
            # The twin first (when programs are rehearsed): lmp_node finds it running.
            self.twin_placed = namespace_arguments(twin_namespace(self.namespace or '/'))
            if overrides.get('lmp_node', {}).get('rehearse', 'off') != 'off':  # lmp_node will rehearse
                twin_values = options.twin_overrides()
                for spec in twin_nodes(self.domain):
                    self._add_node(spec, f'twin/{spec.name}', twin_values.get(spec.name, {}), self.twin_placed)
            for spec in graph_nodes(self.domain, hardware=self.hardware):
                # lmp_node's worker thread reports its death to the graph's watch, like the executors' threads.
                watched = {'thread_watch': self._watch} if spec is LMP_NODE else {}
                given = (node_arguments or {}).get(spec.name, {})  # a test's own constructor arguments
                self._add_node(spec, spec.name, overrides.get(spec.name, {}), placed, {**watched, **given})
            twin = getattr(self.nodes['lmp_node'], 'twin', None)
            if twin is not None:  # its robot API's clients, on the twin's clock
                quick.add_node(twin.node)
            # Perception's answers reach every client of its services in the process, waking each client's
            # executor: all of them live on the events executor, where a wake-up for another client is cheap.
            sim_time = [Parameter('use_sim_time', value=not self.hardware)]
            api_placed = dict(placed)
            if profile is not None:  # the robot's own servers under the names the profile gives them
                from cap_bringup.hardware import robot_api_remappings
                remaps = [argument for name, target in robot_api_remappings(profile)
                          for argument in ('-r', f'{name}:={target}')]
                if remaps:
                    api_placed['cli_args'] = [*placed.get('cli_args', ['--ros-args']), *remaps]
            self.api_node = rclpy.create_node('lmp_node_robot_api', context=context, parameter_overrides=sim_time,
                                              **api_placed)
            quick.add_node(self.api_node)
            bind_clients = getattr(self.nodes['lmp_node'].robot, 'bind_clients', None)
            if bind_clients is not None:  # a domain's binding may keep its clients on lmp_node itself
                bind_clients(self.api_node)
            # A control node that asks perception (pick-and-place) moves those clients onto a node of the events
            # executor, for the same reason.
            for name, node in self.nodes.items():
                bind_perception = getattr(node, 'bind_perception_clients', None)
                if bind_perception is None:
                    continue
                clients = rclpy.create_node(f'{name.rpartition("/")[2]}_perception_clients', context=context,
                                            parameter_overrides=self._sim_time(name, sim_time),
                                            **self._placement(name, placed))
                self.client_nodes.append(clients)
                quick.add_node(clients)
                bind_perception(clients)
            # A controller's loop asks once per tick (controller_node's clients of the plant's step and of the
            # controller's call, the simulator's step service): nodes with such endpoints move them onto a node of
            # the events executor too (`bind_quick`).
            for name, node in self.nodes.items():
                bind_quick = getattr(node, 'bind_quick', None)
                if bind_quick is None:
                    continue
                endpoints = rclpy.create_node(f'{name.rpartition("/")[2]}_quick', context=context,
                                              parameter_overrides=self._sim_time(name, sim_time),
                                              **self._placement(name, placed))
                self.client_nodes.append(endpoints)
                quick.add_node(endpoints)
                bind_quick(endpoints)
        except BaseException:
            self.close()
            raise
        self._previous_sigterm = _install_sigterm_exit()
        _close_at_exit(self)
        for spinner in self._spinners:
            spinner.start()

    def _add_node(self, spec, key: str, overrides: dict[str, Any], placed: dict[str, Any],
                  arguments: dict[str, Any] | None = None) -> None:
        """Make the node `spec` names with its package's config and `overrides`, keep it as self.nodes[key] and
        put it on the executor that suits it."""
        from_config = config_parameters(spec.package, spec.config_file)
        values = {**from_config.get('/**', {}), **from_config.get(spec.name, {}), **overrides}
        node = node_class(spec)(context=self.context, parameter_overrides=[
            Parameter(name, value=value) for name, value in values.items()], **placed, **(arguments or {}))
        self.nodes[key] = node
        if is_quick(spec.name, values):
            self._spinners[1].executor.add_node(node)
        else:  # a wait set rebuilt in Python at every wake-up: only what can wake it (qos_events.py)
            drop_default_event_handlers(node)
            self.executor.add_node(node)

    def _placement(self, key: str, placed: dict[str, Any]) -> dict[str, Any]:
        """Where a helper node of self.nodes[key] goes: beside it, in the twin's namespace for a twin's node."""
        return self.twin_placed if key.startswith('twin/') else placed

    def _sim_time(self, key: str, sim_time: list) -> list:
        return [Parameter('use_sim_time', value=True)] if key.startswith('twin/') else sim_time

    def __enter__(self) -> 'Graph':
        return self

    def __exit__(self, *_exc) -> None:
        self.close()

    @property
    def events_executor(self):
        """The executor of the quick request-response path (perception's services, the robot API's clients)."""
        return self._spinners[1].executor

    @property
    def world(self):
        """The simulator's world (for images and ground truth in demos and checks)."""
        return self.nodes['sim_bridge'].world

    @property
    def failed(self) -> threading.Event:
        """Set when a thread the graph depends on died: the graph no longer answers."""
        return self._watch.died

    @property
    def failure(self) -> str:
        """Which thread died and why ('' while the graph is healthy)."""
        return self._watch.failure

    def _on_thread_death(self, failure: str) -> None:
        print(f'error: the graph no longer answers: {failure}', file=sys.stderr, flush=True)

    def _let_callbacks_end(self, timeout_s: float) -> None:
        """Keep spinning until the callbacks running now have returned (within `timeout_s`).

        An action's callback that waits for a motion or a program ends only once the stop has gone round the
        graph (a cancel request and its answer, the simulator's trajectory), which needs the executors running.
        """
        in_flight = [task for task in list(getattr(self.executor, '_futures', ())) if not task.done()]
        deadline = time.monotonic() + timeout_s
        while any(not task.done() for task in in_flight) and time.monotonic() < deadline:
            if self._watch.died.is_set() or not self.context.ok():
                return  # nothing spins any more: waiting would only cost the timeout
            time.sleep(0.01)

    def _destroy_nodes(self) -> None:
        nodes = list(self.nodes.values()) + self.client_nodes + ([self.api_node] if self.api_node is not None else [])
        for node in reversed(nodes):
            try:
                node.destroy_node()
            except Exception:  # shutting down: keep going with the other nodes
                pass

    def close(self) -> None:
        """Stop what runs, end the executors' threads, destroy the nodes. Idempotent; safe from any thread."""
        with self._close_lock:
            if self._closed:
                return
            self._closed = True
        self._watch.stop()
        lmp = self.nodes.get('lmp_node')
        if lmp is not None:  # a running program and its motion end now, so their callbacks can return
            try:
                lmp.stop('the graph is shutting down')
            except Exception:  # a node half built or already gone: nothing to stop
                pass
        self._let_callbacks_end(self.CLOSE_TIMEOUT_S)
        for spinner in self._spinners:
            spinner.stop(self.CLOSE_TIMEOUT_S)
        for spinner in self._spinners:
            spinner.finish(self.CLOSE_TIMEOUT_S)
        self._destroy_nodes()
        _restore_sigterm(getattr(self, '_previous_sigterm', None))
        _OPEN_GRAPHS.discard(self)


def _install_sigterm_exit():
    """Make SIGTERM raise SystemExit(143) in the main thread if it still has its default action; return the old one.

    Dying on the default action would skip every cleanup: the sandbox process would outlive the graph.
    """
    if threading.current_thread() is not threading.main_thread():
        return None
    if signal.getsignal(signal.SIGTERM) is not signal.SIG_DFL:
        return None  # the program chose its own handling (cap up does)

    def exit_on_sigterm(signum, _frame):
        raise SystemExit(128 + signum)

    signal.signal(signal.SIGTERM, exit_on_sigterm)
    return signal.SIG_DFL


def _restore_sigterm(previous) -> None:
    if previous is not None and threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, previous)
