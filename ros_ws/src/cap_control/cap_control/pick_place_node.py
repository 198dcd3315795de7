"""pick_place: the PickPlace action over the arm's FollowJointTrajectory and GripperCommand actions.

Object and target positions come from the perception services; the plan (cap_control.pick_place) is made before
anything moves, then its stages run one by one with feedback per stage. A cancel of the PickPlace goal, or a
message on the stop topic, cancels the running arm or gripper goal at once (the arm holds where it is) and ends
the goal with CANCELLED.

A goal the plan refuses (a target off the table's usable area, or on another block: OUTSIDE_WORKSPACE) is aborted
before the arm moves, with error_code and an error_msg that names the target and what is allowed. After the
retreat the node waits for perception to answer from an observation made after it, and a placed object seen off
the table or away from its target fails the goal (OBJECT_DROPPED), so the result agrees with where it really is.

Threading: every callback is in one reentrant group, and main() spins a MultiThreadedExecutor, so the execute
callback may wait on service and action futures that other executor threads complete.
"""
from __future__ import annotations

import threading
import time
from typing import Callable

import numpy as np
import rclpy
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.action import ActionClient, ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Empty

from cap_control import ros_conversions as conv
from cap_control.kinematics import JOINT_NAMES
from cap_control.pick_place import (
    GripperStep, ObjectInfo, Observation, PickPlaceConfig, PickPlaceError, PickPlaceErrorCode, PickPlacePlan,
    Stage, StageName, TrajectoryStep, Workspace, plan_pick_place,
)
from cap_control.trajectory import CartesianLimits, UR5E_LIMITS
from cap_interfaces.action import FollowJointTrajectory, GripperCommand, PickPlace
from cap_interfaces.msg import GraphNames
from cap_interfaces.srv import GetObjectNames, GetObjectState

TRAJECTORY_SUCCESSFUL = FollowJointTrajectory.Result.SUCCESSFUL
TRAJECTORY_PATH_TOLERANCE_VIOLATED = FollowJointTrajectory.Result.PATH_TOLERANCE_VIOLATED
TRAJECTORY_GOAL_TOLERANCE_VIOLATED = FollowJointTrajectory.Result.GOAL_TOLERANCE_VIOLATED
POLL_PERIOD = 0.005  # [s] between looks at a pending future


class _Interrupted(Exception):
    """The goal was cancelled or a stop was requested."""


class _Failed(Exception):
    def __init__(self, code: PickPlaceErrorCode, message: str):
        super().__init__(message)
        self.code = code
        self.message = message


class PickPlaceNode(Node):
    def __init__(self, **kwargs) -> None:
        super().__init__('pick_place', **kwargs)
        p = self._parameter
        workspace = Workspace(
            x_min=p('workspace_x_min', -0.3, 'Workspace (table-top) bounds, world frame [m]; objects and targets '
                    'outside are refused.'),
            x_max=p('workspace_x_max', 0.3, 'See workspace_x_min.'),
            y_min=p('workspace_y_min', -0.8, 'See workspace_x_min.'),
            y_max=p('workspace_y_max', -0.2, 'See workspace_x_min.'),
            table_z=p('table_z', 0.0, 'Height of the table surface [m].'),
            min_tcp_height=p('min_tcp_height', 0.016, 'Lowest tool-centre-point height above the table [m].'))
        scale = p('velocity_scale', 1.0, 'Fraction of the UR5e joint speed (180 deg/s) used, in (0, 1].')
        acceleration_scale = p('acceleration_scale', 1.0, 'Fraction of the joint acceleration (3 rad/s^2) and '
                               'jerk (30 rad/s^3) limits used, in (0, 1].')
        clear_view = p('clear_view', False, 'After placing, move the tool sideways out of the line of sight of '
                       'the camera at camera_position, so camera-based perception sees what was just placed.')
        camera = p('camera_position', [0.0, -0.5, 0.85], 'Where the camera perception watches the table from (world '
                   'frame) [m]; used with clear_view. The default is the simulated top camera.')
        if clear_view and len(camera) != 3:
            raise ValueError(f'camera_position must be x, y, z, not {list(camera)}')
        clear_view_from = tuple(float(v) for v in camera) if clear_view else None
        self.config = PickPlaceConfig(
            workspace=workspace,
            tool_offset=p('tool_offset', 0.15, 'Tool centre point along the flange z axis [m].'),
            travel_height=p('travel_height', 0.25, 'Lowest tool height while carrying or approaching [m].'),
            travel_clearance=p('travel_clearance', 0.05, 'Gap kept under a carried object [m].'),
            gripper_open_width=p('gripper_open_width', 0.085, 'Opening of the open gripper [m].'),
            grip_force=p('grip_force', 20.0, 'Grip force per finger when grasping [N].'),
            require_stalled=p('require_stalled', True, 'A grasp counts only if the fingers stalled on the object.'),
            place_clearance=p('place_clearance', 0.005, 'Release height above the expected contact [m].'),
            finger_thickness=p('finger_thickness', 0.014, 'Thickness of a finger outside its pad [m]; grasp and '
                               'place yaws keep the fingers clear of neighbouring objects.'),
            finger_room=p('finger_room', 0.03, 'Room beside the fingers beyond which every grasp or place yaw '
                          'counts as clear [m].'),
            clear_view_from=clear_view_from,
            clear_view_distance=p('clear_view_distance', 0.20, 'How far sideways the tool moves after placing to '
                                  'clear the camera\'s view (with clear_view) [m].'),
            contact_tolerance=p('contact_tolerance', 0.002, 'Joint tracking error read as contact while placing '
                                '[rad] (sent as the path tolerance of the place descent).'),
            place_tolerance=p('place_tolerance', 0.08, 'Largest xy distance of the placed object from the target '
                              'object [m] before the result reports it dropped.'),
            point_place_tolerance=p('point_place_tolerance', PickPlaceConfig.point_place_tolerance,
                                    'Largest xy distance of an object placed at a point of the table from that '
                                    'point [m] before the result reports a failure.'),
            edge_margin=p('edge_margin', PickPlaceConfig.edge_margin, 'Room kept between a placed object\'s '
                          'footprint and the table\'s edges [m]; a target that leaves less is refused '
                          '(OUTSIDE_WORKSPACE).'),
            joint_limits=UR5E_LIMITS.scaled(scale, acceleration_scale),
            cartesian_limits=CartesianLimits(
                speed=p('cartesian_speed', 0.25, 'Tool speed on straight descents and lifts [m/s].'),
                acceleration=p('cartesian_acceleration', 1.0, 'Tool acceleration on straight lines [m/s^2].')),
            period=p('trajectory_period', 0.02, 'Time between trajectory points sent to the controller [s].'))
        self._service_timeout = p('service_timeout', 5.0, 'Longest wait for a perception answer [s].')
        self._server_timeout = p('server_timeout', 10.0, 'Longest wait for the arm and gripper action servers and '
                                 'the perception services to appear [s].')
        self._motion_timeout_margin = p('motion_timeout_margin', 30.0, 'Wall time allowed beyond a motion\'s '
                                        'planned duration before TIMEOUT [s].')
        self._gripper_timeout = p('gripper_timeout', 15.0, 'Longest wait for a gripper command [s].')
        self._view_timeout = p('view_timeout', 3.0, 'Longest wait after the retreat for perception to answer from an '
                               'observation made after it (with clear_view: after the tool cleared the camera\'s '
                               'view) [s].')

        callbacks = ReentrantCallbackGroup()
        self._joint_lock = threading.Lock()
        self._joint_state: JointState | None = None
        self._stop_requested = threading.Event()
        self._busy = threading.Lock()
        self._active_goal = None  # the arm or gripper goal handle running now (cancelled on interrupt)
        self.create_subscription(JointState, GraphNames.JOINT_STATES_TOPIC, self._on_joint_state, 10,
                                 callback_group=callbacks)
        self.create_subscription(Empty, GraphNames.STOP_TOPIC, self._on_stop, 10, callback_group=callbacks)
        self._create_perception_clients(self)
        self._arm = ActionClient(self, FollowJointTrajectory, GraphNames.SIM_FOLLOW_JOINT_TRAJECTORY_ACTION,
                                 callback_group=callbacks)
        self._gripper = ActionClient(self, GripperCommand, GraphNames.SIM_GRIPPER_ACTION, callback_group=callbacks)
        self._server = ActionServer(self, PickPlace, GraphNames.PICK_PLACE_ACTION, self._execute,
                                    goal_callback=self._on_goal, cancel_callback=lambda _: CancelResponse.ACCEPT,
                                    callback_group=callbacks)
        self.get_logger().info(f'pick-and-place ready; workspace {workspace.describe()}')

    def _create_perception_clients(self, node) -> None:
        group = ReentrantCallbackGroup()
        self._state_client = node.create_client(GetObjectState, GraphNames.PERCEPTION_OBJECT_STATE_SERVICE,
                                                callback_group=group)
        self._names_client = node.create_client(GetObjectNames, GraphNames.PERCEPTION_OBJECT_NAMES_SERVICE,
                                                callback_group=group)

    def bind_perception_clients(self, node) -> None:
        """Move the perception clients onto `node` (call before the first goal).

        The middleware hands each perception answer to every client of that service in the process, and each
        client then wakes its executor. A graph that composes this node with lmp_node binds these clients to a node
        on its events executor, so that the robot API's many perception calls do not wake the multi-threaded
        executor (a whole Python wait set rebuilt each time) through these idle clients.
        """
        old = (self._state_client, self._names_client)
        self._create_perception_clients(node)
        for client in old:
            self.destroy_client(client)

    def _parameter(self, name: str, default, description: str):
        return self.declare_parameter(name, default, ParameterDescriptor(description=description)).value

    def destroy_node(self) -> None:
        self._server.destroy()
        self._arm.destroy()
        self._gripper.destroy()
        super().destroy_node()

    # ------------------------------------------------------------------------------------------- inputs
    def _on_joint_state(self, msg: JointState) -> None:
        with self._joint_lock:
            self._joint_state = msg

    def _on_stop(self, _: Empty) -> None:
        self._stop_requested.set()

    def _on_goal(self, _request) -> GoalResponse:
        if self._busy.locked():
            self.get_logger().warning('refusing a pick-and-place goal: another one is running')
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    # ------------------------------------------------------------------------------------------- waiting
    def _wait(self, future, timeout: float, goal_handle, what: str):
        """The future's result; raises _Interrupted on cancel/stop and _Failed(TIMEOUT) after `timeout` [s]."""
        deadline = time.monotonic() + timeout
        while not future.done():
            if goal_handle.is_cancel_requested or self._stop_requested.is_set():
                raise _Interrupted()
            if time.monotonic() > deadline:
                raise _Failed(PickPlaceErrorCode.TIMEOUT, f'no answer from {what} within {timeout:.0f} s')
            time.sleep(POLL_PERIOD)
        return future.result()

    def _wait_until(self, ready: Callable[[], bool], goal_handle, what: str) -> None:
        deadline = time.monotonic() + self._server_timeout
        while not ready():
            if goal_handle.is_cancel_requested or self._stop_requested.is_set():
                raise _Interrupted()
            if time.monotonic() > deadline:
                raise _Failed(PickPlaceErrorCode.TIMEOUT, f'{what} is not available')
            time.sleep(0.02)

    def _current_joints(self, goal_handle) -> np.ndarray:
        def arm_joints():
            with self._joint_lock:
                msg = self._joint_state
            return None if msg is None else conv.joint_positions(msg, JOINT_NAMES)

        self._wait_until(lambda: arm_joints() is not None, goal_handle, f'{GraphNames.JOINT_STATES_TOPIC} with '
                         'the arm joints')
        return arm_joints()

    def _current_opening(self) -> float | None:
        with self._joint_lock:
            msg = self._joint_state
        return None if msg is None else conv.gripper_opening(msg)

    # ------------------------------------------------------------------------------------------- perception
    def _object_state(self, name: str, goal_handle):
        self._wait_until(self._state_client.service_is_ready, goal_handle,
                         f'the perception service {GraphNames.PERCEPTION_OBJECT_STATE_SERVICE}')
        response = self._wait(self._state_client.call_async(GetObjectState.Request(name=name)),
                              self._service_timeout, goal_handle, 'perception')
        return response

    def _objects_in_view(self, goal_handle, exclude: str) -> list[ObjectInfo] | None:
        """The other objects in view: the carried object passes over them and the fingers keep clear of them.

        Objects perception only remembers (not in view now) are left out: their last known place may be stale.
        None when perception cannot list them.
        """
        if not self._names_client.service_is_ready():
            return None
        names = self._wait(self._names_client.call_async(GetObjectNames.Request(visible_only=True)),
                           self._service_timeout, goal_handle, 'perception').names
        others = []
        for name in names:
            if name == exclude:
                continue
            response = self._object_state(name, goal_handle)
            if response.success and response.state.visible:
                others.append(conv.object_info(response.state))
        return others

    # ------------------------------------------------------------------------------------------- execution
    def _execute(self, goal_handle) -> PickPlace.Result:
        result = PickPlace.Result()
        if not self._busy.acquire(blocking=False):
            goal_handle.abort()
            result.error_code, result.error_msg = PickPlaceErrorCode.UNKNOWN, 'another pick-and-place is running'
            return result
        self._stop_requested.clear()
        request = goal_handle.request
        try:
            plan = self._plan(request, goal_handle)
            self._run(plan, goal_handle)
            final = self._object_state(plan.object.name, goal_handle)
            if final.success:
                result.final_position = final.state.position
            result.error_code = PickPlaceErrorCode.NONE
            result.error_msg = ''
            goal_handle.succeed()
            self.get_logger().info(f'placed the {plan.object.name} on {plan.target_description}')
        except _Interrupted:
            self._cancel_active_goal()
            result.error_code = PickPlaceErrorCode.CANCELLED
            result.error_msg = 'cancelled: the arm stopped where it was'
            if goal_handle.is_cancel_requested:
                goal_handle.canceled()
            else:
                result.error_msg = f'stopped by {GraphNames.STOP_TOPIC}: the arm stopped where it was'
                goal_handle.abort()
        except (_Failed, PickPlaceError) as failure:
            self._cancel_active_goal()
            result.error_code, result.error_msg = int(failure.code), failure.message
            goal_handle.abort()
            self.get_logger().warning(f'pick-and-place failed: {failure.message}')
        finally:
            self._busy.release()
        return result

    def _plan(self, request, goal_handle) -> PickPlacePlan:
        found = self._object_state(request.object_name, goal_handle)
        if not found.success:
            raise _Failed(PickPlaceErrorCode.OBJECT_NOT_FOUND, found.message or
                          f'no object named {request.object_name!r}')
        obj = conv.object_info(found.state)
        if request.target_name:
            target_found = self._object_state(request.target_name, goal_handle)
            if not target_found.success:
                raise _Failed(PickPlaceErrorCode.TARGET_NOT_FOUND, target_found.message or
                              f'no object named {request.target_name!r}')
            target = conv.object_info(target_found.state)
        else:
            target = (request.target_position.x, request.target_position.y)
        others = self._objects_in_view(goal_handle, obj.name)
        obstacle_height = max((other.top for other in others), default=None) if others is not None else None
        return plan_pick_place(obj, target, self._current_joints(goal_handle), self.config, obstacle_height,
                               others or ())

    def _run(self, plan: PickPlacePlan, goal_handle) -> None:
        observation = Observation()
        done = 0.0
        for stage in plan.stages:
            goal_handle.publish_feedback(PickPlace.Feedback(stage=stage.name.value, progress=float(done)))
            for step in stage.steps:
                if isinstance(step, TrajectoryStep):
                    self._move(plan, step, goal_handle)
                else:
                    self._grip(step, goal_handle, observation)
            if stage.name == StageName.RETREAT:
                # The outcome is judged on what perception sees after the retreat, not on what it last saw.
                self._wait_for_fresh_view(plan.object.name, goal_handle)
            self._check(plan, stage, goal_handle, observation)
            done = stage.progress
        goal_handle.publish_feedback(PickPlace.Feedback(stage=plan.stages[-1].name.value, progress=1.0))

    def _move(self, plan: PickPlacePlan, step: TrajectoryStep, goal_handle) -> None:
        trajectory = plan.trajectory_for(step, self._current_joints(goal_handle))
        if len(trajectory) < 2:
            return
        self._wait_until(self._arm.server_is_ready, goal_handle,
                         f'the arm action {GraphNames.SIM_FOLLOW_JOINT_TRAJECTORY_ACTION}')
        handle = self._wait(self._arm.send_goal_async(conv.follow_trajectory_goal(step, trajectory)),
                            self._service_timeout, goal_handle, 'the arm controller')
        if not handle.accepted:
            raise _Failed(PickPlaceErrorCode.UNKNOWN, 'the arm controller refused the trajectory')
        self._active_goal = handle
        response = self._wait(handle.get_result_async(), trajectory.duration + self._motion_timeout_margin,
                              goal_handle, 'the arm controller')
        self._active_goal = None
        code = response.result.error_code
        if code == TRAJECTORY_SUCCESSFUL:
            return
        if step.stop_on_contact and code in (TRAJECTORY_PATH_TOLERANCE_VIOLATED, TRAJECTORY_GOAL_TOLERANCE_VIOLATED):
            # Touched down before the planned height (on the way, or in the last millimetres, where the arm ends
            # a few milliradians short of its goal): placing ends here.
            self.get_logger().debug(f'touched down: {response.result.error_string}')
            return
        raise _Failed(PickPlaceErrorCode.UNKNOWN, f'the arm did not complete its motion: '
                      f'{response.result.error_string or f"error code {code}"}')

    def _wait_for_fresh_view(self, name: str, goal_handle) -> None:
        """Wait until perception answers from an observation made after the retreat (and so after the tool cleared
        the camera's view, with clear_view).

        Otherwise the check below, and the next command, would see the placed object where perception last saw it
        (a camera: before the tool moved out of its view; the simulator's objects: up to a publishing period ago).
        A source without time stamps (stamp 0, e.g. a stub) is not waited for.
        """
        with self._joint_lock:
            msg = self._joint_state
        if msg is None:
            return
        cleared_at = conv.seconds(msg.header.stamp)
        deadline = time.monotonic() + self._view_timeout
        while True:
            response = self._object_state(name, goal_handle)
            if not response.success:
                return  # perception no longer knows it: the check below says so
            if conv.seconds(response.stamp) == 0.0:
                return
            if conv.seconds(response.stamp) >= cleared_at:
                if not response.state.visible:
                    self.get_logger().warning(f'the {name} is out of the camera\'s sight after placing; its '
                                              f'position is the one last seen')
                return
            if time.monotonic() > deadline:
                self.get_logger().warning(f'perception saw nothing newer than the place within '
                                          f'{self._view_timeout:.0f} s; going on with what it has')
                return
            if goal_handle.is_cancel_requested or self._stop_requested.is_set():
                raise _Interrupted()
            time.sleep(0.02)  # a camera frame comes every 0.1 s at most

    def _grip(self, step: GripperStep, goal_handle, observation: Observation) -> None:
        self._wait_until(self._gripper.server_is_ready, goal_handle,
                         f'the gripper action {GraphNames.SIM_GRIPPER_ACTION}')
        handle = self._wait(self._gripper.send_goal_async(conv.gripper_goal(step)), self._service_timeout,
                            goal_handle, 'the gripper')
        if not handle.accepted:
            raise _Failed(PickPlaceErrorCode.UNKNOWN, 'the gripper refused the command')
        self._active_goal = handle
        response = self._wait(handle.get_result_async(), self._gripper_timeout, goal_handle, 'the gripper')
        self._active_goal = None
        observation.gripper_position = response.result.position
        observation.gripper_stalled = response.result.stalled

    def _check(self, plan: PickPlacePlan, stage: Stage, goal_handle, observation: Observation) -> None:
        if not stage.checks:
            return
        if not any(isinstance(step, GripperStep) for step in stage.steps):
            opening = self._current_opening()
            if opening is not None:
                observation.gripper_position = opening
        if any(check.needs_object_position for check in stage.checks):
            seen = self._object_state(plan.object.name, goal_handle)
            observation.object_position = (seen.state.position.x, seen.state.position.y, seen.state.position.z) \
                if seen.success else None
            observation.object_visible = bool(seen.success and seen.state.visible)
        for check in stage.checks:
            failure = check.failure(observation)
            if failure:
                raise _Failed(stage.failure_code, failure)

    def _cancel_active_goal(self) -> None:
        handle, self._active_goal = self._active_goal, None
        if handle is None:
            return
        # The controller holds the arm (or the fingers) where they are; answer only once it has taken the cancel.
        future = handle.cancel_goal_async()
        deadline = time.monotonic() + self._service_timeout
        while not future.done() and time.monotonic() < deadline:
            time.sleep(POLL_PERIOD)


def main(args=None) -> None:
    rclpy.init(args=args)
    node = None
    try:
        node = PickPlaceNode()
        executor = MultiThreadedExecutor(num_threads=4)
        executor.add_node(node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()


if __name__ == '__main__':
    main()
