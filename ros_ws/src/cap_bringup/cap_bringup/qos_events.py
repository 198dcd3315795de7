"""The default QoS event handlers of rclpy's publishers and subscriptions, taken out of a node's wait set.

rclpy gives every publisher and subscription two handlers (incompatible QoS, incompatible type) that only log a
warning. The multi-threaded executor rebuilds its wait set in Python at every wake-up, under the interpreter lock
the whole graph shares, and on the table top those handlers were 38 of its 44 waitables (sim_bridge, pick_place
and lmp_node). Out of the wait set, they cost nothing; the warnings they would log still come from the peer, whose
side of a mismatch gets the same event (rviz2 and the `ros2` tools print it).
"""
from __future__ import annotations


def drop_default_event_handlers(node) -> int:
    """Destroy the QoS event handlers of `node`'s publishers and subscriptions (as if each had been created with
    `use_default_callbacks=False`); the number destroyed. Call it before the node's executor spins."""
    dropped = 0
    for entity in (*node.publishers, *node.subscriptions):
        for handler in entity.event_handlers:
            node.remove_waitable(handler)
            handler.destroy()
            dropped += 1
        entity.event_handlers = []  # destroy_publisher / destroy_subscription look for them in the wait set
    return dropped


__all__ = ['drop_default_event_handlers']
