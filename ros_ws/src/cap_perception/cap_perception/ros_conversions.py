"""PerceivedObject <-> cap_interfaces/ObjectState. Messages only, no rclpy, so it is tested without a ROS graph."""
from __future__ import annotations

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
