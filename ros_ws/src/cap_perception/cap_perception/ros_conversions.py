"""Conversions between cap_perception types and ROS messages (ObjectState, Image). No rclpy: tested without a graph."""
from __future__ import annotations

import numpy as np
from cap_interfaces.msg import ObjectState
from geometry_msgs.msg import Point, Quaternion
from std_msgs.msg import ColorRGBA

from cap_perception.names import canonical_name
from cap_perception.objects import PerceivedObject


def _point(values) -> Point:
    return Point(x=float(values[0]), y=float(values[1]), z=float(values[2]))


def to_msg(obj: PerceivedObject) -> ObjectState:
    x, y, z, w = obj.orientation
    red, green, blue, alpha = obj.color_rgba
    return ObjectState(
        name=obj.name, category=obj.category, color_name=obj.color_name,
        color=ColorRGBA(r=float(red), g=float(green), b=float(blue), a=float(alpha)),
        position=_point(obj.position), orientation=Quaternion(x=float(x), y=float(y), z=float(z), w=float(w)),
        bbox_min=_point(obj.bbox_min), bbox_max=_point(obj.bbox_max), visible=obj.visible)


def from_msg(msg: ObjectState) -> PerceivedObject:
    def triple(point: Point) -> tuple[float, float, float]:
        return (point.x, point.y, point.z)

    return PerceivedObject(
        name=canonical_name(msg.name), category=msg.category, color_name=msg.color_name,
        position=triple(msg.position), bbox_min=triple(msg.bbox_min), bbox_max=triple(msg.bbox_max),
        orientation=(msg.orientation.x, msg.orientation.y, msg.orientation.z, msg.orientation.w),
        visible=msg.visible, color_rgba=(msg.color.r, msg.color.g, msg.color.b, msg.color.a))


def image_to_array(msg) -> np.ndarray:
    """sensor_msgs/Image -> NumPy: rgb8/bgr8/rgba8 as (H, W, 3) RGB uint8; 32FC1 as metres; 16UC1 (mm) as metres."""
    encoding = msg.encoding.lower()
    if encoding in ('rgb8', 'bgr8', 'rgba8', 'bgra8'):
        channels = 4 if encoding.endswith('a8') else 3
        rows = np.frombuffer(msg.data, dtype=np.uint8).reshape(msg.height, msg.step)
        image = rows[:, :msg.width * channels].reshape(msg.height, msg.width, channels)[..., :3]
        return image[..., ::-1].copy() if encoding.startswith('bgr') else image.copy()
    if encoding in ('32fc1', '16uc1'):
        dtype = np.dtype(np.float32 if encoding == '32fc1' else np.uint16)
        dtype = dtype.newbyteorder('>' if msg.is_bigendian else '<')
        rows = np.frombuffer(msg.data, dtype=np.uint8).reshape(msg.height, msg.step)
        image = rows[:, :msg.width * dtype.itemsize].copy().view(dtype).reshape(msg.height, msg.width)
        return image.astype(np.float32) / (1000.0 if encoding == '16uc1' else 1.0)
    raise ValueError(f'unsupported image encoding {msg.encoding!r}; expected rgb8, bgr8, 32FC1 or 16UC1')
