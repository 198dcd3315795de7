"""lmp_node over DDS for tests: the node, the real perception node on stub objects, and a user node.

The user node keeps what the graph publishes (statuses, said lines, code), publishes commands and stops, and sends
/cap/execute goals, /cap/reset_session requests and parameter changes; an executor spins everything in a thread.
"""
from __future__ import annotations

import threading
import time
from typing import Any, Callable

from cap_ros_common.actions import ActionClient
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter, parameter_value_to_python
from rclpy.parameter_client import AsyncParameterClient
from std_msgs.msg import Empty, String
from std_srvs.srv import Trigger

from cap_interfaces.action import ExecuteCommand
from cap_interfaces.msg import GraphNames, StatusEvent
from cap_lmp_ros.lmp_node import COMMAND_QOS, EVENT_QOS, LmpNode
from cap_perception.perception_node import PerceptionNode

TWO_BLOCKS = ('objects:\n'
              '  - {color: red, category: block, position: [0.1, -0.5, 0.02]}\n'
              '  - {color: blue, category: block, position: [-0.1, -0.6, 0.02]}\n')


def wait_for(predicate: Callable[[], Any], timeout: float = 20.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.01)
    return bool(predicate())


class LmpGraph:
    def __init__(self, context, tmp_path, lmp_parameters: list[Parameter], objects: str = TWO_BLOCKS) -> None:
        stub = tmp_path / 'objects.yaml'
        stub.write_text(objects)
        self.perception = PerceptionNode(context=context, parameter_overrides=[
            Parameter('source', value='stub'), Parameter('stub_file', value=str(stub))])
        self.lmp = LmpNode(context=context, parameter_overrides=lmp_parameters)
        self.user = Node('user', context=context)
        self.statuses: list[StatusEvent] = []
        self.said: list[str] = []
        self.code: list[str] = []
        self.user.create_subscription(StatusEvent, GraphNames.STATUS_TOPIC, self.statuses.append, EVENT_QOS)
        self.user.create_subscription(String, GraphNames.SAY_TOPIC, lambda m: self.said.append(m.data), EVENT_QOS)
        self.user.create_subscription(String, GraphNames.CODE_TOPIC, lambda m: self.code.append(m.data), EVENT_QOS)
        self.commands = self.user.create_publisher(String, GraphNames.COMMAND_TOPIC, COMMAND_QOS)
        self.stop = self.user.create_publisher(Empty, GraphNames.STOP_TOPIC, COMMAND_QOS)
        self.execute = ActionClient(self.user, ExecuteCommand, GraphNames.EXECUTE_ACTION)
        self.reset = self.user.create_client(Trigger, GraphNames.RESET_SESSION_SERVICE)
        self.parameters = AsyncParameterClient(self.user, 'lmp_node')
        self.executor = MultiThreadedExecutor(num_threads=6, context=context)
        for node in (self.perception, self.lmp, self.user):
            self.executor.add_node(node)
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()
        assert wait_for(lambda: self.commands.get_subscription_count() == 1 and self.execute.server_is_ready()
                        and self.parameters.services_are_ready())

    def stages(self, command_id: str) -> list[int]:
        return [s.stage for s in list(self.statuses) if s.command_id == command_id]

    def final(self, command_id: str) -> StatusEvent | None:
        for status in reversed(list(self.statuses)):
            if status.command_id == command_id and status.stage >= StatusEvent.STAGE_DONE:
                return status
        return None

    def run(self, command: str, timeout: float = 30.0):
        """Send through /cap/execute; return the wrapped result (status, result)."""
        done = threading.Event()
        box: dict[str, Any] = {}

        def on_goal(future) -> None:
            box['handle'] = future.result()
            box['handle'].get_result_async().add_done_callback(lambda f: (box.update(result=f.result()),
                                                                           done.set()))
        self.execute.send_goal_async(ExecuteCommand.Goal(command=command)).add_done_callback(on_goal)
        assert done.wait(timeout), f'no result for {command!r}'
        return box['result']

    def set_parameter(self, name: str, value: Any):
        future = self.parameters.set_parameters([Parameter(name, value=value)])
        assert wait_for(future.done)
        return future.result().results[0]

    def get_parameter(self, name: str) -> Any:
        future = self.parameters.get_parameters([name])
        assert wait_for(future.done)
        return parameter_value_to_python(future.result().values[0])

    def close(self) -> None:
        self.executor.shutdown()
        self.thread.join(5)
        for node in (self.perception, self.lmp, self.user):
            node.destroy_node()
