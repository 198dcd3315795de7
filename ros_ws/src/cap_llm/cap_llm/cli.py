"""`cap`: the command line of cap-ros (works without ros2cli).

    cap up --seed 3                                  bring up the whole simulated graph (Ctrl-C stops it)
    cap send "put the red block in the blue bowl"   run a command, follow it to the end (exit 0 only on success)
    cap stop                                         stop the running program and every motion
    cap snapshot --camera top --out snapshots/       save the cameras' current images as PNG
    cap demo                                         the table-top demo (see cap_llm/demo.py)
    cap bench tabletop --trials 1                    the paper's table-top benchmark (see cap_bench/runner.py)

Uses the ROS_DOMAIN_ID of the environment; discovery stays on this host unless ROS_AUTOMATIC_DISCOVERY_RANGE says
otherwise.
"""
from __future__ import annotations

import argparse
import os
import pathlib
import sys
import threading
import time
from typing import Callable, Sequence

EXIT_OK, EXIT_FAILED, EXIT_UNREACHABLE = 0, 1, 2



def _spin_until(executor, predicate: Callable[[], bool], timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            return False
        executor.spin_once(timeout_sec=0.05)
    return True


class _Session:
    """rclpy context, one node and a single-threaded executor for the duration of one CLI command."""

    def __init__(self, name: str) -> None:
        os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
        import rclpy
        from rclpy.executors import SingleThreadedExecutor

        rclpy.init()
        self.rclpy = rclpy
        self.node = rclpy.create_node(name)
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        self.rclpy.try_shutdown()


def send(command: str, server_timeout: float, timeout: float, out=sys.stdout) -> int:
    """Send one command through the /cap/execute action and print its progress; return the exit code."""
    from rclpy.action import ActionClient
    from std_msgs.msg import String

    from cap_interfaces.action import ExecuteCommand
    from cap_interfaces.msg import GraphNames, StatusEvent

    session = _Session('cap_send')
    client = ActionClient(session.node, ExecuteCommand, GraphNames.EXECUTE_ACTION)
    session.node.create_subscription(String, GraphNames.SAY_TOPIC, lambda m: print(f'robot says: {m.data}',
                                                                                   file=out, flush=True), 10)
    stage_names = {getattr(StatusEvent, name): name[len('STAGE_'):].lower()
                   for name in dir(StatusEvent) if name.startswith('STAGE_')}
    last_stage: list[int] = []
    goal_handle = None

    def on_feedback(message) -> None:
        status = message.feedback.status
        if last_stage and last_stage[-1] == status.stage:
            return
        last_stage.append(status.stage)
        if status.stage == StatusEvent.STAGE_CODE:
            print('code:\n' + '\n'.join('    ' + line for line in status.code.splitlines()), file=out, flush=True)
        else:
            detail = f': {status.message}' if status.message else ''
            print(f'[{stage_names.get(status.stage, status.stage)}]{detail}', file=out, flush=True)

    try:
        if not client.wait_for_server(timeout_sec=server_timeout):
            print(f'error: nobody offers {GraphNames.EXECUTE_ACTION}; is the graph up (cap up)? '
                  f'ROS_DOMAIN_ID={os.environ.get("ROS_DOMAIN_ID", "0")}', file=sys.stderr)
            return EXIT_UNREACHABLE
        print(f'> {command}', file=out, flush=True)
        goal_future = client.send_goal_async(ExecuteCommand.Goal(command=command), feedback_callback=on_feedback)
        if not _spin_until(session.executor, goal_future.done, server_timeout):
            print('error: the command was not acknowledged', file=sys.stderr)
            return EXIT_UNREACHABLE
        goal_handle = goal_future.result()
        if not goal_handle.accepted:
            print('refused: lmp_node did not accept the command (another one is running?)', file=sys.stderr)
            return EXIT_FAILED
        result_future = goal_handle.get_result_async()
        if not _spin_until(session.executor, result_future.done, timeout):
            print(f'error: no result within {timeout:.0f} s; cancelling', file=sys.stderr)
            cancel = goal_handle.cancel_goal_async()
            _spin_until(session.executor, cancel.done, 5.0)
            return EXIT_FAILED
        result = result_future.result().result
        print(('success' if result.success else 'failed') + (f': {result.message}' if result.message else ''),
              file=out, flush=True)
        return EXIT_OK if result.success else EXIT_FAILED
    except KeyboardInterrupt:
        if goal_handle is not None:
            cancel = goal_handle.cancel_goal_async()
            _spin_until(session.executor, cancel.done, 5.0)
            print('cancelled', file=sys.stderr)
        return EXIT_FAILED
    finally:
        session.close()


def stop(server_timeout: float) -> int:
    """Publish on /cap/stop once somebody listens."""
    from std_msgs.msg import Empty

    from cap_interfaces.msg import GraphNames

    session = _Session('cap_stop')
    try:
        publisher = session.node.create_publisher(Empty, GraphNames.STOP_TOPIC, 10)
        if not _spin_until(session.executor, lambda: publisher.get_subscription_count() > 0, server_timeout):
            print(f'error: nobody listens on {GraphNames.STOP_TOPIC}', file=sys.stderr)
            return EXIT_UNREACHABLE
        publisher.publish(Empty())
        # Give DDS a moment to deliver before the process exits.
        _spin_until(session.executor, lambda: False, 0.3)
        print(f'stop sent to {publisher.get_subscription_count()} listener(s)')
        return EXIT_OK
    finally:
        session.close()


def snapshot(cameras: Sequence[str], out_dir: pathlib.Path, server_timeout: float) -> int:
    """Save one colour image per camera as PNG."""
    import cv2
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import Image

    from cap_interfaces.msg import GraphNames
    from cap_perception.ros_conversions import image_to_array

    session = _Session('cap_snapshot')
    images: dict[str, Image] = {}
    try:
        for camera in cameras:
            session.node.create_subscription(Image, f'{GraphNames.CAMERA_NAMESPACE}/{camera}/color',
                                             lambda m, c=camera: images.setdefault(c, m), qos_profile_sensor_data)
        if not _spin_until(session.executor, lambda: len(images) == len(cameras), server_timeout):
            missing = ', '.join(sorted(set(cameras) - set(images)))
            print(f'error: no image from camera(s) {missing} within {server_timeout:.0f} s', file=sys.stderr)
            return EXIT_UNREACHABLE
        out_dir.mkdir(parents=True, exist_ok=True)
        for camera, msg in images.items():
            path = out_dir / f'{camera}.png'
            cv2.imwrite(str(path), image_to_array(msg)[..., ::-1])
            print(path)
        return EXIT_OK
    finally:
        session.close()


def up(seed: int, objects: str, real_time: bool, perception: str, backend: str, cassette: str,
       record: bool) -> int:
    """Bring up sim bridge, perception, pick-and-place and lmp_node in this process until Ctrl-C."""
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    import rclpy
    from rclpy.context import Context

    from cap_llm.graph import Graph, GraphOptions

    import signal

    from rclpy.signals import SignalHandlerOptions

    context = Context()
    # Our own handlers: Ctrl-C (SIGINT) and SIGTERM both end the graph cleanly, whatever started this process.
    rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    stop_requested = threading.Event()
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, lambda *_: stop_requested.set())
    graph = None
    try:
        graph = Graph(context, GraphOptions(seed=seed, objects=objects, real_time=real_time, perception=perception,
                                            llm_backend=backend, cassette=cassette, record_cassette=record))
        print(f'cap-ros is up (ROS_DOMAIN_ID={os.environ.get("ROS_DOMAIN_ID", "0")}): '
              f'{", ".join(graph.nodes)}. Send commands with: cap send "..."  Stop with Ctrl-C.', flush=True)
        stop_requested.wait()
        print('shutting down', flush=True)
        return EXIT_OK
    finally:
        if graph is not None:
            graph.close()
        context.try_shutdown()


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog='cap', description='Command a cap-ros robot in plain language.')
    commands = parser.add_subparsers(dest='command', required=True)
    p_up = commands.add_parser('up', help='bring up the simulated table-top graph (sim, perception, control, lmp)')
    p_up.add_argument('--seed', type=int, default=0, help='scene seed [0]')
    p_up.add_argument('--objects', default='', help='comma-separated objects, e.g. "red block, blue bowl"')
    p_up.add_argument('--real-time', action='store_true', help='simulate in real time (default: as fast as possible)')
    p_up.add_argument('--perception', choices=('ground_truth', 'rgbd'), default='ground_truth')
    p_up.add_argument('--backend', choices=('cassette', 'http'), default='cassette',
                      help='cassette (offline replay) or http (CAP_LLM_BASE_URL, CAP_LLM_MODEL, CAP_LLM_API_KEY)')
    p_up.add_argument('--cassette', default='', help='cassette file (default: the packaged reference cassette)')
    p_up.add_argument('--record', action='store_true', help='with --backend http: record answers into --cassette')
    commands.add_parser('demo', help='run the table-top demo (options: cap demo --help)', add_help=False)
    commands.add_parser('bench', help='the paper\'s table-top benchmark (cap bench tabletop --help)', add_help=False)
    p_send = commands.add_parser('send', help='run a natural-language command and follow it to the end')
    p_send.add_argument('text', help='the command, e.g. "put the red block in the blue bowl"')
    p_send.add_argument('--timeout', type=float, default=600.0, help='give up after this many seconds [600]')
    p_send.add_argument('--wait', type=float, default=10.0, help='wait this long for lmp_node [10 s]')
    p_stop = commands.add_parser('stop', help='stop the running program and every motion')
    p_stop.add_argument('--wait', type=float, default=5.0, help='wait this long for a listener [5 s]')
    p_snap = commands.add_parser('snapshot', help='save camera images as PNG')
    p_snap.add_argument('--camera', action='append', help='camera name (repeatable; default: front and top)')
    p_snap.add_argument('--out', type=pathlib.Path, default=pathlib.Path('snapshots'), help='output folder')
    p_snap.add_argument('--wait', type=float, default=10.0, help='wait this long for images [10 s]')
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ['demo']:
        from cap_llm import demo
        return demo.main([a for a in argv[1:] if a != '--'])
    if argv[:2] == ['bench', 'tabletop']:
        # cap_bench builds on cap_llm, so it is imported only when asked for (no dependency cycle).
        from cap_bench import runner
        return runner.main(argv[2:])
    args = build_parser().parse_args(argv)
    if args.command == 'up':
        return up(args.seed, args.objects, args.real_time, args.perception, args.backend, args.cassette, args.record)
    if args.command == 'send':
        return send(args.text, args.wait, args.timeout)
    if args.command == 'stop':
        return stop(args.wait)
    return snapshot(args.camera or ['front', 'top'], args.out, args.wait)


if __name__ == '__main__':
    sys.exit(main())
