"""The RViz markers say what perception and the plan say: a shape and a name per object, an arrow per planned move
from the object to its target, the workspace's edge."""
from __future__ import annotations

from geometry_msgs.msg import Point
from visualization_msgs.msg import Marker

from cap_bringup.markers import Bounds, scene_markers
from cap_interfaces.msg import ObjectState, PlannedMotion


def _object(name: str, x: float, y: float, category: str, visible: bool = True) -> ObjectState:
    state = ObjectState(name=name, category=category, visible=visible)
    half = 0.02 if category == 'block' else 0.07
    state.position = Point(x=x, y=y, z=0.02)
    state.bbox_min = Point(x=x - half, y=y - half, z=0.0)
    state.bbox_max = Point(x=x + half, y=y + half, z=0.04)
    state.orientation.w = 1.0
    return state


def test_objects_plan_and_bounds_become_markers():
    objects = [_object('red block', 0.1, -0.4, 'block'), _object('blue bowl', -0.1, -0.6, 'bowl', visible=False)]
    plan = [PlannedMotion(function='put_first_on_second', object_name='red block', target_name='blue bowl',
                          description='put the red block on the blue bowl'),
            PlannedMotion(function='put_first_on_second', object_name='red block',
                          points=[Point(x=0.2, y=-0.3, z=0.0)], description='put the red block at (0.200, -0.300)'),
            PlannedMotion(function='say', description="say 'done'")]
    markers = scene_markers(objects, plan, Bounds(-0.3, 0.3, -0.8, -0.2), 'world', None).markers
    assert markers[0].action == Marker.DELETEALL
    names = {m.text: m for m in markers if m.ns == 'object_names'}
    assert set(names) == {'red block', 'blue bowl'}
    assert (names['red block'].pose.position.x, names['red block'].pose.position.y) == (0.1, -0.4)
    shapes = {m.id: m for m in markers if m.ns == 'objects'}
    assert shapes[0].type == Marker.CUBE and abs(shapes[0].scale.x - 0.04) < 1e-9
    assert shapes[1].type == Marker.CYLINDER and shapes[1].color.a < 0.5  # remembered, not seen
    arrows = [m for m in markers if m.ns == 'plan' and m.type == Marker.ARROW]
    assert [(a.points[0].x, a.points[1].x, a.points[1].y) for a in arrows] == [(0.1, -0.1, -0.6), (0.1, 0.2, -0.3)]
    labels = [m.text for m in markers if m.ns == 'plan' and m.type == Marker.TEXT_VIEW_FACING]
    assert labels == ['1. put the red block on the blue bowl', '2. put the red block at (0.200, -0.300)']
    (edge,) = [m for m in markers if m.ns == 'workspace']
    assert [(p.x, p.y) for p in edge.points] == [(-0.3, -0.8), (0.3, -0.8), (0.3, -0.2), (-0.3, -0.2), (-0.3, -0.8)]
    assert all(m.header.frame_id == 'world' for m in markers)
