"""console: the web console as a ROS node (`cap console`, `cap up --console`). It talks to the graph only through
its names (cap_interfaces GraphNames), so it works against a graph in another process or on a real robot:

- /cap/status, /cap/code, /cap/say in: what the page shows (the commands with stage, code, plan, words, outcome);
- /cap/execute: the command box sends goals; /cap/stop: the stop button; /cap/reset_session; /cap/approve;
- every sensor_msgs/Image topic under cap/sim (found in the graph every `discovery_period_s`: the cameras, and any
  image a domain adds), subscribed only while a browser watches it (best effort, keep last 1, so a slow console
  never holds the simulator's publisher up).

The web server (server.py) runs in a thread of its own; whatever it asks of ROS is queued and carried out on the
executor's thread (woken by a guard condition), so rclpy objects are only touched there.
"""
from __future__ import annotations

import queue
import sys
import threading
import time
from typing import Any, Callable

import rclpy
from cap_ros_common.actions import ActionClient
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Image
from std_msgs.msg import Empty, String
from std_srvs.srv import Trigger

from cap_bringup.console.config import ConsoleConfig
from cap_bringup.console.frames import FrameChannel, RawImage
from cap_bringup.console.server import ConsoleServer
from cap_bringup.console.state import ConsoleState, StatusRecord
from cap_interfaces.action import ExecuteCommand
from cap_interfaces.msg import GraphNames, StatusEvent
from cap_interfaces.srv import ApproveCommand
from cap_lmp.safe_text import terminal_text
from cap_lmp_ros.lmp_node import COMMAND_QOS, EVENT_QOS
from cap_ros_common.parameters import declare_config
from cap_ros_common.time import to_seconds

IMAGE_TYPE = 'sensor_msgs/msg/Image'
# The newest frame only, and no resends: a console that falls behind skips frames instead of slowing the publisher.
STREAM_QOS = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.BEST_EFFORT,
                        durability=DurabilityPolicy.VOLATILE)
STAGE_NAMES = {getattr(StatusEvent, name): name[len('STAGE_'):].lower()
               for name in dir(StatusEvent) if name.startswith('STAGE_')}


def status_record(status: StatusEvent) -> StatusRecord:
    plan = tuple({'description': step.description, 'object_name': step.object_name,
                  'target_name': step.target_name, 'points': [[p.x, p.y, p.z] for p in step.points]}
                 for step in status.plan)
    twin = bytes(status.twin_image.data) if status.twin_image.format == 'png' else b''
    return StatusRecord(status.command_id, status.command, STAGE_NAMES.get(status.stage, str(status.stage)),
                        status.code, status.message, plan, to_seconds(status.header.stamp), twin)


class ConsoleNode(Node):
    """See the module docstring. `url` is where the page is served once the node is built."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('console', **kwargs)
        self.config = config = declare_config(self, ConsoleConfig)
        self.state = ConsoleState(config.history_size)
        self.state.set_namespace(self.get_namespace().rstrip('/'))
        self._requests: queue.SimpleQueue[Callable[[], None]] = queue.SimpleQueue()
        self._wake = self.create_guard_condition(self._carry_out)
        # The action client comes before the status reader: once the status history arrives, lmp_node has found
        # this node's reply readers too (see cli._ReplyPath), so a goal from the page is never lost.
        self._execute = ActionClient(self, ExecuteCommand, GraphNames.EXECUTE_ACTION)
        self._stop = self.create_publisher(Empty, GraphNames.STOP_TOPIC, COMMAND_QOS)
        self._reset = self.create_client(Trigger, GraphNames.RESET_SESSION_SERVICE)
        self._approve = self.create_client(ApproveCommand, GraphNames.APPROVE_SERVICE)
        self.create_subscription(StatusEvent, GraphNames.STATUS_TOPIC,
                                 lambda status: self.state.on_status(status_record(status)), EVENT_QOS)
        self.create_subscription(String, GraphNames.CODE_TOPIC, lambda m: self.state.on_code(m.data), EVENT_QOS)
        # Only lines said from now on: the history of /cap/say belongs to commands the page never saw.
        self.create_subscription(String, GraphNames.SAY_TOPIC, lambda m: self.state.on_say(m.data), COMMAND_QOS)
        self._channels: dict[str, FrameChannel] = {}
        self._channels_lock = threading.Lock()
        self._image_subscriptions: dict[str, Any] = {}
        self._goals: list[Any] = []  # goal futures, kept until they are answered
        self._prefix = self.resolve_topic_name(GraphNames.SIM_PREFIX).rstrip('/') + '/'
        self._discover()
        self.create_timer(config.discovery_period_s, self._discover)
        self.server = ConsoleServer(self, config.port, config.max_stream_fps)
        self.url = self.server.start()
        self.get_logger().info(f'console at {self.url}')

    # -------------------------------------------------------------------------------------------- web thread side
    def _ask(self, request: Callable[[], None]) -> None:
        """Run `request` on the executor's thread (from the web server's threads)."""
        self._requests.put(request)
        self._wake.trigger()

    def _carry_out(self) -> None:
        while True:
            try:
                request = self._requests.get_nowait()
            except queue.Empty:
                return
            try:
                request()
            except Exception as error:  # a failed request is the page's news, not the node's end
                self.state.notice('error', f'{type(error).__name__}: {error}')

    def run_command(self, text: str) -> None:
        self._ask(lambda: self._send_goal(text))

    def stop(self) -> None:
        self._ask(self._send_stop)

    def reset_session(self) -> None:
        self._ask(lambda: self._call(self._reset, Trigger.Request(), 'reset the session'))

    def approve(self, command_id: str, approve: bool) -> None:
        request = ApproveCommand.Request(command_id=command_id, approve=approve,
                                         reason='' if approve else 'rejected in the console')
        self._ask(lambda: self._call(self._approve, request, 'approve' if approve else 'reject'))

    def watch(self, topic: str) -> FrameChannel | None:
        with self._channels_lock:
            channel = self._channels.get(topic)
            if channel is None:
                return None
            channel.viewers += 1
            first = channel.viewers == 1
        if first:
            self._ask(lambda: self._subscribe(channel))
        return channel

    def unwatch(self, topic: str) -> None:
        with self._channels_lock:
            channel = self._channels.get(topic)
            if channel is None:
                return
            channel.viewers = max(0, channel.viewers - 1)
            last = channel.viewers == 0
        if last:
            self._ask(lambda: self._unsubscribe(channel))

    # -------------------------------------------------------------------------------------------- executor side
    def _send_goal(self, text: str) -> None:
        if not self._execute.server_is_ready():
            self.state.notice('error', f'nobody offers {self.resolve_topic_name(GraphNames.EXECUTE_ACTION)}: '
                                       'is the graph up?')
            return
        future = self._execute.send_goal_async(ExecuteCommand.Goal(command=text))
        self._goals.append(future)
        future.add_done_callback(self._goal_answered)

    def _goal_answered(self, future: Any) -> None:
        if future in self._goals:
            self._goals.remove(future)
        handle = future.result()
        if handle is not None and handle.accepted:
            # The result is on /cap/status as well; the handle is kept until then so the goal is not dropped.
            result = handle.get_result_async()
            self._goals.append(result)
            result.add_done_callback(lambda done: self._goals.remove(done) if done in self._goals else None)

    def _send_stop(self) -> None:
        if self._stop.get_subscription_count() == 0:
            self.state.notice('error', f'nobody listens on {self.resolve_topic_name(GraphNames.STOP_TOPIC)}')
            return
        self._stop.publish(Empty())
        self.state.notice('info', 'stop sent: the program and every motion end')

    def _call(self, client: Any, request: Any, what: str) -> None:
        if not client.service_is_ready():
            self.state.notice('error', f'cannot {what}: nobody offers {client.srv_name}')
            return
        future = client.call_async(request)

        def answered(done: Any) -> None:
            response = done.result()
            self.state.notice('info' if response.success else 'error', response.message)

        future.add_done_callback(answered)

    def _subscribe(self, channel: FrameChannel) -> None:
        if channel.viewers > 0 and channel.topic not in self._image_subscriptions:
            self._image_subscriptions[channel.topic] = self.create_subscription(
                Image, channel.topic, lambda image: channel.put(_raw(image)), STREAM_QOS)

    def _unsubscribe(self, channel: FrameChannel) -> None:
        subscription = self._image_subscriptions.get(channel.topic)
        if channel.viewers == 0 and subscription is not None:
            del self._image_subscriptions[channel.topic]
            self.destroy_subscription(subscription)

    def _discover(self) -> None:
        """Every image topic under cap/sim, as the graph offers them now."""
        topics = sorted(name for name, types in self.get_topic_names_and_types()
                        if IMAGE_TYPE in types and name.startswith(self._prefix))
        with self._channels_lock:
            for topic in topics:
                if topic not in self._channels:
                    self._channels[topic] = FrameChannel(topic, self.config.jpeg_quality)
        self.state.set_streams(topics)

    def destroy_node(self) -> None:
        self.server.close()
        super().destroy_node()


def _raw(image: Image) -> RawImage:
    return RawImage(image.encoding, image.width, image.height, image.step, image.data,
                    to_seconds(image.header.stamp), time.time())


def main(args: list[str] | None = None) -> None:
    """The `console` entry point: serve the page until Ctrl-C or SIGTERM. Prints the URL on its first line."""
    rclpy.init(args=args)
    try:
        node = ConsoleNode()
    except OSError as error:  # the port is taken: one line
        print(f'console: {terminal_text(str(error))}', file=sys.stderr)
        rclpy.try_shutdown()
        sys.exit(2)
    print(f'console: {node.url}', flush=True)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    try:
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
