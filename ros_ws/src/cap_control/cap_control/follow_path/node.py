"""follow_path: the FollowPath action (draw, erase, or move over the work surface) over the arm's
FollowJointTrajectory action.

The work is cap_control.follow_path.executor's (planned by cap_control.follow_path.plan): this node binds its ports
to ROS (the arm's trajectory action, the tool's spring in /joint_states) and serves the action with it: feedback with
the stage, the stroke, the points passed and the progress; a cancel of the goal or a message on the stop topic halts
the arm where it is (the goal ends CANCELLED, aborted for a stop). A path off the surface or out of reach is refused
before anything moves, with the fraction of it the arm could follow. Parameters are declared from PathConfig
(nested: surface.x_min, ...) and PathTimeouts, whose fields hold every default.
"""
from __future__ import annotations

import numpy as np
from cap_ros_common.actions import RESULT_TIMEOUT_S
from cap_ros_common.parameters import declare_config
from cap_ros_common.time import to_seconds
from cap_whiteboard import tool as tools
from rclpy.action import ActionServer

from cap_control import ros_conversions as conv
from cap_control.follow_path.executor import PathExecutor, PathProgress, PathRequest, PathTimeouts, ToolSpring
from cap_control.follow_path.plan import TOOL_ERASER, TOOL_MARKER, TOOL_NONE, PathConfig
from cap_control.skill_node import ArmNode, ArmPort, spin_node
from cap_interfaces.action import FollowPath
from cap_interfaces.msg import GraphNames

TOOLS_BY_CODE = {FollowPath.Goal.TOOL_NONE: TOOL_NONE, FollowPath.Goal.TOOL_MARKER: TOOL_MARKER,
                 FollowPath.Goal.TOOL_ERASER: TOOL_ERASER}


class _SpringPort(ToolSpring):
    def __init__(self, node: 'FollowPathNode'):
        self._node = node

    def compression(self, tool: str) -> float | None:
        msg = self._node.joint_state()
        position = None if msg is None else conv.joint_positions(msg, (tools.tool_joint(tool),))
        return None if position is None else float(-position[0])

    def state_time(self) -> float | None:
        msg = self._node.joint_state()
        return None if msg is None else to_seconds(msg.header.stamp)


class FollowPathNode(ArmNode):
    goal_description = 'path'

    def __init__(self, **kwargs) -> None:
        super().__init__('follow_path', **kwargs)
        self.config = declare_config(self, PathConfig, skip=('joint_limits',))
        self.config.validate()
        self.timeouts = declare_config(self, PathTimeouts)
        self.set_timeouts(self.timeouts.server_timeout, self.timeouts.service_timeout)
        self.paths = PathExecutor(ArmPort(self), _SpringPort(self), self.config, self.timeouts,
                                 stop_source=GraphNames.STOP_TOPIC, log=self._log)
        self._server = ActionServer(self, FollowPath, GraphNames.FOLLOW_PATH_ACTION, self._execute,
                                    goal_callback=self._on_goal, cancel_callback=self._on_cancel,
                                    result_timeout=RESULT_TIMEOUT_S, callback_group=self.callbacks)
        self.get_logger().info(f'path following ready; surface {self.config.surface.describe()}')

    def destroy_node(self) -> None:
        self._server.destroy()
        super().destroy_node()

    def _execute(self, goal_handle) -> FollowPath.Result:
        goal = goal_handle.request
        result = FollowPath.Result()

        def run(interruption):
            tool = TOOLS_BY_CODE.get(goal.tool)
            strokes = [np.array([[p.x, p.y] for p in stroke.points], dtype=float).reshape(-1, 2)
                       for stroke in goal.strokes]
            outcome = self.paths.run(PathRequest(strokes, tool if tool is not None else f'code {goal.tool}',
                                                     float(goal.speed)),
                                         interruption, lambda progress: self._feedback(goal_handle, progress))
            result.error_code, result.error_msg = int(outcome.code), outcome.message
            result.fraction, result.points_done = float(outcome.fraction), int(outcome.points_done)
            return outcome

        return self.serve(goal_handle, result, run)

    @staticmethod
    def _feedback(goal_handle, progress: PathProgress) -> None:
        goal_handle.publish_feedback(FollowPath.Feedback(
            stage=progress.stage, stroke=int(progress.stroke), points_done=int(progress.points_done),
            points_total=int(progress.points_total), progress=float(progress.progress)))


def main(args=None) -> None:
    spin_node(FollowPathNode, args)


if __name__ == '__main__':
    main()
