"""perception_node: the object services of the graph over one interchangeable source.

The `source` parameter chooses where objects come from: `ground_truth` (the simulator's object array), `rgbd` (a
colour detector on one camera's colour and depth images, run on the newest frame when a service is asked: the
domain's, the `detector` parameter: cap_perception.detectors) or `stub` (a YAML file). With `rgbd`, the camera's pose
comes from tf: the pose of the images' frame (their header's frame_id) in `world_frame` at the images' stamp, so a
camera on a calibrated mount (a static transform) and one that moves with the robot work the same way.
"""
from __future__ import annotations

import threading

import numpy as np
import rclpy
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import CameraInfo, Image
from std_srvs.srv import Trigger

from cap_interfaces.msg import GraphNames, ObjectArray
from cap_interfaces.srv import GetObjectNames, GetObjectState
from cap_ros_common.parameters import declare_config
from cap_ros_common.tf import TfListener
from cap_ros_common.transforms import TransformError
from cap_ros_common.time import time_msg, to_seconds
from cap_perception.config import PerceptionConfig
from cap_perception.detectors import get_detector
from cap_perception.rgbd import CameraView, same_view
from cap_perception.ros_conversions import from_msg, image_to_array, to_msg
from cap_perception.sources import (CameraMemory, NoObservationError, SnapshotSource, UnknownObjectError,
                                    load_stub_objects)

# Only the latest object array matters: keep one, reliably delivered.
OBJECTS_QOS = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE)
class PerceptionNode(Node):
    def __init__(self, **kwargs) -> None:
        super().__init__('perception_node', **kwargs)
        self._memory: CameraMemory | None = None  # the RGB-D source's frame bookkeeping
        self.config = config = declare_config(self, PerceptionConfig)
        config.validate()
        source, stub_file = config.source, config.stub_file
        self.source = SnapshotSource({'ground_truth': 'the simulator ground truth',
                                      'rgbd': 'the RGB-D detector', 'stub': f'the stub file {stub_file!r}'}[source])
        if source == 'stub':
            self.source.update(load_stub_objects(stub_file), stamp=0.0)
        elif source == 'ground_truth':
            self.create_subscription(ObjectArray, GraphNames.SIM_OBJECTS_TOPIC, self._on_objects, OBJECTS_QOS)
        else:
            self._start_detector()
        # Services answer from the latest snapshot (with the RGB-D source, the newest frame is analysed first); their
        # own group keeps them apart from the image callbacks, which only keep the newest frame.
        services = MutuallyExclusiveCallbackGroup()
        self.create_service(GetObjectNames, GraphNames.PERCEPTION_OBJECT_NAMES_SERVICE, self._on_names,
                            callback_group=services)
        self.create_service(GetObjectState, GraphNames.PERCEPTION_OBJECT_STATE_SERVICE, self._on_state,
                            callback_group=services)
        self.create_service(Trigger, GraphNames.PERCEPTION_FORGET_SERVICE, self._on_forget, callback_group=services)
        self._stub_objects = self.source.objects() if source == 'stub' else None
        self.get_logger().info(f'serving objects from {self.source.description}')

    # ------------------------------------------------------------------------------------------ ground truth
    def _on_objects(self, msg: ObjectArray) -> None:
        self.source.update((from_msg(obj) for obj in msg.objects), to_seconds(msg.header.stamp))

    # ------------------------------------------------------------------------------------------ RGB-D detector
    def _start_detector(self) -> None:
        config = self.config
        self._detect = get_detector(config.detector)
        self._memory = CameraMemory(self.source, analyse=self._analyse)
        self._last_analysis: tuple[CameraView, list] | None = None  # only touched inside CameraMemory.refresh
        self._frames_lock = threading.Lock()
        self._color: Image | None = None
        self._depth: Image | None = None
        self._waiting_for_pose = False  # the newest frame's pose has not come on tf yet
        # When each image reached this process (local wall clock, ns): not the sender's clock, which may differ.
        self._color_received_ns = self._depth_received_ns = 0
        self._camera_matrix: np.ndarray | None = None
        # Images are sensor data: the latest frame matters, a lost one is replaced by the next.
        images = MutuallyExclusiveCallbackGroup()
        self._tf = TfListener(self, callback_group=images, on_update=self._on_transforms)
        # With the message info: a frame received before a forget shows the old scene (see CameraMemory).
        self.create_subscription(Image, config.topic('color'), lambda m, info: self._on_image('color', m, info),
                                 qos_profile_sensor_data, callback_group=images)
        self.create_subscription(Image, config.topic('depth'), lambda m, info: self._on_image('depth', m, info),
                                 qos_profile_sensor_data, callback_group=images)
        self.create_subscription(CameraInfo, config.topic('camera_info'), self._on_camera_info,
                                 qos_profile_sensor_data, callback_group=images)

    def _on_transforms(self) -> None:
        if self._waiting_for_pose:  # a frame may have come before the transform of its stamp
            self._offer_frame()

    def _on_camera_info(self, msg: CameraInfo) -> None:
        self._camera_matrix = np.array(msg.k, dtype=float).reshape(3, 3)

    def _on_image(self, kind: str, msg: Image, info: dict) -> None:
        with self._frames_lock:
            setattr(self, f'_{kind}', msg)
            setattr(self, f'_{kind}_received_ns', int(info.get('received_timestamp') or 0))
        self._offer_frame()

    def _offer_frame(self) -> None:
        """Offer the newest colour and depth pair with the camera's pose at its stamp, to be analysed when somebody
        asks; a frame whose pose is not known yet waits for it (a moving camera's is exactly the frame's)."""
        with self._frames_lock:
            color, depth = self._color, self._depth
            received_ns = min(self._color_received_ns, self._depth_received_ns)
        # Colour and depth of one frame carry the same stamp.
        if color is None or depth is None or color.header.stamp != depth.header.stamp:
            return
        stamp, frame = to_seconds(color.header.stamp), color.header.frame_id
        try:
            pose = self._tf.buffer.lookup(self.config.world_frame, frame, stamp)
        except TransformError as error:
            self._waiting_for_pose = True
            try:
                later = self._tf.buffer.latest_stamp(self.config.world_frame, frame)
            except TransformError:
                later = None
            if later is not None and later > stamp:  # transforms of later moments came but not this frame's
                self.get_logger().warning(f'no camera pose for the frame at {stamp:.3f} s: {error}',
                                          throttle_duration_sec=10.0)
            return
        self._waiting_for_pose = False
        self._memory.offer((color, depth, pose), stamp, received_ns or None)

    def _analyse(self, frame: tuple[Image, Image, np.ndarray]) -> list | None:
        """The objects in one colour and depth pair seen from `pose` (None when it cannot be analysed yet or at all).

        A frame identical to the last one analysed (the world at rest: the simulator sends the same image with new
        stamps) has the same objects: they are reused rather than detected again.
        """
        if self._camera_matrix is None:
            return None
        color, depth, pose = frame
        try:
            view = CameraView(image_to_array(color), image_to_array(depth), self._camera_matrix, pose)
        except ValueError as error:
            self.get_logger().error(str(error), throttle_duration_sec=5.0)
            return None
        last = self._last_analysis
        if last is not None and same_view(last[0], view):
            return last[1]
        detected = self._detect(view)
        self._last_analysis = (view, detected)
        return detected

    # ------------------------------------------------------------------------------------------ services
    def _on_forget(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        if self._stub_objects is not None:
            response.message = 'the stub source is fixed; nothing to forget'
        else:
            if self._memory is not None:
                self._memory.forget()
            else:
                self.source.clear()
            response.message = f'forgot every object; waiting for the next observation from {self.source.description}'
        response.success = True
        return response

    def _on_names(self, request: GetObjectNames.Request, response: GetObjectNames.Response):
        try:
            response.names = self.source.names(visible_only=request.visible_only)
        except NoObservationError as error:
            self.get_logger().warning(str(error), throttle_duration_sec=5.0)
            response.names = []
        return response

    def _on_state(self, request: GetObjectState.Request, response: GetObjectState.Response):
        try:
            state, stamp = self.source.stamped_state(request.name)
            response.state = to_msg(state)
            response.stamp = time_msg(stamp)
            response.success = True
        except (UnknownObjectError, NoObservationError) as error:
            response.success = False
            response.message = str(error)
        return response


def main(args=None) -> None:
    rclpy.init(args=args)
    node = PerceptionNode()
    executor = MultiThreadedExecutor(num_threads=2)
    executor.add_node(node)
    try:
        executor.spin()
    except KeyboardInterrupt:
        pass
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
