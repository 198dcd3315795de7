"""/tf and /tf_static in and out of the graph: a listener that fills a TransformBuffer (cap_ros_common.transforms,
standing in for tf2_ros's, which is not on PyPI) and the conversions of TransformStamped messages. tf2's topics and
QoS, so RViz, robot_state_publisher and real drivers meet the graph on them."""
from __future__ import annotations

from typing import Callable, Iterable

from geometry_msgs.msg import TransformStamped
from tf2_msgs.msg import TFMessage

from cap_ros_common.qos import TF_QOS, TF_STATIC_LISTENER_QOS, TF_STATIC_QOS
from cap_ros_common.time import time_msg, to_seconds
from cap_ros_common.transforms import Transform, TransformBuffer

# Relative names, like every name of the graph: under a namespace they move with it.
TF_TOPIC = 'tf'
TF_STATIC_TOPIC = 'tf_static'


def transform_from_msg(message: TransformStamped) -> Transform:
    t, r = message.transform.translation, message.transform.rotation
    return Transform(message.header.frame_id, message.child_frame_id, to_seconds(message.header.stamp),
                     (t.x, t.y, t.z), (r.x, r.y, r.z, r.w))


def transform_msg(transform: Transform) -> TransformStamped:
    message = TransformStamped()
    message.header.stamp = time_msg(transform.stamp)
    message.header.frame_id, message.child_frame_id = transform.parent, transform.child
    t, r = message.transform.translation, message.transform.rotation
    t.x, t.y, t.z = (float(v) for v in transform.translation)
    r.x, r.y, r.z, r.w = (float(v) for v in transform.rotation)
    return message


def tf_message(transforms: Iterable[Transform]) -> TFMessage:
    return TFMessage(transforms=[transform_msg(transform) for transform in transforms])


class TfListener:
    """Subscribes `node` to /tf and /tf_static and keeps what arrives in `buffer`; `on_update()`, if given, is called
    after each message is taken."""

    def __init__(self, node, buffer: TransformBuffer | None = None, callback_group=None,
                 on_update: Callable[[], None] | None = None) -> None:
        self.buffer = buffer or TransformBuffer()
        self._node = node
        self._on_update = on_update
        self._subscriptions = [
            node.create_subscription(TFMessage, TF_TOPIC, lambda m: self._take(m, False), TF_QOS,
                                     callback_group=callback_group),
            node.create_subscription(TFMessage, TF_STATIC_TOPIC, lambda m: self._take(m, True), TF_STATIC_LISTENER_QOS,
                                     callback_group=callback_group)]

    def destroy(self) -> None:
        """Stop listening (a binding that moves to another node makes a new listener there)."""
        for subscription in self._subscriptions:
            self._node.destroy_subscription(subscription)
        self._subscriptions = []

    def _take(self, message: TFMessage, static: bool) -> None:
        transforms = []
        for item in message.transforms:
            transform = transform_from_msg(item)
            try:
                transform.matrix()
            except ValueError:
                continue  # not a pose (a zero quaternion, a NaN): tf2 drops it too
            transforms.append(transform)
        self.buffer.add(transforms, static=static)
        if self._on_update is not None:
            self._on_update()


class TfBroadcaster:
    """Sends transforms on /tf, and on /tf_static the node's whole set of fixed ones (each static message replaces
    the publisher's last, so the set is always sent together, as tf2's static broadcaster does)."""

    def __init__(self, node) -> None:
        self._tf = node.create_publisher(TFMessage, TF_TOPIC, TF_QOS)
        self._static = node.create_publisher(TFMessage, TF_STATIC_TOPIC, TF_STATIC_QOS)
        self._fixed: dict[str, Transform] = {}

    def send(self, transforms: Iterable[Transform]) -> None:
        message = tf_message(transforms)
        if message.transforms:
            self._tf.publish(message)

    def send_static(self, transforms: Iterable[Transform]) -> None:
        self._fixed.update({transform.child: transform for transform in transforms})
        self._static.publish(tf_message(self._fixed.values()))


__all__ = ['TF_STATIC_TOPIC', 'TF_TOPIC', 'TfBroadcaster', 'TfListener', 'tf_message', 'transform_from_msg',
           'transform_msg']
