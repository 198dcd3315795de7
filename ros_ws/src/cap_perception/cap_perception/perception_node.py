"""perception_node: the object services of the graph over one interchangeable source.

Parameters choose the source: `ground_truth` (the simulator's object array), `stub` (a YAML file) or `rgbd`
(the colour detector on the bridge's camera images, when available).
"""
from __future__ import annotations

import rclpy
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy, HistoryPolicy

from cap_interfaces.msg import GraphNames, ObjectArray
from cap_interfaces.srv import GetObjectNames, GetObjectState
from cap_perception.ros_conversions import from_msg, to_msg
from cap_perception.sources import NoObservationError, SnapshotSource, UnknownObjectError, load_stub_objects

SOURCES = ('ground_truth', 'stub')

# Only the latest object array matters: keep one, reliably delivered.
OBJECTS_QOS = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE)


class PerceptionNode(Node):
    def __init__(self, **kwargs) -> None:
        super().__init__('perception_node', **kwargs)
        source = self.declare_parameter('source', 'ground_truth', ParameterDescriptor(
            description='Where objects come from: ground_truth (simulator object array) or stub (YAML file).')).value
        stub_file = self.declare_parameter('stub_file', '', ParameterDescriptor(
            description='YAML file of objects for source=stub.')).value
        if source not in SOURCES:
            raise ValueError(f'parameter source={source!r} is not one of {", ".join(SOURCES)}')
        self.source = SnapshotSource(
            'the simulator ground truth' if source == 'ground_truth' else f'the stub file {stub_file!r}')
        if source == 'stub':
            if not stub_file:
                raise ValueError('parameter stub_file is required when source=stub')
            self.source.update(load_stub_objects(stub_file), stamp=0.0)
        else:
            self.create_subscription(ObjectArray, GraphNames.SIM_OBJECTS_TOPIC, self._on_objects, OBJECTS_QOS)
        self.create_service(GetObjectNames, GraphNames.PERCEPTION_OBJECT_NAMES_SERVICE, self._on_names)
        self.create_service(GetObjectState, GraphNames.PERCEPTION_OBJECT_STATE_SERVICE, self._on_state)
        self.get_logger().info(f'serving objects from {self.source.description}')

    def _on_objects(self, msg: ObjectArray) -> None:
        stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        self.source.update((from_msg(obj) for obj in msg.objects), stamp)

    def _on_names(self, request: GetObjectNames.Request, response: GetObjectNames.Response):
        try:
            response.names = self.source.names(visible_only=request.visible_only)
        except NoObservationError as error:
            self.get_logger().warning(str(error))
            response.names = []
        return response

    def _on_state(self, request: GetObjectState.Request, response: GetObjectState.Response):
        try:
            response.state = to_msg(self.source.state(request.name))
            response.success = True
        except (UnknownObjectError, NoObservationError) as error:
            response.success = False
            response.message = str(error)
        return response


def main(args=None) -> None:
    rclpy.init(args=args)
    node = PerceptionNode()
    try:
        rclpy.spin(node)
    except KeyboardInterrupt:
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
