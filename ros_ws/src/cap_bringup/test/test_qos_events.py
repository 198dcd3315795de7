"""Without its default QoS event handlers a node still publishes and receives: only the wait set shrinks."""
import rclpy
from rclpy.event_handler import EventHandler
from rclpy.executors import MultiThreadedExecutor
from std_msgs.msg import String

from cap_bringup.qos_events import drop_default_event_handlers


def test_a_node_without_its_event_handlers_still_publishes_and_receives(ros_context, spin_until):
    node = rclpy.create_node('quiet_events', context=ros_context)
    received = []
    publisher = node.create_publisher(String, 'chatter', 10)
    node.create_subscription(String, 'chatter', lambda message: received.append(message.data), 10)
    # Two handlers (incompatible QoS, incompatible type) for each publisher and subscription, /parameter_events
    # included.
    assert drop_default_event_handlers(node) >= 4
    assert not [waitable for waitable in node.waitables if isinstance(waitable, EventHandler)]
    executor = MultiThreadedExecutor(num_threads=2, context=ros_context)
    executor.add_node(node)

    def heard() -> bool:
        publisher.publish(String(data='hello'))
        return bool(received)

    try:
        assert spin_until(executor, heard)
        assert received[0] == 'hello'
        assert node.destroy_publisher(publisher)  # as it would with handlers of its own
    finally:
        executor.shutdown()
        node.destroy_node()
