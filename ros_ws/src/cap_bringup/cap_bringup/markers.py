"""RViz markers of the table top as the graph sees it: the perceived objects with their names, the plan of the
command waiting for approval (or running after it), the workspace bounds. Builds messages only (no rclpy), so
the visualization node stays thin and this is tested directly.

Namespaces (RViz lists them): `objects` (a box per block, a cylinder per bowl, in the object's colour),
`object_names` (its name above it), `plan` (an arrow from the object to its target per step, numbered),
`workspace` (the table-top bounds). Every array starts with DELETEALL, so objects that are gone disappear.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

from geometry_msgs.msg import Point
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

TEXT_HEIGHT = 0.025  # [m] of a name's letters
ABOVE = 0.03  # [m] between an object's top and its name
PLAN_HEIGHT = 0.12  # [m] above the table where the plan's arrows fly
_PLAN_COLOR = ColorRGBA(r=0.05, g=0.4, b=0.9, a=0.9)
_BOUNDS_COLOR = ColorRGBA(r=0.2, g=0.2, b=0.2, a=0.8)
_TEXT_COLOR = ColorRGBA(r=1.0, g=1.0, b=1.0, a=1.0)


@dataclass(frozen=True)
class Bounds:
    """The workspace: an axis-aligned rectangle at height z [m, world frame]."""

    x_min: float
    x_max: float
    y_min: float
    y_max: float
    z: float = 0.0


def _marker(namespace: str, number: int, kind: int, frame_id: str, stamp: Any) -> Marker:
    marker = Marker(ns=namespace, id=number, type=kind, action=Marker.ADD)
    marker.header.frame_id = frame_id
    marker.header.stamp = stamp
    marker.pose.orientation.w = 1.0
    marker.frame_locked = True
    return marker


def object_markers(objects: Sequence[Any], frame_id: str, stamp: Any) -> list[Marker]:
    """A shape and a name per perceived object (cap_interfaces/ObjectState), in the order given."""
    markers = []
    for number, state in enumerate(objects):
        size = [max(getattr(state.bbox_max, axis) - getattr(state.bbox_min, axis), 0.005) for axis in 'xyz']
        shape = _marker('objects', number, Marker.CYLINDER if state.category == 'bowl' else Marker.CUBE,
                        frame_id, stamp)
        shape.pose.position = Point(x=state.position.x, y=state.position.y, z=state.position.z)
        shape.pose.orientation = state.orientation
        shape.scale.x, shape.scale.y, shape.scale.z = size
        shape.color = ColorRGBA(r=state.color.r, g=state.color.g, b=state.color.b,
                                a=0.9 if state.visible else 0.35)  # remembered, not seen: faint
        name = _marker('object_names', number, Marker.TEXT_VIEW_FACING, frame_id, stamp)
        name.pose.position = Point(x=state.position.x, y=state.position.y, z=state.bbox_max.z + ABOVE)
        name.scale.z = TEXT_HEIGHT
        name.color = _TEXT_COLOR
        name.text = state.name
        markers += [shape, name]
    return markers


def plan_markers(steps: Sequence[Any], positions: dict[str, tuple[float, float, float]], frame_id: str,
                 stamp: Any) -> list[Marker]:
    """An arrow per step of a plan (cap_interfaces/PlannedMotion) that moves a known object to a known target,
    and its number and words at the target. Steps that move nothing (say) or name unknown objects are left out."""
    markers = []
    for number, step in enumerate(steps, 1):
        start = positions.get(step.object_name)
        end = positions.get(step.target_name) if step.target_name else (
            (step.points[-1].x, step.points[-1].y, step.points[-1].z) if step.points else None)
        if start is None or end is None:
            continue
        arrow = _marker('plan', number, Marker.ARROW, frame_id, stamp)
        arrow.points = [Point(x=start[0], y=start[1], z=start[2] + PLAN_HEIGHT),
                        Point(x=end[0], y=end[1], z=end[2] + PLAN_HEIGHT)]
        arrow.scale.x, arrow.scale.y, arrow.scale.z = 0.008, 0.02, 0.03  # shaft and head diameters, head length
        arrow.color = _PLAN_COLOR
        label = _marker('plan', 1000 + number, Marker.TEXT_VIEW_FACING, frame_id, stamp)
        label.pose.position = Point(x=end[0], y=end[1], z=end[2] + PLAN_HEIGHT + ABOVE)
        label.scale.z = TEXT_HEIGHT
        label.color = _PLAN_COLOR
        label.text = f'{number}. {step.description}'
        markers += [arrow, label]
    return markers


def workspace_marker(bounds: Bounds, frame_id: str, stamp: Any) -> Marker:
    """The workspace's edge as a closed line."""
    outline = _marker('workspace', 0, Marker.LINE_STRIP, frame_id, stamp)
    corners = [(bounds.x_min, bounds.y_min), (bounds.x_max, bounds.y_min), (bounds.x_max, bounds.y_max),
               (bounds.x_min, bounds.y_max), (bounds.x_min, bounds.y_min)]
    outline.points = [Point(x=x, y=y, z=bounds.z) for x, y in corners]
    outline.scale.x = 0.005
    outline.color = _BOUNDS_COLOR
    return outline


def scene_markers(objects: Sequence[Any], plan: Sequence[Any], bounds: Bounds, frame_id: str,
                  stamp: Any) -> MarkerArray:
    """Everything, after a DELETEALL of what was shown before."""
    clear = Marker(action=Marker.DELETEALL)
    clear.header.frame_id = frame_id
    positions = {state.name: (state.position.x, state.position.y, state.bbox_max.z) for state in objects}
    return MarkerArray(markers=[clear, *object_markers(objects, frame_id, stamp),
                                *plan_markers(plan, positions, frame_id, stamp),
                                workspace_marker(bounds, frame_id, stamp)])


__all__ = ['Bounds', 'object_markers', 'plan_markers', 'scene_markers', 'workspace_marker']
