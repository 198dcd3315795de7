"""visualization: the markers RViz on a regular ROS 2 install shows over the robot (whose model and links come from
/robot_description and /tf), from the graph's names only.

- /cap/markers (visualization_msgs/MarkerArray, reliable, transient local, keep last 1, so a late RViz gets the
  latest): perception's objects with their names, the plan of the command waiting for approval (kept while it runs
  after approval), the workspace bounds (markers.py). Perception is asked (GetObjectNames, GetObjectState) at
  `rate_hz`, and only while somebody subscribes: an unwatched graph pays nothing but a timer.

Requests never block: each answer's callback sends the next request, so the node fits a single-threaded executor.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from rclpy.node import Node
from visualization_msgs.msg import MarkerArray

from cap_bringup.markers import Bounds, scene_markers
from cap_interfaces.msg import GraphNames, StatusEvent
from cap_interfaces.srv import GetObjectNames, GetObjectState
from cap_lmp_ros.lmp_node import EVENT_QOS
from cap_ros_common.nodes import spin_node
from cap_ros_common.parameters import declare_config, parameter
from cap_ros_common.qos import LATCHED_QOS
from cap_tabletop.workspace import TABLE_X_RANGE, TABLE_Y_RANGE, TABLE_Z

_FINAL = (StatusEvent.STAGE_DONE, StatusEvent.STAGE_ERROR, StatusEvent.STAGE_CANCELLED, StatusEvent.STAGE_REFUSED)


@dataclass(frozen=True)
class VisualizationConfig:
    rate_hz: float = parameter(2.0, 'How often the markers are refreshed from perception while subscribed [Hz].')
    frame_id: str = parameter('world', 'Frame of the markers: the frame perception\'s positions are in.')
    x_min: float = parameter(TABLE_X_RANGE[0], 'Workspace bounds shown [m, world frame].')
    x_max: float = parameter(TABLE_X_RANGE[1], 'Workspace bounds shown [m, world frame].')
    y_min: float = parameter(TABLE_Y_RANGE[0], 'Workspace bounds shown [m, world frame].')
    y_max: float = parameter(TABLE_Y_RANGE[1], 'Workspace bounds shown [m, world frame].')
    z: float = parameter(TABLE_Z, 'Height of the workspace bounds [m, world frame].')


class VisualizationNode(Node):
    """See the module docstring."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('visualization', **kwargs)
        config = self.config = declare_config(self, VisualizationConfig)
        self.bounds = Bounds(config.x_min, config.x_max, config.y_min, config.y_max, config.z)
        self._markers = self.create_publisher(MarkerArray, GraphNames.MARKERS_TOPIC, LATCHED_QOS)
        self._names = self.create_client(GetObjectNames, GraphNames.PERCEPTION_OBJECT_NAMES_SERVICE)
        self._state = self.create_client(GetObjectState, GraphNames.PERCEPTION_OBJECT_STATE_SERVICE)
        self.create_subscription(StatusEvent, GraphNames.STATUS_TOPIC, self._on_status, EVENT_QOS)
        self.objects: list[Any] = []  # perception's latest ObjectStates
        self.plan: list[Any] = []  # PlannedMotion steps of the command waiting for approval or running after it
        self._plan_command = ''
        self._asking = False
        self.create_timer(1.0 / config.rate_hz, self._refresh)

    def _on_status(self, status: StatusEvent) -> None:
        if status.stage == StatusEvent.STAGE_AWAITING_APPROVAL:
            self.plan, self._plan_command = list(status.plan), status.command_id
            self._publish()
        elif status.command_id == self._plan_command and status.stage in _FINAL:
            self.plan, self._plan_command = [], ''
            self._publish()

    def _refresh(self) -> None:
        if self._asking or self._markers.get_subscription_count() == 0:
            return
        if not (self._names.service_is_ready() and self._state.service_is_ready()):
            self._publish()  # the bounds (and a plan) at least
            return
        self._asking = True
        self._names.call_async(GetObjectNames.Request()).add_done_callback(self._on_names)

    def _on_names(self, future: Any) -> None:
        names = list(future.result().names) if future.result() is not None else []
        states: dict[str, Any] = {}
        if not names:
            self._finish(states, names)
            return
        for name in names:
            def answered(done: Any, name: str = name) -> None:
                response = done.result()
                states[name] = response.state if response is not None and response.success else None
                if len(states) == len(names):
                    self._finish(states, names)
            self._state.call_async(GetObjectState.Request(name=name)).add_done_callback(answered)

    def _finish(self, states: dict[str, Any], names: list[str]) -> None:
        self.objects = [states[name] for name in names if states.get(name) is not None]
        self._asking = False
        self._publish()

    def _publish(self) -> None:
        self._markers.publish(scene_markers(self.objects, self.plan, self.bounds, self.config.frame_id,
                                            self.get_clock().now().to_msg()))


def main(args: list[str] | None = None) -> None:
    """The `visualization_node` entry point."""
    spin_node(VisualizationNode, args)
