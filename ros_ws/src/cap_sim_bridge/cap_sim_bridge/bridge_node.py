"""sim_bridge: the MuJoCo world (a registered scene, by default the table top) on ROS 2, standing in for the robot
driver and the cameras.

Publishes /clock (simulated time), /joint_states (the arm, the fingers and the scene's own joints: a cart-pole's, the
whiteboard tool's sprung slides, a mobile base's x, y and yaw), the ground-truth object array, per camera
<CAMERA_NAMESPACE>/<camera>/{color, depth, camera_info} (a camera is rendered only while somebody subscribes
to its colour or depth images, and depth only for a depth subscriber), on /tf_static each camera's optical frame
(REP-103: +z forward, +y down) on the body it is fixed to, and in a scene with a mobile base map -> odom (identity:
the simulator knows where the base is) on /tf_static and odom -> base_link (the base joints' values) on /tf with
every joint state and every frame of a camera the base carries, as a base driver and a localisation would; the
robot's own links are robot_state's (robot_state_node.py). In a scene with a whiteboard it publishes its ink
(SIM_INK_TOPIC when it changes, at most `ink_rate` times a second of simulated time, and a PNG from
SIM_GET_INK_SERVICE); serves the scene reset, a
FollowJointTrajectory action and a GripperCommand action (and in a scene with a mobile base, a FollowJointTrajectory
action over the base's joints, SIM_FOLLOW_BASE_TRAJECTORY_ACTION); for controllers, lockstep stepping of a plant
(ControlStep, lockstep.py; a run's START puts the plant at its defined start first) and pushes on the tool
(PushTool). Like a robot driver it does not listen to /cap/stop: the motion owners (cap_control) cancel their
goals, and a cancelled trajectory leaves the arm holding where it stopped. The physics runs in a thread of its own
(never on an executor thread); the callbacks, which may block while a motion runs, need a MultiThreadedExecutor with
a few threads (main() uses 8). Parameters: SimBridgeConfig (cap_sim_bridge.config).

Idle: once no goal has run and nothing has moved for `idle_after` seconds (rest.py), /clock, /joint_states, the
objects and the cameras drop to their idle rates (the cameras resend the frame rendered when the world came to
rest); a goal or a reset ends the idling at once. As fast as possible, an idle world also slows down to
`idle_speed` times the wall clock: a graph that waits for a program or a model leaves them the CPU.

QoS, chosen on purpose:
- /clock, /joint_states: reliable, keep last 10 (the defaults robot_state_publisher and sim-time users expect;
  a reliable publisher also serves best-effort subscribers);
- images, depth, camera_info: reliable, keep last 1: any subscriber (default or sensor-data QoS) receives them,
  and keep-last 1 hands a slow subscriber the newest frame instead of a backlog;
- ground-truth objects and the whiteboard's ink: reliable, transient local, keep last 1: a node that starts later
  gets the current scene and the ink at once;
- /tf and /tf_static: tf2's (cap_ros_common.qos).
"""
from __future__ import annotations

import dataclasses
import math
import threading
import time
from typing import Any, Callable

import numpy as np
import rclpy
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import CameraInfo, CompressedImage, Image, JointState
from trajectory_msgs.msg import JointTrajectoryPoint

from control_msgs.action import FollowJointTrajectory, GripperCommand
from cap_interfaces.msg import GraphNames, ObjectArray
from cap_interfaces.srv import ControlStep, GetInk, GetTwinReport, PushTool, ResetScene
from cap_ros_common.actions import RESULT_TIMEOUT_S
from cap_ros_common.parameters import declare_config
from cap_ros_common.qos import LATCHED_QOS
from cap_ros_common.tf import TfBroadcaster
from cap_ros_common.transforms import Transform, translation_rotation
from cap_ros_common.time import duration_msg, time_msg
from cap_sim_bridge import ros_conversions as conv
from cap_sim_bridge import trajectory_goal
from cap_sim_bridge.pacing import LoopPacing
from cap_sim_bridge.rest import RestWatch
from cap_sim_bridge.config import SimBridgeConfig, cameras_to_publish, gripper_opening, gripper_position
from cap_sim_bridge.lockstep import Lockstep
from cap_sim_bridge.mobile_base import BASE_JOINT_NAMES
from cap_sim_bridge.standin import LINK_TO_OPTICAL, Perturbation, standin_adjustment
from cap_sim_bridge.urdf import BASE_LINK
from cap_hardware.profile import load_profile
from cap_sim_bridge.twin_watch import TwinWatch
from cap_sim_bridge.world import ARM_JOINT_NAMES, GRIPPER_JOINT_NAMES, World

STATE_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
IMAGE_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE)

GRIPPER_POSITION_TOLERANCE = 0.002  # [m] opening counted as reached
GRIPPER_SETTLE_TIME = 0.1  # [s] of simulated time the fingers must be still before a gripper goal ends
POLL_PERIOD = 0.005  # [s] wall time between checks of a running action
# Faster than real time, rates in simulated time would mean thousands of messages per wall second; these caps
# keep the publishing cost bounded (a skipped /clock or /joint_states message is superseded by the next anyway).
# Every node of the graph but this one runs on /clock, so each /clock message wakes six subscriptions on the
# graph's executors: capped at 500 a wall second they took about 40% of a table-top episode's wall time (22
# episodes: 59.7 s wall at 500/s, 39.9 s at 200/s, 33.9 s at 100/s, 33.5 s at 50/s). The least interval lets
# real time's 100 Hz through despite the loop's jitter (at most 133 messages a wall second).
MIN_WALL_STATE_INTERVAL = 0.0075  # [s] between two /clock (and /joint_states) messages
MAX_WALL_OBJECTS_RATE = 50.0  # [Hz] ground-truth objects
PICTURE_SIZE = (320, 240)  # the twin's picture [pixels]: enough to see what moved, small on /cap/status
REST_SPEED = 0.01  # [m/s or rad/s] the twin's world counts as at rest below this
FEEDBACK_PERIOD = 0.05  # [s] wall time between feedback messages


def camera_topic(camera: str, kind: str) -> str:
    return f'{GraphNames.CAMERA_NAMESPACE}/{camera}/{kind}'


@dataclasses.dataclass(frozen=True)
class _TrajectoryTarget:
    """What a FollowJointTrajectory server drives (the arm, or a mobile base), as the world's calls for it."""

    name: str
    joint_names: tuple[str, ...]
    follow: Callable[..., float]  # (times, positions, velocities) -> end time
    reference: Callable[[], tuple[np.ndarray, np.ndarray]]
    hold: Callable[[], None]
    serial: Callable[[], int]  # counts commands: a change means the goal was replaced
    positions: Callable[[], np.ndarray]
    velocities: Callable[[], np.ndarray]


class SimBridgeNode(Node):
    def __init__(self, **kwargs) -> None:
        super().__init__('sim_bridge', **kwargs)
        config = declare_config(self, SimBridgeConfig)
        self.config = config
        self._real_time_factor = config.real_time_factor if config.real_time else 0.0
        self._state_rate = config.state_rate
        self._objects_rate = config.objects_rate
        self._camera_rate = config.camera_rate
        self._image_width = config.image_width
        self._image_height = config.image_height
        self._publish_depth = config.publish_depth
        self._goal_tolerance = config.goal_tolerance
        self._goal_time_tolerance = config.goal_time_tolerance
        self._gripper_timeout = config.gripper_timeout
        scene_name, seed = config.scene, config.seed

        names = [n for n in (part.strip() for part in config.objects.split(',')) if n]
        # A hardware stand-in plays the profile's robot (cap_sim_bridge.standin): its names, units and camera.
        self.profile = load_profile(config.profile) if config.profile else None
        self._perturbation = Perturbation(seed=config.perturbation_seed)
        adjust = standin_adjustment(self._perturbation, config.standin_camera,
                                    self.profile.calibration.camera_mount) if self.profile else None
        # Names, not specs: the world reads them once its scene (and the object kinds the scene brings) is loaded.
        self.world = World(scene_name, seed, names or None, adjust_model=adjust)
        if self.profile is None:
            self._cameras = cameras_to_publish(config.cameras, self.world.scene.camera_names, self.world.camera_names)
            topics = {camera: {kind: camera_topic(camera, kind) for kind in ('color', 'depth', 'camera_info')}
                      for camera in self._cameras}
        else:
            self._cameras = [config.standin_camera]
            camera = self.profile.camera
            topics = {config.standin_camera: {'color': camera.color, 'depth': camera.depth,
                                              'camera_info': camera.camera_info}}
        # Stamps: simulated time, or for a stand-in the wall clock (a real robot's drivers stamp with theirs).
        self._stamp_offset = time.time() - self.world.time if self.profile else 0.0
        self._frames_sent = 0

        self._clock_pub = self.create_publisher(Clock, GraphNames.CLOCK_TOPIC, STATE_QOS) if not self.profile \
            else None
        self._joint_pub = self.create_publisher(JointState, config.joint_states_topic, STATE_QOS)
        self._objects_pub = self.create_publisher(ObjectArray, GraphNames.SIM_OBJECTS_TOPIC, LATCHED_QOS) \
            if not self.profile else None
        self._camera_pubs = {camera: {kind: self.create_publisher(CameraInfo if kind == 'camera_info' else Image,
                                                                  topic, IMAGE_QOS)
                                      for kind, topic in kinds.items()}
                             for camera, kinds in topics.items()}
        self._tf = TfBroadcaster(self)
        self._tf.send_static(self._static_transforms())
        # A camera the base carries: each of its frames is sent with odom -> base_link at the frame's stamp.
        self._moving_cameras = {camera for camera in self._cameras if self.world.camera_moves(camera)}

        callbacks = ReentrantCallbackGroup()
        if not self.profile:  # a real robot has no reset of its world
            self.create_service(ResetScene, GraphNames.SIM_RESET_SERVICE, self._on_reset, callback_group=callbacks)
        # A twin watches each rehearsal for harm (twin_watch.py) and reports it.
        self.twin_watch = TwinWatch(self.world) if config.twin and not self.profile else None
        if self.twin_watch is not None:
            self.twin_watch.start()
            self.create_service(GetTwinReport, GraphNames.SIM_TWIN_REPORT_SERVICE, self._on_twin_report,
                                callback_group=callbacks)
        self._ink_pub = None
        if self.world.ink_canvas is not None and not self.profile:
            self._ink_pub = self.create_publisher(Image, GraphNames.SIM_INK_TOPIC, LATCHED_QOS)
            self.create_service(GetInk, GraphNames.SIM_GET_INK_SERVICE, self._on_get_ink, callback_group=callbacks)
        self._ink_rate = config.ink_rate
        self._trajectory_server = ActionServer(
            self, FollowJointTrajectory, config.arm_controller_action,
            lambda handle: self._while_running(self._execute_trajectory, handle, self._arm_target()),
            goal_callback=lambda _: GoalResponse.ACCEPT, cancel_callback=lambda _: CancelResponse.ACCEPT,
            result_timeout=RESULT_TIMEOUT_S, callback_group=callbacks)
        # A mobile base is driven by timed trajectories of its joints too (scenes that have one; the server is made
        # at start: a reset keeps the scene).
        self._base_server = None
        if self.world.base is not None:
            self._base_server = ActionServer(
                self, FollowJointTrajectory, config.base_controller_action,
                lambda handle: self._while_running(self._execute_trajectory, handle, self._base_target()),
                goal_callback=lambda _: GoalResponse.ACCEPT, cancel_callback=lambda _: CancelResponse.ACCEPT,
                result_timeout=RESULT_TIMEOUT_S, callback_group=callbacks)
        self._gripper_server = None
        if config.serve_gripper or not self.profile:
            self._gripper_server = ActionServer(
                self, GripperCommand, config.gripper_action,
                lambda handle: self._while_running(self._execute_gripper, handle),
                goal_callback=lambda _: GoalResponse.ACCEPT, cancel_callback=lambda _: CancelResponse.ACCEPT,
                result_timeout=RESULT_TIMEOUT_S, callback_group=callbacks)

        # Controllers: lockstep stepping of a plant, pushes on the tool.
        self._scene_joints = self.world.scene_joint_names()
        self.lockstep = Lockstep(self.world, self._real_time_factor, config.lockstep_timeout)
        self._step_node: Node = self
        self._step_service = None
        if not self.profile:
            self._step_service = self.create_service(ControlStep, GraphNames.SIM_CONTROL_STEP_SERVICE,
                                                     self._on_control_step, callback_group=callbacks)
            self.create_service(PushTool, GraphNames.SIM_PUSH_TOOL_SERVICE, self._on_push_tool,
                                callback_group=callbacks)
        self._last_lockstep_state_wall = -math.inf

        self._publish_scene()
        self._stop = threading.Event()
        self._scene_reset = threading.Event()
        self._woken = threading.Event()  # a goal or a reset: the physics loop stops waiting and stops idling
        self._goals_running = 0  # trajectory and gripper goals being executed (the world is not idle meanwhile)
        self._goals_lock = threading.Lock()
        self._physics = threading.Thread(target=self._run_physics, name='sim_physics', daemon=True)
        self._physics.start()
        mode = f'{self._real_time_factor:g}x real time' if self._real_time_factor > 0 else 'as fast as possible'
        self.get_logger().info(f'simulating scene "{scene_name}" seed {seed} {mode}; cameras {self._cameras}')


    def destroy_node(self) -> None:
        self._stop.set()
        self._woken.set()
        self._physics.join(timeout=10.0)
        self._trajectory_server.destroy()
        if self._gripper_server is not None:
            self._gripper_server.destroy()
        if self._base_server is not None:
            self._base_server.destroy()
        super().destroy_node()

    # ------------------------------------------------------------------------------------------- physics
    def _run_physics(self) -> None:
        world = self.world
        config = self.config
        pacer = LoopPacing(self._real_time_factor, config.idle_speed)
        rest = RestWatch(config.idle_after if self._real_time_factor > 0 or pacer.slows_when_idle else 0.0)
        next_objects = next_camera = next_ink = world.time
        ink_version = -1  # the ink version last published
        last_state_wall = last_objects_wall = -math.inf
        # The cameras watched and their messages rendered when idling began (or when the watched ones changed).
        idle_frames: tuple[tuple[tuple[str, bool], ...], list[tuple[Any, ...]]] | None = None
        try:
            while not self._stop.is_set():
                if self.lockstep.active:  # a controller steps the world; a silent one loses it, made safe
                    if self.lockstep.expired() and self.lockstep.release(silent=True):
                        self.get_logger().warning('a controller stopped stepping the world: its plant was made safe')
                    # Not on _woken: a push sets it while the controller steps, and it stays set until the loop
                    # runs freely again (waiting on it would spin for the rest of the run, slowing the steps).
                    self._stop.wait(0.01)
                    pacer.restart()
                    continue
                if self._woken.is_set():
                    self._woken.clear()
                    rest.wake()
                idle = rest.update(world.time, self._goals_running > 0, world.max_speed())
                state_rate = config.idle_state_rate if idle else self._state_rate
                steps = max(1, int(round(1.0 / (state_rate * world.timestep))))
                wall = time.monotonic()
                publish_state = wall - last_state_wall >= MIN_WALL_STATE_INTERVAL
                objects_rate = config.idle_objects_rate if idle else self._objects_rate
                with world.lock:
                    world.step(steps)
                    if self.twin_watch is not None:
                        self.twin_watch.update()
                    now = world.time
                    joints = self._joint_states(now) if publish_state else None
                    base = self._base_transform(now) if world.base is not None else None
                    objects = world.object_states() if now >= next_objects and objects_rate > 0 and \
                        wall - last_objects_wall >= 1.0 / MAX_WALL_OBJECTS_RATE else None
                base_sent = False
                if joints is not None:
                    if self._clock_pub is not None:
                        self._clock_pub.publish(Clock(clock=time_msg(now)))
                    self._joint_pub.publish(joints)
                    if base is not None:
                        self._tf.send([base])
                        base_sent = True
                    last_state_wall = wall
                if objects is not None and self._objects_pub is not None:
                    self._objects_pub.publish(ObjectArray(header=conv.header(now),
                                                          objects=[conv.object_state_msg(s) for s in objects]))
                    next_objects = max(next_objects + 1.0 / objects_rate, now)
                    last_objects_wall = wall
                if self._ink_pub is not None and world.ink_canvas.version != ink_version and now >= next_ink:
                    image, ink_version = world.ink_canvas.snapshot()
                    self._ink_pub.publish(conv.ink_image_msg(now, image))
                    next_ink = now + 1.0 / self._ink_rate
                camera_rate = config.idle_camera_rate if idle else self._camera_rate
                if not idle:
                    idle_frames = None
                if camera_rate > 0 and self._camera_rate > 0 and self._cameras and now >= next_camera:
                    watched = self._watched_cameras()
                    if base is not None and not base_sent and any(c in self._moving_cameras for c, _ in watched):
                        self._tf.send([base])  # the frames' stamp: a moving camera's pose at it is known exactly
                    if idle:  # nothing in view moves: render once, then send that frame with new stamps
                        if idle_frames is None or idle_frames[0] != watched:
                            idle_frames = (watched, self._render_frames(now, watched))
                        self._send_frames(idle_frames[1], now)
                    elif watched:
                        self._send_frames(self._render_frames(now, watched), now)
                    next_camera = max(next_camera + 1.0 / camera_rate, now)
                if self._scene_reset.is_set():
                    # A reset simulates the settling at once: pace from here rather than wait for the wall clock.
                    self._scene_reset.clear()
                    pacer.restart()
                delay = pacer.delay(now, idle)
                if delay > 0:
                    self._woken.wait(delay)  # a goal that arrives ends the wait (and the idling)
                else:
                    time.sleep(0)  # let callbacks waiting for world.lock in
        except Exception as error:  # noqa: BLE001 - a dead physics thread must say why
            if self.context.ok() and not self._stop.is_set():
                self.get_logger().fatal(f'physics loop stopped: {error!r}')
                raise
            # Otherwise the process is shutting down (e.g. SIGTERM) and publishing failed: nothing to report.
        finally:
            world.close()

    def _static_transforms(self) -> list[Transform]:
        """What /tf_static says for this scene: each published camera's optical frame on its body, and with a mobile
        base map -> odom, both the world (the simulator localises perfectly)."""
        transforms = []
        if self.world.base is not None:
            identity = ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))
            transforms += [Transform(conv.WORLD_FRAME, conv.MAP_FRAME, 0.0, *identity),
                           Transform(conv.MAP_FRAME, conv.ODOM_FRAME, 0.0, *identity)]
        if self.profile is not None:  # a camera driver's part of the chain; the mount is the calibration's
            mount = self.profile.calibration.camera_mount
            return transforms + [Transform(mount.child, self.profile.camera.frame, 0.0,
                                           *translation_rotation(LINK_TO_OPTICAL))]
        for camera in self._cameras:
            mount = self.world.camera_mount(camera)
            if mount is not None:
                transforms.append(Transform(mount[0], conv.optical_frame_id(camera), 0.0,
                                            *translation_rotation(mount[1])))
        return transforms

    def _base_transform(self, now: float) -> Transform:
        """odom -> base_link now: the base joints' x, y and yaw (call with world.lock held)."""
        x, y, yaw = self.world.base_pose()
        return Transform(conv.ODOM_FRAME, BASE_LINK, now + self._stamp_offset, (float(x), float(y), 0.0),
                         (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)))

    def _joint_states(self, now: float) -> JointState:
        """The arm's, the fingers' and the scene's own joints (call with world.lock held)."""
        world, scene = self.world, self._scene_joints
        scene_positions, scene_velocities = world.joint_state(scene)
        names = ARM_JOINT_NAMES + GRIPPER_JOINT_NAMES + tuple(scene)
        positions = np.concatenate([world.joint_positions(), world.finger_positions(), scene_positions])
        velocities = np.concatenate([world.joint_velocities(), world.finger_velocities(), scene_velocities])
        efforts = np.concatenate([world.joint_efforts(), np.zeros(2), world.joint_actuator_forces(scene)])
        if self.profile is not None and self.profile.gripper.joint:  # the gripper's own joint, in its units
            names += (self.profile.gripper.joint,)
            positions = np.append(positions, gripper_position(self.config, float(np.sum(world.finger_positions()))))
            velocities, efforts = np.append(velocities, 0.0), np.append(efforts, 0.0)
        return conv.joint_state_msg(now + self._stamp_offset, names, positions, velocities, efforts)

    # ------------------------------------------------------------------------------------------- controllers
    def bind_quick(self, node: Node) -> None:
        """Serve ControlStep from `node` (before the first controller): a graph that spins a small node on a fast
        executor answers a controller's steps there, not on this node's executor, which action goals keep busy."""
        old_node, old = self._step_node, self._step_service
        self._step_service = node.create_service(ControlStep, GraphNames.SIM_CONTROL_STEP_SERVICE,
                                                 self._on_control_step)
        self._step_node = node
        old_node.destroy_service(old)

    def _on_control_step(self, request: ControlStep.Request, response: ControlStep.Response) -> ControlStep.Response:
        try:
            if request.action == ControlStep.Request.RELEASE:
                released = self.lockstep.release()
                self._woken.set()
                response.success = True
                response.message = 'the plant was made safe' if released else 'no controller was stepping'
                with self.world.lock:
                    response.time = self.world.time
                return response
            if request.action == ControlStep.Request.START:
                now, positions, velocities, applied = self.lockstep.start(request.joint_names,
                                                                          request.actuator_names)
                self._last_lockstep_state_wall = -math.inf  # the plant was put back: shown at once
            elif request.action == ControlStep.Request.STEP:
                now, positions, velocities, applied = self.lockstep.step(
                    request.joint_names, request.actuator_names, request.efforts, request.duration)
            else:
                raise ValueError(f'unknown action {request.action}')
        except ValueError as error:
            response.success = False
            response.message = str(error)
            return response
        response.success = True
        response.time = now
        response.positions, response.velocities, response.applied = \
            positions.tolist(), velocities.tolist(), applied.tolist()
        wall = time.monotonic()
        if wall - self._last_lockstep_state_wall >= MIN_WALL_STATE_INTERVAL:  # the physics loop pauses meanwhile
            self._last_lockstep_state_wall = wall
            with self.world.lock:
                joints = self._joint_states(now)
            self._clock_pub.publish(Clock(clock=time_msg(now)))
            self._joint_pub.publish(joints)
        return response

    def _on_push_tool(self, request: PushTool.Request, response: PushTool.Response) -> PushTool.Response:
        try:
            self.world.push_tool([request.force.x, request.force.y, request.force.z], request.duration)
        except ValueError as error:
            response.success, response.message = False, str(error)
            return response
        self._woken.set()
        response.success = True
        response.message = f'pushing the tool with {request.force.x:g}, {request.force.y:g}, {request.force.z:g} N ' \
                           f'for {request.duration:g} s'
        return response

    def _watched_cameras(self) -> tuple[tuple[str, bool], ...]:
        """(camera, with depth) of every camera somebody subscribes to.

        Rendering costs the physics thread more than the physics (an RGB-D frame is several steps' time): a camera
        nobody watches is not rendered, and depth only for a depth subscriber.
        """
        watched = []
        for camera in self._cameras:
            publishers = self._camera_pubs[camera]
            depth = self._publish_depth and publishers['depth'].get_subscription_count() > 0
            if depth or publishers['color'].get_subscription_count() > 0:
                watched.append((camera, depth))
        return tuple(watched)

    def _render_frames(self, now: float, watched: tuple[tuple[str, bool], ...]) -> list[tuple[Any, ...]]:
        """(publishers, colour, depth or None, camera_info) of the `watched` cameras, rendered now."""
        width, height = self._image_width, self._image_height
        frames = []
        for camera, with_depth in watched:
            publishers = self._camera_pubs[camera]
            rgb, depth = self.world.render(camera, width, height, with_depth=with_depth)
            messages = [conv.color_image_msg(now, camera, rgb), None,
                        conv.camera_info_msg(now, camera, self.world.camera_intrinsics(camera, width, height))]
            if depth is not None and self.profile is None:
                messages[1] = conv.depth_image_msg(now, camera, depth)
            elif depth is not None:  # a stand-in's camera: noisy whole millimetres, in its driver's frame
                self._frames_sent += 1
                messages[1] = conv.depth_mm_image_msg(now, camera, self._perturbation.noisy_depth(
                    depth, self._frames_sent))
            if self.profile is not None:
                for message in messages:
                    if message is not None:
                        message.header.frame_id = self.profile.camera.frame
            frames.append((publishers, *messages))
        return frames

    def _send_frames(self, frames: list[tuple[Any, ...]], now: float) -> None:
        stamp = time_msg(now + self._stamp_offset)
        for publishers, color, depth, info in frames:
            for kind, message in (('color', color), ('depth', depth), ('camera_info', info)):
                if message is not None:
                    message.header.stamp = stamp
                    publishers[kind].publish(message)

    def _publish_scene(self) -> None:
        """Ground truth now (after start and after every reset), and where a reset put the base."""
        with self.world.lock:
            now = self.world.time
            states = self.world.object_states()
            base = self._base_transform(now) if self.world.base is not None else None
        if self._objects_pub is not None:
            self._objects_pub.publish(ObjectArray(header=conv.header(now),
                                                  objects=[conv.object_state_msg(s) for s in states]))
        if base is not None:
            self._tf.send([base])

    # ----------------------------------------------------------------------------------------------- ink
    def _on_get_ink(self, request: GetInk.Request, response: GetInk.Response) -> GetInk.Response:
        canvas = self.world.ink_canvas
        with self.world.lock:
            now = self.world.time
        response.image = CompressedImage(header=conv.header(now), format='png', data=canvas.png())
        response.image.header.frame_id = 'whiteboard'
        response.resolution = canvas.spec.resolution
        response.x_min, response.y_max = canvas.spec.x_range[0], canvas.spec.y_range[1]
        response.success = True
        return response

    # --------------------------------------------------------------------------------------------- reset
    def reset_world(self, seed: int, specs=None, arm_joints=None, base_pose=None, exactly: bool = False,
                    ghost_overlaps: bool = False) -> list:
        """Reset the world (objects: specs, or when there are none the seed's episode, unless `exactly`; the arm at
        `arm_joints` and a mobile base at `base_pose`, else where the scene starts them) and tell the graph; the
        states settled. A stand-in is reset this way by the test that plays the world around the robot (it offers no
        reset service)."""
        self.lockstep.release()  # a reset ends a controller's hold on the world
        with self.world.lock:  # the physics loop's watch sees the new scene only once it watches it
            states = self.world.reset(seed, specs if specs or exactly else None, arm_joints=arm_joints,
                                      base_pose=base_pose, ghost_overlaps=ghost_overlaps)
            if self.twin_watch is not None:
                self.twin_watch.start()
        self._scene_reset.set()
        self._woken.set()
        self._publish_scene()
        return states

    def _on_reset(self, request: ResetScene.Request, response: ResetScene.Response) -> ResetScene.Response:
        try:
            if request.scene and request.scene != self.world.scene_name:
                raise ValueError(f'unknown scene {request.scene!r}; this bridge simulates '
                                 f'"{self.world.scene_name}"')
            states = self.reset_world(request.seed, [conv.object_spec(o) for o in request.objects],
                                      arm_joints=list(request.arm_joint_positions) or None,
                                      base_pose=list(request.base_pose) or None, exactly=request.exactly,
                                      ghost_overlaps=request.ghost_overlaps)
        except ValueError as error:
            response.success = False
            response.message = str(error)
            return response
        response.success = True
        ghosts = [spec.name for spec in self.world.objects if not spec.solid]
        response.message = f'scene "{self.world.scene_name}" seed {request.seed}: ' + \
            ', '.join(s.name for s in states) + (f'; ghosts (placed into another): {", ".join(ghosts)}' if ghosts
                                                 else '')
        response.objects = [conv.object_state_msg(s) for s in states]
        return response

    def _on_twin_report(self, request: GetTwinReport.Request,
                        response: GetTwinReport.Response) -> GetTwinReport.Response:
        """What the twin saw since its reset; with settle_s, once the objects came to rest (or that much simulated
        time passed)."""
        world, watch = self.world, self.twin_watch
        settle_s = min(max(float(request.settle_s), 0.0), 10.0) if math.isfinite(request.settle_s) else 0.0
        with world.lock:
            until = world.time + settle_s
        self._woken.set()  # no idling while it settles
        wall_deadline = time.monotonic() + 10.0
        while settle_s > 0 and time.monotonic() < wall_deadline:
            with world.lock:
                if world.time >= until or (world.max_speed() < REST_SPEED and world.trajectory_end_time is None):
                    break
            time.sleep(POLL_PERIOD)
        watch.finish()
        with world.lock:
            response.findings = watch.findings()
            response.objects = [conv.object_state_msg(s) for s in world.object_states()]
            response.simulated_s = world.time - watch.started_at
            now = world.time
        if request.picture:
            cameras = self.world.scene.camera_names or self.world.camera_names
            rgb, _ = world.render(cameras[0], PICTURE_SIZE[0], PICTURE_SIZE[1], with_depth=False)
            response.image = conv.png_image_msg(now, cameras[0], rgb)
        response.success = True
        response.message = (f'{len(response.findings)} finding(s) in {response.simulated_s:.1f} s of simulated time; '
                            f'the gripper pressed on the fixed scene with at most {watch.max_gripper_force:.1f} N')
        return response

    # ------------------------------------------------------------------------------------------- goals
    def _while_running(self, execute, goal_handle, *args):
        """Run a goal's execute callback; the world is not idle meanwhile (nor for idle_after afterwards)."""
        with self._goals_lock:
            self._goals_running += 1
        self._woken.set()
        try:
            return execute(goal_handle, *args)
        finally:
            with self._goals_lock:
                self._goals_running -= 1
            self._woken.set()

    # ---------------------------------------------------------------------------------------- trajectory
    def _arm_target(self) -> '_TrajectoryTarget':
        world = self.world
        return _TrajectoryTarget('arm', ARM_JOINT_NAMES, world.follow_trajectory, world.reference, world.hold,
                                 lambda: world.arm_command_serial, world.joint_positions, world.joint_velocities)

    def _base_target(self) -> '_TrajectoryTarget':
        world = self.world
        return _TrajectoryTarget('base', BASE_JOINT_NAMES, world.follow_base_trajectory, world.base_reference,
                                 world.hold_base, lambda: world.base.command_serial, world.base_pose,
                                 world.base_velocity)

    def _execute_trajectory(self, goal_handle, target: '_TrajectoryTarget') -> FollowJointTrajectory.Result:
        world = self.world
        result = FollowJointTrajectory.Result()
        with world.lock:
            try:
                plan = trajectory_goal.plan_from_goal(goal_handle.request, target.joint_names, target.reference()[0],
                                                      self._goal_tolerance, self._goal_time_tolerance)
                end_time = target.follow(plan.times, plan.positions, plan.velocities)
            except trajectory_goal.GoalError as error:
                return self._abort(goal_handle, result, error.code, str(error))
            except ValueError as error:
                return self._abort(goal_handle, result, trajectory_goal.INVALID_GOAL, str(error))
            serial = target.serial()
            start_time = world.time
        last_feedback = 0.0
        while True:
            if goal_handle.is_cancel_requested:
                with world.lock:
                    if target.serial() == serial:
                        target.hold()
                goal_handle.canceled()
                result.error_string = f'cancelled: the {target.name} holds where it stopped'
                return result
            with world.lock:
                replaced = target.serial() != serial
                now = world.time
                positions, velocities = target.positions(), target.velocities()
                desired, desired_velocities = target.reference()
            if replaced:
                return self._abort(goal_handle, result, trajectory_goal.INVALID_GOAL,
                                   'replaced by a newer trajectory, a hold or a scene reset')
            if self._stop.is_set():
                return self._abort(goal_handle, result, trajectory_goal.INVALID_GOAL, 'the simulation stopped')
            if time.monotonic() - last_feedback >= FEEDBACK_PERIOD:
                last_feedback = time.monotonic()
                goal_handle.publish_feedback(self._trajectory_feedback(
                    target.joint_names, now, now - start_time, desired, desired_velocities, positions, velocities))
            violation = plan.path_violation(positions, desired, target.joint_names) if now < end_time else None
            if violation:
                with world.lock:
                    if target.serial() == serial:
                        target.hold()
                return self._abort(goal_handle, result, trajectory_goal.PATH_TOLERANCE_VIOLATED, violation)
            if now >= end_time:
                if plan.goal_reached(positions, velocities):
                    goal_handle.succeed()
                    result.error_code = trajectory_goal.SUCCESSFUL
                    return result
                if now > end_time + plan.goal_time_tolerance:
                    return self._abort(goal_handle, result, trajectory_goal.GOAL_TOLERANCE_VIOLATED,
                                       'goal not reached in time: ' + plan.goal_errors(positions, target.joint_names))
            time.sleep(POLL_PERIOD)

    @staticmethod
    def _abort(goal_handle, result, code: int, message: str):
        goal_handle.abort()
        result.error_code = code
        result.error_string = message
        return result

    def _trajectory_feedback(self, joint_names, now, elapsed, desired, desired_velocities, positions, velocities):
        duration = duration_msg(elapsed)
        feedback = FollowJointTrajectory.Feedback(header=conv.header(now + self._stamp_offset),
                                                  joint_names=list(joint_names))
        feedback.desired = JointTrajectoryPoint(positions=desired.tolist(), velocities=desired_velocities.tolist(),
                                                time_from_start=duration)
        feedback.actual = JointTrajectoryPoint(positions=positions.tolist(), velocities=velocities.tolist(),
                                               time_from_start=duration)
        feedback.error = JointTrajectoryPoint(positions=(desired - positions).tolist(),
                                              velocities=(desired_velocities - velocities).tolist(),
                                              time_from_start=duration)
        return feedback

    # ------------------------------------------------------------------------------------------- gripper
    def _execute_gripper(self, goal_handle) -> GripperCommand.Result:
        world, config = self.world, self.config
        command = goal_handle.request.command
        with world.lock:
            world.command_gripper(gripper_opening(config, command.position), command.max_effort)
            target = world.gripper_state().target_opening
            deadline = world.time + self._gripper_timeout
        still_since = None
        last_feedback = 0.0
        while True:
            with world.lock:
                state = world.gripper_state()
                now = world.time
            reached = abs(state.opening - state.target_opening) <= GRIPPER_POSITION_TOLERANCE
            position = gripper_position(config, state.opening)
            outcome = GripperCommand.Result(position=position, effort=state.force, stalled=False,
                                            reached_goal=reached)
            if goal_handle.is_cancel_requested:
                # The fingers stay where they are, keeping whatever grip they have.
                world.command_gripper(state.opening, state.max_force)
                goal_handle.canceled()
                return outcome
            if state.target_opening != target or self._stop.is_set():
                goal_handle.abort()
                return outcome
            if time.monotonic() - last_feedback >= FEEDBACK_PERIOD:
                last_feedback = time.monotonic()
                goal_handle.publish_feedback(GripperCommand.Feedback(position=position, effort=state.force,
                                                                     stalled=False, reached_goal=reached))
            still = not state.reference_moving and state.speed < 2e-3
            still_since = (still_since if still_since is not None else now) if still else None
            if still_since is not None and now - still_since >= GRIPPER_SETTLE_TIME:
                # Stopped short of the commanded opening: the fingers hold an object (a grasp, not a failure).
                outcome.stalled = not reached
                goal_handle.succeed()
                return outcome
            if now > deadline:
                goal_handle.abort()
                return outcome
            time.sleep(POLL_PERIOD)

def main(args=None) -> None:
    rclpy.init(args=args)
    # Action goals block their thread while the motion runs: keep threads free for services and cancels.
    executor = MultiThreadedExecutor(num_threads=8)
    node = None
    try:
        node = SimBridgeNode()
        executor.add_node(node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:
        # A SIGTERM or SIGINT while starting up shuts the context down under our feet: that is a normal exit.
        if rclpy.ok():
            raise
    finally:
        if node is not None:
            node.destroy_node()
        executor.shutdown()
        rclpy.try_shutdown()


if __name__ == '__main__':
    main()
