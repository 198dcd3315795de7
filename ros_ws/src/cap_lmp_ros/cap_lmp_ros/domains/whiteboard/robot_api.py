"""The whiteboard robot API of generated code, bound to the graph's perception services and follow_path action.

Object names, positions, `say` and the plumbing are the shared RosRobotApi's (cap_lmp_ros.domains.ros_api); this
adds `draw(pts)` and `erase(pts)`: one stroke of the marker, or one wipe of the eraser, along the polyline through
the points (an (N, 2) array of x, y in metres). The follow_path node checks and plans the whole stroke before the
arm moves, so a shape off the board is refused with nothing drawn.
"""
from __future__ import annotations

from typing import Any, Callable

import numpy as np
from geometry_msgs.msg import Point
from cap_ros_common.actions import ActionClient
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node

from cap_interfaces.action import FollowPath
from cap_interfaces.msg import GraphNames, Stroke
from cap_lmp.errors import RobotApiError, StoppedError
from cap_lmp_ros.domains.ros_api import RosRobotApi

MAX_STROKE_POINTS = 5000  # of one draw() or erase()


def stroke_points(pts: Any, verb: str) -> np.ndarray:
    """The (N, 2) float points of what a program passed to draw or erase, or a RobotApiError saying what is wrong."""
    try:
        points = np.asarray(pts, dtype=float)
    except (TypeError, ValueError):
        raise RobotApiError(f'{verb} needs points as rows of [x, y] in metres, not {type(pts).__name__}') from None
    if points.ndim == 1 and points.size == 2:
        points = points.reshape(1, 2)  # one point: a dot
    if points.ndim != 2 or points.shape[1] not in (2, 3) or len(points) == 0:
        raise RobotApiError(f'{verb} needs points as rows of [x, y] in metres, not an array of shape '
                            f'{tuple(points.shape)}')
    if len(points) > MAX_STROKE_POINTS:
        raise RobotApiError(f'{verb} takes at most {MAX_STROKE_POINTS} points, not {len(points)}')
    if not np.all(np.isfinite(points)):
        raise RobotApiError(f'{verb} was given a point that is not a number')
    return points[:, :2]


class RosWhiteboardApi(RosRobotApi):
    """get_obj_names, get_obj_pos, draw, erase and say over ROS."""

    where = 'on the board'

    def _create_clients(self, node: Node) -> None:
        super()._create_clients(node)
        self._follow_path = ActionClient(node, FollowPath, GraphNames.FOLLOW_PATH_ACTION,
                                         callback_group=ReentrantCallbackGroup())

    def _clients(self) -> list[Any]:
        return super()._clients() + [self._follow_path]

    def functions(self) -> dict[str, Callable[..., Any]]:
        """The names generated code sees."""
        return {'get_obj_names': self.get_obj_names, 'get_obj_pos': self.get_obj_pos, 'draw': self.draw,
                'erase': self.erase, 'say': self.say}

    def draw(self, pts: Any) -> None:
        """Draw the line through `pts` (rows of [x, y] in metres) with the marker; repeat the first row to close."""
        self._stroke(pts, FollowPath.Goal.TOOL_MARKER, 'draw')

    def erase(self, pts: Any) -> None:
        """Wipe along the line through `pts` (rows of [x, y] in metres) with the eraser."""
        self._stroke(pts, FollowPath.Goal.TOOL_ERASER, 'erase')

    def _stroke(self, pts: Any, tool: int, verb: str) -> None:
        points = stroke_points(pts, verb)
        goal = FollowPath.Goal(tool=tool, strokes=[Stroke(points=[Point(x=float(x), y=float(y), z=0.0)
                                                                 for x, y in points])])
        result = self._run_goal(self._follow_path, goal, 'the path-following controller',
                                f'the path-following controller refused to {verb}')
        if self.stop_requested.is_set() or result.error_code == FollowPath.Result.CANCELLED:
            raise StoppedError(f'stopped while {"drawing" if verb == "draw" else "erasing"}')
        if result.error_code != FollowPath.Result.NONE:
            raise RobotApiError(f'could not {verb}: {result.error_msg}')


__all__ = ['MAX_STROKE_POINTS', 'RosWhiteboardApi', 'stroke_points']
