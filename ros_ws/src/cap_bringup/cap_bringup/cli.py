"""`cap`: the command line of cap-ros (works without ros2cli).

    cap up --seed 3                                  bring up the whole simulated graph (Ctrl-C stops it)
    cap up --namespace robot1                        ... with every name under /robot1 (a second robot beside)
    cap up --console                                 ... and the web console at http://127.0.0.1:8765/
    cap console --port 8765                          the web console of a graph that is up (cap_bringup/console)
    cap send "put the red block in the blue bowl"   run a command, follow it to the end (exit 0: it ran to the end)
    cap stop                                         stop the running program and every motion
    cap approve [--reject]                           approve (or reject) the program waiting for approval
    cap snapshot --camera top --out snapshots/       save the cameras' current images as PNG
    cap urdf > ur5e_gripper.urdf                     the robot's URDF, as /robot_description carries it
    cap up --hardware my_robot.yaml                  the graph on a real robot (a hardware profile), after a preflight
    cap preflight my_robot.yaml                      check that the robot offers what its profile names
    cap standin ur5e_robotiq_d435                    a simulator that plays the profile's robot (for hardware mode)
    cap demo [NAME]                                  a domain's demo (cap_bringup/demos; the table top's without NAME)
    cap bench tabletop --trials 1                    the paper's table-top benchmark (cap bench: the others)

Every command takes --namespace (the graph's names are relative; `cap send --namespace robot1 "..."` talks to the
graph brought up with `cap up --namespace robot1`). Uses the ROS_DOMAIN_ID of the environment; discovery stays on
this host unless ROS_AUTOMATIC_DISCOVERY_RANGE says otherwise.

Exit codes: 0 done (for `cap send`: the program ran to the end and reported success); 1 failed (the program
failed or was refused); 2 unreachable or misconfigured (nobody offers
the action within --wait, no acknowledgement, a bad option, `cap up` missing a setting: one `error:` line says
what); 3 timed out (`cap send --timeout` bounds the whole command, whatever phase it is in; the command is then
cancelled); 130 / 143 ended by SIGINT (Ctrl-C) / SIGTERM, within a fraction of a second (`cap send` first asks
lmp_node to cancel, waiting at most 2 s). `cap up` ends with 0 on either signal (that is how it is stopped), and
with 70 when a thread the graph depends on died (one `error:` line names it): it does not live on unanswering.
Everything printed that comes from the graph or the user (code, said lines, messages, the command echoed) has its
control characters escaped (cap_lmp.safe_text.terminal_text).
"""
from __future__ import annotations

import argparse
import os
import pathlib
import signal
import sys
import threading
import time
from typing import Any, Callable, Sequence

from cap_bringup.namespaces import normalise_namespace
from cap_lmp.safe_text import one_line, terminal_text
from cap_tabletop.cameras import CAMERA_NAMES

# Exit codes (README, "Commanding the robot yourself"). A command ended by SIGINT (Ctrl-C) or SIGTERM exits
# 128 + the signal's number, 130 or 143, as shells report it; `cap up` exits 0 there, that is how it is stopped.
EXIT_OK, EXIT_FAILED, EXIT_UNREACHABLE, EXIT_TIMEOUT = 0, 1, 2, 3
CANCEL_GRACE_S = 2.0  # after --timeout or a signal: how long `cap send` waits for lmp_node to accept the cancel
SAY_DRAIN_S = 0.3  # after the result: time for the last /cap/say lines to arrive
# Once lmp_node is found: how long `cap send` waits for it to have found this process too (see _ReplyPath)
# before it sends anyway. lmp_node publishes its first status when it starts, so the wait ends as soon as it has.
REPLY_PATH_WAIT_S = 10.0


class Interrupted(BaseException):
    """SIGINT or SIGTERM arrived while a command waited (a BaseException, like KeyboardInterrupt)."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.exit_code = 128 + signum


class _Signals:
    """SIGINT and SIGTERM only note the signal; the waiting loops check it (every spin slice) and end the command.

    rclpy's own handlers are not installed: they shut the context down and swallow SIGTERM, so a command kept on
    waiting for an answer that could no longer come.
    """

    def __init__(self) -> None:
        self.received: int | None = None
        self.event = threading.Event()
        if threading.current_thread() is threading.main_thread():
            for signum in (signal.SIGINT, signal.SIGTERM):
                signal.signal(signum, self._note)

    def _note(self, signum, _frame) -> None:
        if self.received is None:
            self.received = signum
        self.event.set()

    def check(self) -> None:
        if self.received is not None:
            raise Interrupted(self.received)


_installed: list[_Signals] = []


def _signals() -> _Signals:
    """The process's one _Signals, installed on first use (main() does it first, before the slow imports)."""
    if not _installed:
        _installed.append(_Signals())
    return _installed[0]


class _Session:
    """rclpy context, one node and a single-threaded executor for the duration of one CLI command."""

    SLICE_S = 0.05  # longest wait inside rclpy: bounds how late a signal or a deadline is noticed

    def __init__(self, name: str, namespace: str = '') -> None:
        os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
        import rclpy
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.signals import SignalHandlerOptions

        self.signals = _signals()
        self.context = Context()
        rclpy.init(context=self.context, signal_handler_options=SignalHandlerOptions.NO)
        # The graph's names are relative: a node in the graph's namespace finds them under it.
        self.node = rclpy.create_node(name, context=self.context, namespace=normalise_namespace(namespace))
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def spin_until(self, predicate: Callable[[], bool], timeout: float, interruptible: bool = True) -> bool:
        """Spin until predicate() holds (True) or `timeout` [s] passes (False); a signal raises Interrupted."""
        deadline = time.monotonic() + max(0.0, timeout)
        while not predicate():
            if interruptible:
                self.signals.check()
            if time.monotonic() >= deadline:
                return False
            self.executor.spin_once(timeout_sec=min(self.SLICE_S, max(0.0, deadline - time.monotonic())))
        return True

    def close(self) -> None:
        self.executor.shutdown(timeout_sec=0)
        self.node.destroy_node()
        self.context.try_shutdown()


def _say(text: str, out=None) -> None:
    """Print a line that holds text from the graph (or from the user): never a raw control character."""
    print(terminal_text(text), file=out or sys.stdout, flush=True)


def _error(text: str) -> None:
    _say(text, sys.stderr)


class _ReplyPath:
    """Whether lmp_node has discovered this process' reply readers, so that its answers can reach it.

    Discovery is not symmetric. `server_is_ready()` says that this process found lmp_node's endpoints, not that
    lmp_node found this process' reply readers; a reply sent before then is lost (Fast DDS waits 100 ms for the
    reader, then drops the reply; rclpy's action server then keeps the goal accepted but never runs it, ros2/ros2
    issue 1253), and `cap send` would wait for an acknowledgement that never comes. lmp_node publishes on
    /cap/status from its start, reliably and transient-local: a reader created after the action client receives
    that history once lmp_node's participant has matched it, and a participant matches another's readers in the
    order they were announced, so by then it has matched the action client's reply readers as well.
    """

    def __init__(self, node) -> None:
        from cap_ros_common.qos import LATCHED_QOS

        from cap_interfaces.msg import GraphNames, StatusEvent

        self.heard = False
        self._subscription = node.create_subscription(StatusEvent, GraphNames.STATUS_TOPIC, self._on_status,
                                                      LATCHED_QOS)

    def _on_status(self, _status) -> None:
        self.heard = True

    def is_open(self) -> bool:
        return self.heard


def send(command: str, server_timeout: float, timeout: float, out=None, namespace: str = '') -> int:
    """Send one command through the /cap/execute action, print its progress and return the exit code.

    `timeout` [s] bounds the whole command, every phase included (finding lmp_node, the acknowledgement, the
    result); `server_timeout` [s] bounds finding lmp_node and the acknowledgement. When the time is up, or on
    SIGINT/SIGTERM, the command asks lmp_node to cancel (waiting at most CANCEL_GRACE_S) and ends.
    """
    from cap_ros_common.actions import ActionClient
    from std_msgs.msg import String

    from cap_interfaces.action import ExecuteCommand
    from cap_interfaces.msg import GraphNames, StatusEvent

    out = out or sys.stdout
    deadline = time.monotonic() + timeout
    session = _Session('cap_send', namespace)
    client = ActionClient(session.node, ExecuteCommand, GraphNames.EXECUTE_ACTION)
    reply_path = _ReplyPath(session.node)  # after the action client: see _ReplyPath
    execute_name = session.node.resolve_topic_name(GraphNames.EXECUTE_ACTION)  # e.g. /robot1/cap/execute
    session.node.create_subscription(String, GraphNames.SAY_TOPIC, lambda m: _say(f'robot says: {m.data}', out),
                                     10)
    stage_names = {getattr(StatusEvent, name): name[len('STAGE_'):].lower()
                   for name in dir(StatusEvent) if name.startswith('STAGE_')}
    last_stage: list[int] = []
    goal_handle = None
    goal_future = None

    def on_feedback(message) -> None:
        status = message.feedback.status
        if last_stage and last_stage[-1] == status.stage:
            return
        last_stage.append(status.stage)
        if status.stage == StatusEvent.STAGE_CODE:
            _say('code:\n' + '\n'.join('    ' + line for line in status.code.splitlines()), out)
        else:
            detail = f': {status.message}' if status.message else ''
            _say(f'[{stage_names.get(status.stage, status.stage)}]{detail}', out)

    def left() -> float:
        return deadline - time.monotonic()

    def timed_out(phase: str) -> int:
        _error(f'error: timed out after {timeout:g} s (--timeout) {phase}')
        return EXIT_TIMEOUT

    def cancel() -> bool:
        """Ask lmp_node to cancel the goal; True when it answered within the grace."""
        handle = goal_handle
        if handle is None and goal_future is not None:
            # Sent, but its acceptance is not here yet (a signal in between): the program may already run, so
            # wait for the handle within the grace and cancel it then.
            if session.spin_until(goal_future.done, CANCEL_GRACE_S, interruptible=False):
                handle = goal_future.result()
        if handle is None or not handle.accepted:
            return False
        future = handle.cancel_goal_async()
        return session.spin_until(future.done, CANCEL_GRACE_S, interruptible=False)

    try:
        if not session.spin_until(client.server_is_ready, min(server_timeout, left())):
            if left() <= 0.01:  # the overall deadline, not --wait, ended the wait
                return timed_out(f'waiting for lmp_node ({execute_name})')
            _error(f'error: nobody offers {execute_name}; is the graph up (cap up)? '
                   f'ROS_DOMAIN_ID={os.environ.get("ROS_DOMAIN_ID", "0")}')
            return EXIT_UNREACHABLE
        # Not found in time is no error: a lost acknowledgement then ends the wait below with its message.
        session.spin_until(reply_path.is_open, min(REPLY_PATH_WAIT_S, left()))
        _say(f'> {command}', out)
        goal_future = client.send_goal_async(ExecuteCommand.Goal(command=command), feedback_callback=on_feedback)
        if not session.spin_until(goal_future.done, min(server_timeout, left())):
            if left() <= 0.01:  # the overall deadline, not --wait, ended the wait
                return timed_out('waiting for lmp_node to acknowledge the command')
            _error(f'error: lmp_node did not acknowledge the command within {server_timeout:g} s (--wait)')
            return EXIT_UNREACHABLE
        goal_handle = goal_future.result()
        if not goal_handle.accepted:
            _error('refused: lmp_node rejected the goal')  # it accepts every goal and answers refusals in the result
            return EXIT_FAILED
        result_future = goal_handle.get_result_async()
        if not session.spin_until(result_future.done, left()):
            cancelled = cancel()
            return timed_out('waiting for the result; ' + ('the command was cancelled' if cancelled else
                                                            f'lmp_node did not answer the cancel within '
                                                            f'{CANCEL_GRACE_S:g} s'))
        result = result_future.result().result
        # What the robot said came on another topic: lines still in flight would be lost when the process ends.
        session.spin_until(lambda: False, SAY_DRAIN_S)
        if result.outcome == ExecuteCommand.Result.OUTCOME_REFUSED:
            _say(result.message, out)  # says why (an empty command, a full queue, ...)
        else:
            _say(('success' if result.success else 'failed') + (f': {result.message}' if result.message else ''),
                 out)
        return EXIT_OK if result.success else EXIT_FAILED
    except Interrupted as interrupted:
        if goal_future is not None:
            _error(f'interrupted ({interrupted}): ' + ('the command was cancelled' if cancel() else
                                                       'lmp_node did not answer the cancel'))
        else:
            _error(f'interrupted ({interrupted})')
        return interrupted.exit_code
    finally:
        session.close()


def approve(approved: bool, reason: str, command_id: str, server_timeout: float, namespace: str = '') -> int:
    """Approve or reject the command waiting for approval (lmp_node's require_approval): the one `command_id` names,
    else the one /cap/status says waits. Exit 0 when lmp_node took the answer, 1 when no such command waits."""
    from cap_interfaces.msg import GraphNames, StatusEvent
    from cap_interfaces.srv import ApproveCommand
    from cap_lmp_ros.lmp_node import EVENT_QOS

    session = _Session('cap_approve', namespace)
    waiting: dict[str, StatusEvent] = {}

    def on_status(status: StatusEvent) -> None:
        if status.stage == StatusEvent.STAGE_AWAITING_APPROVAL:
            waiting[status.command_id] = status
        elif status.stage in (StatusEvent.STAGE_DONE, StatusEvent.STAGE_ERROR, StatusEvent.STAGE_CANCELLED,
                              StatusEvent.STAGE_REFUSED):
            waiting.pop(status.command_id, None)

    try:
        client = session.node.create_client(ApproveCommand, GraphNames.APPROVE_SERVICE)
        heard: list[bool] = []  # the status history (lmp_node's recent events) arrived
        session.node.create_subscription(StatusEvent, GraphNames.STATUS_TOPIC,
                                         lambda status: (heard.append(True), on_status(status)), EVENT_QOS)
        if not session.spin_until(lambda: client.service_is_ready() and heard, server_timeout):
            _error(f'error: nobody offers {session.node.resolve_topic_name(GraphNames.APPROVE_SERVICE)} with its '
                   'status history; is the graph up (cap up)?')
            return EXIT_UNREACHABLE
        session.spin_until(lambda: False, SAY_DRAIN_S)  # the rest of the history
        if not command_id:
            if not waiting:
                _say('no command waits for approval')
                return EXIT_FAILED
            command_id = list(waiting)[-1]
        status = waiting.get(command_id)
        if status is not None:
            _say(f'{command_id}: {status.command}\n' + '\n'.join('    ' + line for line in status.code.splitlines()))
            _say('plan: ' + ('; '.join(step.description for step in status.plan) or 'no robot action'))
            rehearsed = status.message.partition('; rehearsed on the twin')[2]
            if rehearsed:  # what the rehearsal on the twin found (the console shows its picture too)
                _say('rehearsed on the twin' + rehearsed)
        future = client.call_async(ApproveCommand.Request(command_id=command_id, approve=approved, reason=reason))
        if not session.spin_until(future.done, server_timeout):
            _error(f'error: lmp_node did not answer within {server_timeout:g} s (--wait)')
            return EXIT_UNREACHABLE
        response = future.result()
        _say(response.message)
        return EXIT_OK if response.success else EXIT_FAILED
    except Interrupted as interrupted:
        _error(f'interrupted ({interrupted})')
        return interrupted.exit_code
    finally:
        session.close()


def stop(server_timeout: float, namespace: str = '') -> int:
    """Publish on /cap/stop once somebody listens."""
    from std_msgs.msg import Empty

    from cap_interfaces.msg import GraphNames

    session = _Session('cap_stop', namespace)
    try:
        publisher = session.node.create_publisher(Empty, GraphNames.STOP_TOPIC, 10)
        if not session.spin_until(lambda: publisher.get_subscription_count() > 0, server_timeout):
            _error(f'error: nobody listens on {session.node.resolve_topic_name(GraphNames.STOP_TOPIC)}')
            return EXIT_UNREACHABLE
        publisher.publish(Empty())
        # Give DDS a moment to deliver before the process exits.
        session.spin_until(lambda: False, 0.3)
        print(f'stop sent to {publisher.get_subscription_count()} listener(s)')
        return EXIT_OK
    except Interrupted as interrupted:
        _error(f'interrupted ({interrupted})')
        return interrupted.exit_code
    finally:
        session.close()


def snapshot(cameras: Sequence[str], out_dir: pathlib.Path, server_timeout: float, namespace: str = '') -> int:
    """Save one colour image per camera as PNG."""
    import cv2
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import Image

    from cap_interfaces.msg import GraphNames
    from cap_perception.ros_conversions import image_to_array

    session = _Session('cap_snapshot', namespace)
    images: dict[str, Image] = {}
    # Reliable, as the bridge publishes: one whole frame is wanted, and a best-effort frame of a megabyte loses a
    # fragment now and then (the idle bridge sends a frame a second, so a lost one would cost the wait).
    frame_qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE)
    try:
        for camera in cameras:
            session.node.create_subscription(Image, f'{GraphNames.CAMERA_NAMESPACE}/{camera}/color',
                                             lambda m, c=camera: images.setdefault(c, m), frame_qos)
        if not session.spin_until(lambda: len(images) == len(cameras), server_timeout):
            missing = ', '.join(sorted(set(cameras) - set(images)))
            _error(f'error: no image from camera(s) {missing} within {server_timeout:g} s')
            return EXIT_UNREACHABLE
        out_dir.mkdir(parents=True, exist_ok=True)
        for camera, msg in images.items():
            path = out_dir / f'{camera}.png'
            cv2.imwrite(str(path), image_to_array(msg)[..., ::-1])
            _say(str(path))
        return EXIT_OK
    except Interrupted as interrupted:
        _error(f'interrupted ({interrupted})')
        return interrupted.exit_code
    finally:
        session.close()


def choose_backend(backend: str, model_file: str = '', cassette: str = '') -> str:
    """'auto': the cassette when one is named, else the local model when `make model` installed it (or --model-file
    names one), else the packaged cassette."""
    if backend != 'auto':
        return backend
    if cassette:
        return 'cassette'
    if model_file:  # a model named: the local backend, with its own error if the file is missing
        return 'local'
    from cap_lmp.local_server import local_model_installed
    return 'local' if local_model_installed(model_file) else 'cassette'


def console(port: int, namespace: str = '') -> int:
    """Serve the web console of the graph (in this namespace) on 127.0.0.1:`port` until Ctrl-C or SIGTERM.

    Exits 0 when stopped, 2 when the port cannot be had (one line says so).
    """
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from rclpy.signals import SignalHandlerOptions

    from cap_bringup.console.node import ConsoleNode

    signals = _signals()
    context = Context()
    rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    node = None
    executor = SingleThreadedExecutor(context=context)
    try:
        try:
            node = ConsoleNode(context=context, namespace=normalise_namespace(namespace),
                               parameter_overrides=[Parameter('port', value=port)])
        except OSError as error:
            _error(f'error: {one_line(str(error))}')
            return EXIT_UNREACHABLE
        executor.add_node(node)
        _say(f'console: {node.url}  (Ctrl-C stops it)')
        while not signals.event.is_set() and context.ok():
            executor.spin_once(timeout_sec=0.2)
        return EXIT_OK
    finally:
        executor.shutdown(timeout_sec=0)
        if node is not None:
            node.destroy_node()
        context.try_shutdown()


def _start_console(port: int, namespace: str, graph_cpu: int, allowed: list[int]) -> Any:
    """`cap console` as a process of its own beside the graph, on the CPUs (of `allowed`, the process' CPUs before
    the graph pinned it) the graph is not pinned to: its web server and JPEG encoding then never take the graph's
    interpreter lock or its CPU."""
    import subprocess

    from cap_bringup.cpu_affinity import cpus_besides

    command = [sys.executable, '-m', 'cap_bringup.cli', 'console', '--port', str(port)]
    if namespace:
        command += ['--namespace', namespace]
    process = subprocess.Popen(command, stdin=subprocess.DEVNULL)
    others = cpus_besides(graph_cpu, allowed)
    if others:
        try:
            os.sched_setaffinity(process.pid, others)
        except OSError:  # the process ended already (its error is on stderr) or the CPU is not ours
            pass
    return process


def _end_console(process: Any) -> None:
    if process is None or process.poll() is not None:
        return
    process.terminate()
    try:
        process.wait(5.0)
    except Exception:  # it did not end: kill it
        process.kill()
        process.wait()


def preflight(profile_path: str, wait_s: float, context=None) -> int:
    """`cap preflight PROFILE`: one line per action, topic or frame the robot lacks (exit 1), or that it passed (0)."""
    from cap_bringup.preflight import run_preflight
    from cap_hardware.profile import ProfileError, load_profile

    try:
        profile = load_profile(profile_path)
    except ProfileError as error:
        _error(f'error: {one_line(str(error))}')
        return EXIT_UNREACHABLE
    if context is None:
        session = _Session('cap_preflight')
        node, spin_once, close = session.node, lambda t: session.executor.spin_once(timeout_sec=t), session.close
    else:  # cap up --hardware: in the graph's context, before the graph
        import rclpy
        from rclpy.executors import SingleThreadedExecutor

        node = rclpy.create_node('cap_preflight', context=context)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        spin_once = lambda t: executor.spin_once(timeout_sec=t)  # noqa: E731

        def close() -> None:
            executor.shutdown(timeout_sec=0)
            node.destroy_node()
    try:
        return EXIT_OK if run_preflight(node, spin_once, profile, wait_s, log=_say) else EXIT_FAILED
    finally:
        close()


def standin(profile_path: str, seed: int, objects: str, perturbation_seed: int, serve_gripper: bool) -> int:
    """`cap standin PROFILE`: a simulator that plays the profile's robot, until Ctrl-C or SIGTERM."""
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    import rclpy
    from rclpy.context import Context
    from rclpy.signals import SignalHandlerOptions

    from cap_bringup.standin import StandIn
    from cap_hardware.profile import ProfileError

    signals = _signals()
    context = Context()
    rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    robot = None
    try:
        try:
            robot = StandIn(context, profile_path, seed, objects, perturbation_seed, serve_gripper)
        except (ValueError, ProfileError) as error:
            _error(f'error: {one_line(str(error))}')
            return EXIT_UNREACHABLE
        _say(f'stand-in for {profile_path} is up (ROS_DOMAIN_ID={os.environ.get("ROS_DOMAIN_ID", "0")}): '
             f'{", ".join(robot.nodes)}. Stop with Ctrl-C.')
        signals.event.wait()
        _say('shutting down')
        return EXIT_OK
    finally:
        if robot is not None:
            robot.close()
        context.try_shutdown()


def up(seed: int, objects: str, real_time: bool, perception: str, backend: str, cassette: str,
       record: bool, namespace: str = '', domain: str = 'tabletop', cpu: int = 0, model_file: str = '',
       model_threads: int = 1, console_port: int | None = None, require_approval: bool = False,
       hardware: str = '', preflight_wait: float = 5.0, feedback_rounds: int = 0, rehearse: str = '') -> int:
    """Bring up sim bridge, perception, pick-and-place and lmp_node in this process until Ctrl-C or SIGTERM (and,
    with `console_port`, the web console in a process of its own beside it). With `hardware` (a profile), the
    graph of that real robot instead, once its preflight has passed.

    Exits 0 when stopped by a signal, FATAL_EXIT_CODE (70) when a thread the graph depends on died (the graph no
    longer answered), 2 when the graph cannot be built as configured (one line says what to set), 1 when the
    robot lacks what its profile names (one line per missing piece).
    """
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    import rclpy
    from rclpy.context import Context
    from rclpy.signals import SignalHandlerOptions

    from cap_lmp.errors import CapLLMError
    from cap_bringup.graph import Graph, GraphOptions
    from cap_lmp_ros.thread_watch import FATAL_EXIT_CODE

    signals = _signals()
    context = Context()
    rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    graph = None
    console_process = None
    allowed = sorted(os.sched_getaffinity(0)) if hasattr(os, 'sched_getaffinity') else []  # before the pin
    backend = choose_backend(backend, model_file, cassette)
    lmp: dict[str, Any] = {'require_approval': True} if require_approval else {}
    if feedback_rounds:
        lmp['feedback_rounds'] = feedback_rounds
    if backend == 'local':
        lmp.update(model_file=model_file, model_threads=model_threads)
        _say('language model: the local model server (loading; /cap/status says "model ready" when it is)')
    elif backend == 'cassette':
        _say('language model: the replay cassette (its recorded commands only; `make model` installs a local model)')
    try:
        if hardware:
            _say(f'hardware mode: {hardware}; checking that the robot offers what the profile names ...')
            checked = preflight(hardware, preflight_wait, context)
            if checked != EXIT_OK:
                return checked
        try:
            graph = Graph(context, GraphOptions(seed=seed, objects=objects, real_time=real_time,
                                                perception=perception, llm_backend=backend, cassette=cassette,
                                                record_cassette=record, namespace=namespace, domain=domain,
                                                cpu=cpu, extra={'lmp_node': lmp} if lmp else {}, hardware=hardware,
                                                rehearse=rehearse))
        except (ValueError, CapLLMError) as error:  # a configuration the user can fix: say what, in one line
            _error(f'error: {one_line(str(error))}')
            return EXIT_UNREACHABLE
        if console_port is not None and signals.received is None:
            console_process = _start_console(console_port, namespace, cpu, allowed)
        if signals.received is None:
            where = f', namespace {graph.namespace}' if graph.namespace else ''
            flag = f' --namespace {graph.namespace.lstrip("/")}' if graph.namespace else ''
            _say(f'cap-ros is up (ROS_DOMAIN_ID={os.environ.get("ROS_DOMAIN_ID", "0")}{where}): '
                 f'{", ".join(graph.nodes)}. Send commands with: cap send{flag} "..."  Stop with Ctrl-C.')
        while not signals.event.wait(0.2):
            if graph.failed.is_set():  # the graph has said why (stderr); a zombie graph must not live on
                _say('shutting down: the graph no longer answers')
                return FATAL_EXIT_CODE
        _say('shutting down')
        return EXIT_OK
    finally:
        _end_console(console_process)
        if graph is not None:
            graph.close()
        context.try_shutdown()


BENCH_USAGE = """usage: cap bench NAME [options]   (options: cap bench NAME --help)
       NAME: {names}

The paper's simulated table-top benchmark through the cap-ros graph, e.g.
    cap bench tabletop --trials 1                   one episode of every row with the reference programs
    cap bench tabletop --policy llm --jobs 2        programs from CAP_LLM_BASE_URL / CAP_LLM_MODEL, two graphs
    cap bench devset --policy llm --backend local   the table-top development set with the local model
The other domains through their graphs, e.g.
    cap bench whiteboard --trials 20                drawing and erasing, judged on the ink
    cap bench controllers --trials 5                generated controllers: balance, push, track
    cap bench mobile --trials 20                    the mobile robot in the kitchen: drive, fetch, put away, count
The paper's language-side tables through the engine and the sandbox process (no graph), e.g.
    cap bench codegen                               robot code generation, flat and hierarchical (oracle)
    cap bench humaneval --policy llm --jobs 2       HumanEval with the model at CAP_LLM_BASE_URL
    cap bench reasoning --policy llm                spatial reasoning: code, vanilla and chain-of-thought answers
The results page, docs/results.md, from the runs kept in results/:
    cap bench results --add output/bench            keep a run's report, then write the page from all kept runs
"""


BENCHMARK_GROUP = 'cap_ros.benchmarks'


def demo_usage() -> str:
    """`cap demo --help`: the demos installed (cap_bringup.demos), each with the first line of its description."""
    from cap_bringup.demos import DEFAULT_DEMO, DEMOS

    lines = ['usage: cap demo [NAME] [options]   (options: cap demo NAME --help)', '',
             "A domain's plain-language commands through the whole graph in simulation, each checked on the "
             "simulator's state.", 'NAME:']
    for name in DEMOS.names():
        try:
            about = ' '.join((sys.modules[DEMOS.get(name).__module__].__doc__ or '').split('\n\n')[0].split())
        except (ValueError, KeyError) as error:  # a broken demo is listed with what is wrong
            about = str(error)
        lines.append(f'  {name + (" (default)" if name == DEFAULT_DEMO else ""):22s}{about}')
    return '\n'.join(lines) + '\n'


def demo(argv: Sequence[str]) -> int:
    """`cap demo [NAME] [options]`: runs the demo NAME (the table top's without one) with the options."""
    from cap_bringup.demos import DEFAULT_DEMO, DEMOS

    argv = [a for a in argv if a != '--']
    if argv[:1] in (['-h'], ['--help'], ['help']):
        print(demo_usage(), end='')
        return EXIT_OK
    name, options = (argv[0], argv[1:]) if argv and not argv[0].startswith('-') else (DEFAULT_DEMO, argv)
    try:
        run = DEMOS.get(name)
    except ValueError as error:  # an unknown name, or a demo that cannot be loaded: one line, naming the known ones
        _error(f'cap demo: error: {error}')
        return EXIT_UNREACHABLE
    return int(run(options))


def benchmarks():
    """The benchmarks packages above this one offer (entry points of the group `cap_ros.benchmarks`, value: a
    main(argv)). A benchmark builds on the graph, so its package sits above bringup and registers itself; bringup
    never names it."""
    from cap_ros_common.plugins import PluginGroup

    return PluginGroup(BENCHMARK_GROUP, 'benchmark', callable)


def bench(argv: Sequence[str]) -> int:
    """`cap bench NAME ...`: runs the registered benchmark NAME; anything else prints the usage."""
    offered = benchmarks()
    names = offered.names()
    usage = BENCH_USAGE.format(names=' | '.join(names) or 'none installed')
    if argv[:1] and argv[0] in names:
        try:
            main = offered.get(argv[0])
        except ValueError as error:  # offered twice, or broken: one line says which
            _error(f'cap bench: error: {one_line(str(error))}')
            return EXIT_UNREACHABLE
        return int(main(list(argv[1:])))
    if list(argv) in (['-h'], ['--help'], ['help']):
        print(usage, end='')
        return EXIT_OK
    print(usage, end='', file=sys.stderr)
    problem = f'unknown benchmark {argv[0]!r}' if argv else 'choose a benchmark'
    _error(f'cap bench: error: {problem} (installed: {", ".join(names) or "none"})')
    return EXIT_UNREACHABLE


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog='cap', description='Command a cap-ros robot in plain language.')
    commands = parser.add_subparsers(dest='command', required=True)
    p_up = commands.add_parser('up', help='bring up the simulated table-top graph (sim, perception, control, lmp)')
    p_up.add_argument('--namespace', default='', help='the graph\'s namespace, e.g. robot1 [none]')
    p_up.add_argument('--seed', type=int, default=0, help='scene seed [0]')
    p_up.add_argument('--objects', default='', help='comma-separated objects, e.g. "red block, blue bowl"')
    p_up.add_argument('--fast', action='store_true',
                      help='simulate as fast as possible (default: in real time, as a robot moves; an idle graph '
                           'then costs a few percent of a core)')
    p_up.add_argument('--perception', choices=('ground_truth', 'rgbd'), default='ground_truth')
    p_up.add_argument('--backend', choices=('auto', 'local', 'cassette', 'http'), default='auto',
                      help='local (the llama.cpp server and model of `make model`), cassette (offline replay), '
                           'http (CAP_LLM_BASE_URL, CAP_LLM_MODEL, CAP_LLM_API_KEY); auto: local when installed, '
                           'else cassette [auto]')
    p_up.add_argument('--model-file', default='', help='with --backend local: a GGUF model file [the default '
                      'model of `make model`]')
    p_up.add_argument('--model-threads', type=int, default=1, help='with --backend local: threads of the model '
                      'server [1]')
    p_up.add_argument('--cassette', default='', help='cassette file (default: the packaged reference cassette)')
    p_up.add_argument('--record', action='store_true', help='with --backend http: record answers into --cassette')
    p_up.add_argument('--cpu', type=int, default=0, help='pin the graph to this one of the allowed CPUs [0]; give '
                      'a second graph beside it another')
    p_up.add_argument('--domain', default='tabletop', help='the domain whose prompts, robot API and scene run '
                      '[tabletop]')
    p_up.add_argument('--feedback-rounds', type=int, default=0, help='a program that failed while running is '
                      'followed by one the model writes from what happened, up to this many times per command '
                      '(lmp_node\'s feedback_rounds); 0: one program per command, the paper\'s protocol [0]')
    p_up.add_argument('--rehearse', choices=('always', 'on_approval', 'off'), default='',
                      help='rehearse each program on a twin of the scene (a simulator beside the graph) before the '
                      'robot moves; a program that fails or does harm there is refused [off in simulation, always '
                      'with --hardware]')
    p_up.add_argument('--require-approval', action='store_true', help='hold each generated program until it is '
                      'approved (cap approve, or the console), after a plan-only run lists its robot actions')
    p_up.add_argument('--console', action='store_true', help='also serve the web console (cap console) on '
                      '127.0.0.1, in a process of its own')
    p_up.add_argument('--console-port', type=int, default=8765, help='port of the web console [8765]')
    p_up.add_argument('--hardware', default='', metavar='PROFILE', help='a real robot instead of the simulator: its '
                      'hardware profile (a YAML file, or a shipped profile: ur5e_robotiq_d435, '
                      'mobile_manipulator_nav2); a preflight checks the robot first')
    p_up.add_argument('--preflight-wait', type=float, default=5.0, help='with --hardware: how long the preflight '
                      'looks for what is missing [5 s]')
    p_pre = commands.add_parser('preflight', help='check that a real robot offers every action, topic and frame its '
                                'hardware profile names (exit 1 and one line per missing piece)')
    p_pre.add_argument('profile', help='the hardware profile (a YAML file or a shipped profile\'s name)')
    p_pre.add_argument('--wait', type=float, default=5.0, help='look for this long before calling a piece missing '
                       '[5 s]')
    p_standin = commands.add_parser('standin', help='a simulator that plays the robot of a hardware profile (its '
                                    'names, units, camera; perturbed physics and sensors; no ground truth)')
    p_standin.add_argument('profile', help='the hardware profile (a YAML file or a shipped profile\'s name)')
    p_standin.add_argument('--seed', type=int, default=0, help='scene seed [0]')
    p_standin.add_argument('--objects', default='', help='comma-separated objects, e.g. "red block, blue bowl"')
    p_standin.add_argument('--perturbation-seed', type=int, default=0, help='seed of the differences from the '
                           'graph\'s simulator [0]')
    p_standin.add_argument('--without-gripper', action='store_true', help='do not serve the gripper action (a '
                           'robot whose gripper controller is down)')
    p_console = commands.add_parser('console', help='serve the web console of a running graph on 127.0.0.1: '
                                    'cameras, commands, code, approval, stop')
    p_console.add_argument('--namespace', default='', help='the graph\'s namespace, e.g. robot1 [none]')
    p_console.add_argument('--port', type=int, default=8765, help='port on 127.0.0.1; 0: a free one [8765]')
    commands.add_parser('demo', help='run a domain\'s demo: `cap demo [NAME] [options]`, the table top\'s without '
                        'NAME (the demos: cap demo --help)', add_help=False)
    commands.add_parser('bench', help='the paper\'s benchmarks: tabletop, codegen, humaneval, reasoning (cap bench '
                        '--help)', add_help=False)
    p_send = commands.add_parser('send', help='run a natural-language command and follow it to the end',
                                 epilog='exit status: 0 the program ran to the end (whether it did what was asked '
                                        'is for you to see), 1 it failed or was refused, 2 no graph or '
                                        'misconfigured, 3 --timeout passed, 130/143 Ctrl-C/SIGTERM')
    p_send.add_argument('--namespace', default='', help='the graph\'s namespace, e.g. robot1 [none]')
    p_send.add_argument('text', help='the command, e.g. "put the red block in the blue bowl"')
    p_send.add_argument('--timeout', type=float, default=600.0, help='give up after this many seconds [600]')
    p_send.add_argument('--wait', type=float, default=10.0, help='wait this long for lmp_node [10 s]')
    p_approve = commands.add_parser('approve', help='approve (or reject) the program waiting for approval '
                                    '(cap up --require-approval)')
    p_approve.add_argument('--namespace', default='', help='the graph\'s namespace, e.g. robot1 [none]')
    p_approve.add_argument('--reject', action='store_true', help='reject it: it does not run')
    p_approve.add_argument('--reason', default='', help='words for the record (shown with a rejection)')
    p_approve.add_argument('--id', default='', help='the command id (cmd-N) [the one waiting]')
    p_approve.add_argument('--wait', type=float, default=10.0, help='wait this long for lmp_node [10 s]')
    p_stop = commands.add_parser('stop', help='stop the running program and every motion')
    p_stop.add_argument('--namespace', default='', help='the graph\'s namespace, e.g. robot1 [none]')
    p_stop.add_argument('--wait', type=float, default=5.0, help='wait this long for a listener [5 s]')
    p_urdf = commands.add_parser('urdf', help='print the robot\'s URDF (what /robot_description carries), e.g. for '
                                 'robot_state_publisher')
    p_urdf.add_argument('--scene', default='tabletop', help='the simulator scene whose robot it is [tabletop]')
    p_snap = commands.add_parser('snapshot', help='save camera images as PNG')
    p_snap.add_argument('--namespace', default='', help='the graph\'s namespace, e.g. robot1 [none]')
    p_snap.add_argument('--camera', action='append', help='camera name (repeatable; default: front and top)')
    p_snap.add_argument('--out', type=pathlib.Path, default=pathlib.Path('snapshots'), help='output folder')
    p_snap.add_argument('--wait', type=float, default=10.0, help='wait this long for images [10 s]')
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    for stream in (sys.stdout, sys.stderr):  # a terminal that cannot show a character gets an escape, not a crash
        if hasattr(stream, 'reconfigure'):
            stream.reconfigure(errors='backslashreplace')
    if argv[:1] == ['demo']:
        return demo(argv[1:])
    if argv[:1] == ['bench']:
        return bench(argv[1:])
    args = build_parser().parse_args(argv)
    try:
        normalise_namespace(getattr(args, 'namespace', ''))
    except ValueError as error:
        _error(f'cap: error: {error}')
        return EXIT_UNREACHABLE
    _signals()  # from here on SIGINT / SIGTERM end the command cleanly (rclpy's imports take a while)
    if args.command == 'up':
        return up(args.seed, args.objects, not args.fast, args.perception, args.backend, args.cassette, args.record,
                  args.namespace, args.domain, args.cpu, args.model_file, args.model_threads,
                  args.console_port if args.console else None, args.require_approval, args.hardware,
                  args.preflight_wait, args.feedback_rounds, args.rehearse)
    if args.command == 'preflight':
        return preflight(args.profile, args.wait)
    if args.command == 'standin':
        return standin(args.profile, args.seed, args.objects, args.perturbation_seed, not args.without_gripper)
    if args.command == 'console':
        return console(args.port, args.namespace)
    if args.command == 'send':
        return send(args.text, args.wait, args.timeout, namespace=args.namespace)
    if args.command == 'stop':
        return stop(args.wait, args.namespace)
    if args.command == 'approve':
        return approve(not args.reject, args.reason, args.id, args.wait, args.namespace)
    if args.command == 'urdf':
        from cap_sim_bridge.scenes import build_model
        from cap_sim_bridge.urdf import robot_urdf
        print(robot_urdf(build_model([], args.scene)), end='')
        return EXIT_OK
    return snapshot(args.camera or list(CAMERA_NAMES), args.out, args.wait, args.namespace)


if __name__ == '__main__':
    sys.exit(main())
