"""lmp_node with sandbox_process: false says loudly at start-up (a WARN line and a /cap/status event) that a single
C call of a program is not bounded in its own process; with a sandbox process it says nothing of the kind."""
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter

from cap_interfaces.msg import GraphNames, StatusEvent
from cap_lmp.sandbox import IN_PROCESS_WARNING
from cap_lmp_ros.lmp_node import EVENT_QOS, LmpNode


def start_up_events(ros_context, spin_until, parameters: list[Parameter]) -> list[StatusEvent]:
    """The node's own /cap/status events (no command) once its ready event arrived."""
    node = LmpNode(context=ros_context, parameter_overrides=parameters)
    listener = Node('status_listener', context=ros_context)
    heard: list[StatusEvent] = []
    listener.create_subscription(StatusEvent, GraphNames.STATUS_TOPIC, heard.append, EVENT_QOS)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(listener)
    try:
        assert spin_until(executor, lambda: any(s.message.startswith('ready:') for s in heard))
        spin_until(executor, lambda: False, timeout=0.3)  # what else the history holds
    finally:
        executor.shutdown()
        listener.destroy_node()
        node.destroy_node()
    return [s for s in heard if not s.command_id and s.stage == StatusEvent.STAGE_MODEL]


def test_the_in_process_sandbox_is_announced_as_a_warning(ros_context, spin_until, capfd):
    events = start_up_events(ros_context, spin_until, [Parameter('sandbox_process', value=False)])
    assert [s.message for s in events if s.message.startswith('warning:')] == [IN_PROCESS_WARNING]
    assert 'in-process sandbox' in next(s.message for s in events if s.message.startswith('ready:'))
    warnings = [line for line in capfd.readouterr().err.splitlines() if '[WARN]' in line]
    assert any(IN_PROCESS_WARNING in line for line in warnings), warnings


def test_a_sandbox_process_starts_without_the_warning(ros_context, spin_until, capfd):
    events = start_up_events(ros_context, spin_until, [Parameter('jail', value='off')])
    assert not [s for s in events if s.message.startswith('warning:')]
    assert 'sandbox process' in next(s.message for s in events if s.message.startswith('ready:'))
    assert IN_PROCESS_WARNING not in capfd.readouterr().err
