"""The table-top robot API of generated code, bound to the graph's perception services and pick-place action.

Object names, positions, `say` and the plumbing of calls and goals are the shared RosRobotApi's
(cap_lmp_ros.domains.ros_api); this adds the table top's object details, pick-and-place, and the bookkeeping that
"undo that" needs.
"""
from __future__ import annotations

from typing import Any, Callable

import numpy as np
from geometry_msgs.msg import Point
from cap_ros_common.actions import ActionClient
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node

from cap_interfaces.action import PickPlace
from cap_interfaces.msg import GraphNames
from cap_lmp.errors import RobotApiError, StoppedError
from cap_lmp_ros.domains.object_names import object_name_candidate
from cap_lmp_ros.domains.ros_api import MAX_NAME_CHARS, MAX_SAY_CHARS, RosRobotApi
from cap_tabletop.workspace import named_place


class RosTabletopApi(RosRobotApi):
    """get_obj_names, get_obj_pos, get_bbox, get_color, is_obj_visible, put_first_on_second and say over ROS."""

    def __init__(self, node: Node, say_publisher, service_timeout_s: float = 5.0,
                 motion_timeout_s: float = 180.0) -> None:
        super().__init__(node, say_publisher, service_timeout_s, motion_timeout_s)
        # Where the objects moved by this command, and by the last command that moved any, were before it moved
        # them: what "undo that" needs (get_pos_before_last_command).
        self._moved_from: dict[str, np.ndarray] = {}
        self._last_moved_from: dict[str, np.ndarray] = {}

    def _create_clients(self, node: Node) -> None:
        super()._create_clients(node)
        self._pick_place = ActionClient(node, PickPlace, GraphNames.PICK_PLACE_ACTION,
                                        callback_group=ReentrantCallbackGroup())

    def _clients(self) -> list[Any]:
        return super()._clients() + [self._pick_place]

    def functions(self) -> dict[str, Callable[..., Any]]:
        """The names generated code sees."""
        return {'get_obj_names': self.get_obj_names, 'get_obj_pos': self.get_obj_pos, 'get_bbox': self.get_bbox,
                'get_color': self.get_color, 'is_obj_visible': self.is_obj_visible,
                'put_first_on_second': self.put_first_on_second, 'say': self.say,
                'get_pos_before_last_command': self.get_pos_before_last_command}

    def begin_command(self) -> None:
        """A new command starts: the moves of the one before become "the last command's" (if it moved anything)."""
        if self._moved_from:
            self._last_moved_from, self._moved_from = self._moved_from, {}

    def get_pos_before_last_command(self, name: str) -> np.ndarray:
        """Where the object was before the last command that moved objects (where it is, if that one left it)."""
        name = self._name(name)
        if name in self._last_moved_from:
            return self._last_moved_from[name].copy()
        return self.get_obj_pos(name)

    # -------------------------------------------------------------------------------------------- perception
    def _place(self, name: Any) -> tuple[str, np.ndarray] | None:
        """A place on the table that `name` means ("the middle", "the top left corner"), when no object on the
        table has that name: (its name as given, its position). A program passes a place where an object or a
        position is expected; what it means is not in doubt."""
        if not isinstance(name, str) or name in self._known_names:
            return None
        candidate = object_name_candidate(name)
        place = named_place(candidate) if candidate else None
        if place is None or candidate in self.get_obj_names():
            return None
        return candidate, np.array(place, dtype=float)

    def get_obj_pos(self, name: str) -> np.ndarray:
        """Centre of the object on the table, np.array([x, y]) in metres; for a place on the table ("the
        middle", "the bottom left corner"), that place."""
        place = self._place(name)
        return place[1].copy() if place is not None else super().get_obj_pos(name)

    def get_bbox(self, name: str) -> np.ndarray:
        """The object's footprint on the table, np.array([x_min, y_min, x_max, y_max]) in metres."""
        state = self._object(name)
        return np.array([state.bbox_min.x, state.bbox_min.y, state.bbox_max.x, state.bbox_max.y])

    def get_color(self, name: str) -> str:
        """The object's colour name, e.g. 'red'."""
        return self._object(name).color_name

    def is_obj_visible(self, name: str) -> bool:
        """Whether perception currently sees the object (False for unknown names)."""
        try:
            return bool(self._object(name).visible)
        except RobotApiError:
            return False

    # -------------------------------------------------------------------------------------------- motion
    def put_first_on_second(self, obj_name: str, target: Any) -> None:
        """Pick up `obj_name` and place it on `target`: an object name, or a table position [x, y] in metres."""
        obj_name = self._name(obj_name)
        start_pos = self._moved_from.get(obj_name)
        if start_pos is None:
            start_pos = self.get_obj_pos(obj_name)
        goal = PickPlace.Goal(object_name=obj_name)
        if isinstance(target, (list, tuple)) and len(target) == 1 and isinstance(target[0], str):
            target = target[0]  # a one-name list, as parse_obj_name answers
        place = self._place(target)
        if place is not None:  # "the middle": that point of the table
            where, target = f'the {place[0]}', place[1]
        if isinstance(target, str):
            target = self._name(target)
            goal.target_name = target
            where = f'the {target}'
        else:
            try:
                x, y = (float(v) for v in np.asarray(target, dtype=float).reshape(-1)[:2])
            except (TypeError, ValueError):
                raise RobotApiError(f'put_first_on_second needs an object name or an [x, y] position as its '
                                    f'target, not {target!r}') from None
            if not (np.isfinite(x) and np.isfinite(y)):
                raise RobotApiError(f'the target position ({x}, {y}) is not a number')
            goal.target_position = Point(x=x, y=y, z=0.0)
            where = where if place is not None else f'({x:.3f}, {y:.3f})'
        result = self._run_goal(self._pick_place, goal, 'the pick-and-place controller',
                                f'the pick-and-place controller refused to move the {obj_name}')
        if self.stop_requested.is_set() or result.error_code == PickPlace.Result.CANCELLED:
            raise StoppedError(f'stopped while moving the {obj_name} to {where}')
        if result.error_code != PickPlace.Result.NONE:
            raise RobotApiError(result.error_msg or f'could not put the {obj_name} on {where}')
        self._moved_from.setdefault(obj_name, start_pos)  # moved: where it was is what "undo that" needs


__all__ = ['MAX_NAME_CHARS', 'MAX_SAY_CHARS', 'RosTabletopApi']
