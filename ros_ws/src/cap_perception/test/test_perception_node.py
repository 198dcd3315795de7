"""perception_node over DDS: the services answer from the simulator's object array or from a stub file."""
import pytest
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter

from cap_interfaces.msg import GraphNames, ObjectArray
from cap_interfaces.srv import GetObjectNames, GetObjectState
from cap_perception.objects import PerceivedObject
from cap_perception.perception_node import OBJECTS_QOS, PerceptionNode
from cap_perception.ros_conversions import to_msg


@pytest.fixture
def graph(ros_context):
    nodes = []
    executor = MultiThreadedExecutor(num_threads=4, context=ros_context)

    def add(node):
        nodes.append(node)
        executor.add_node(node)
        return node

    yield add, executor
    executor.shutdown()
    for node in nodes:
        node.destroy_node()


def _call(executor, spin_until, client, request):
    assert spin_until(executor, client.service_is_ready)
    future = client.call_async(request)
    assert spin_until(executor, future.done)
    return future.result()


def test_ground_truth_objects_are_served_by_name(ros_context, graph, spin_until):
    add, executor = graph
    add(PerceptionNode(context=ros_context))
    user = add(Node('perception_user', context=ros_context))
    names = user.create_client(GetObjectNames, GraphNames.PERCEPTION_OBJECT_NAMES_SERVICE)
    state = user.create_client(GetObjectState, GraphNames.PERCEPTION_OBJECT_STATE_SERVICE)

    assert _call(executor, spin_until, names, GetObjectNames.Request()).names == []
    simulator = user.create_publisher(ObjectArray, GraphNames.SIM_OBJECTS_TOPIC, OBJECTS_QOS)
    array = ObjectArray()
    array.header.frame_id = 'world'
    array.header.stamp.sec, array.header.stamp.nanosec = 12, 500_000_000
    array.objects = [to_msg(PerceivedObject.from_fields('red', 'block', (0.1, -0.5, 0.02), (0.04,) * 3)),
                     to_msg(PerceivedObject.from_fields('blue', 'bowl', (-0.1, -0.4, 0.03), (0.14, 0.14, 0.06)))]
    assert spin_until(executor, lambda: simulator.get_subscription_count() == 1)
    simulator.publish(array)
    assert spin_until(executor, lambda: _call(executor, spin_until, names, GetObjectNames.Request()).names
                      == ['blue bowl', 'red block'])

    answer = _call(executor, spin_until, state, GetObjectState.Request(name='the Red_Block'))
    assert answer.success
    assert (answer.state.position.x, answer.state.position.y) == pytest.approx((0.1, -0.5))
    assert answer.state.bbox_max.z == pytest.approx(0.04)
    assert (answer.stamp.sec, answer.stamp.nanosec) == (12, 500_000_000), 'the time of the observation'

    unknown = _call(executor, spin_until, state, GetObjectState.Request(name='green block'))
    assert not unknown.success
    assert "no object called 'green block'" in unknown.message and 'red block' in unknown.message


def test_stub_source_serves_the_file(ros_context, graph, spin_until, tmp_path):
    stub = tmp_path / 'objects.yaml'
    stub.write_text('objects:\n  - {color: green, category: block, position: [0.0, -0.6, 0.02], visible: false}\n')
    add, executor = graph
    add(PerceptionNode(context=ros_context, parameter_overrides=[
        Parameter('source', value='stub'), Parameter('stub_file', value=str(stub))]))
    user = add(Node('perception_user', context=ros_context))
    names = user.create_client(GetObjectNames, GraphNames.PERCEPTION_OBJECT_NAMES_SERVICE)
    assert _call(executor, spin_until, names, GetObjectNames.Request()).names == ['green block']
    assert _call(executor, spin_until, names, GetObjectNames.Request(visible_only=True)).names == []


def test_unknown_source_is_refused_at_start(ros_context):
    with pytest.raises(ValueError, match='not one of'):
        PerceptionNode(context=ros_context, parameter_overrides=[Parameter('source', value='lidar')])


def test_a_moving_cameras_frame_is_analysed_with_the_pose_stamped_as_the_frame(ros_context, graph, spin_until):
    """The head camera moves with the base: a frame waits for the transform of its own stamp (odom -> base_link on
    /tf), which may come after its images, and is never analysed with the latest pose of another moment (here:
    where the base started)."""
    import math

    from cap_mobile import layout, robot
    from cap_ros_common.tf import TfBroadcaster
    from cap_ros_common.transforms import Transform, translation_rotation
    from cap_sim_bridge import ros_conversions as conv
    from cap_sim_bridge.bridge_node import IMAGE_QOS
    from cap_sim_bridge.world import World
    from sensor_msgs.msg import CameraInfo, Image

    world = World('mobile', seed=1)
    parent, mount = world.camera_mount(robot.HEAD_CAMERA)
    start = world.base_pose()
    end = world.follow_base_trajectory([8.0], [list(layout.location('table').approach())])  # a straight drive
    world.run_for(end - world.time + 0.5)
    rgb, depth = world.render(robot.HEAD_CAMERA, 640, 480)
    seen = {s.name: s.position for s in world.object_states() if s.visible}
    assert len(seen) >= 2

    def base(stamp, pose):  # world -> base_link, as map -> odom -> base_link says it in the simulator
        x, y, yaw = pose
        return Transform('world', 'base_link', stamp, (x, y, 0.0), (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)))

    add, executor = graph
    add(PerceptionNode(context=ros_context, parameter_overrides=[
        Parameter('source', value='rgbd'), Parameter('detector', value='mobile'),
        Parameter('camera', value=robot.HEAD_CAMERA)]))
    camera = add(Node('head_camera', context=ros_context))
    tf = TfBroadcaster(camera)
    from cap_sim_bridge.robot_state import RobotState
    from cap_sim_bridge.urdf import robot_urdf
    tf.send_static([*RobotState(robot_urdf(world.model)).fixed_transforms(),
                    Transform(parent, conv.optical_frame_id(robot.HEAD_CAMERA), 0.0, *translation_rotation(mount))])
    prefix = f'{GraphNames.CAMERA_NAMESPACE}/{robot.HEAD_CAMERA}'
    publishers = {kind: camera.create_publisher(kind_type, f'{prefix}/{kind}', qos) for kind, kind_type, qos in (
        ('color', Image, IMAGE_QOS), ('depth', Image, IMAGE_QOS), ('camera_info', CameraInfo, IMAGE_QOS))}
    names = camera.create_client(GetObjectNames, GraphNames.PERCEPTION_OBJECT_NAMES_SERVICE)
    state = camera.create_client(GetObjectState, GraphNames.PERCEPTION_OBJECT_STATE_SERVICE)
    assert spin_until(executor, lambda: all(p.get_subscription_count() == 1 for p in publishers.values()))

    tf.send([base(1.0, start)])  # the latest transform, of an earlier moment
    intrinsics = world.camera_intrinsics(robot.HEAD_CAMERA, 640, 480)
    publishers['camera_info'].publish(conv.camera_info_msg(2.0, robot.HEAD_CAMERA, intrinsics))
    publishers['color'].publish(conv.color_image_msg(2.0, robot.HEAD_CAMERA, rgb))
    publishers['depth'].publish(conv.depth_image_msg(2.0, robot.HEAD_CAMERA, depth))
    executor.spin_once(timeout_sec=0.5)
    assert _call(executor, spin_until, names, GetObjectNames.Request()).names == [], 'analysed without its pose'
    broken = base(2.0, world.base_pose())
    tf.send([Transform(broken.parent, broken.child, 2.0, broken.translation, (0.0, 0.0, 0.0, 0.0))])
    executor.spin_once(timeout_sec=0.5)  # not a rotation: dropped, the node serves on
    assert _call(executor, spin_until, names, GetObjectNames.Request()).names == [], 'analysed with a broken pose'

    tf.send([base(2.0, world.base_pose())])

    def seen_all() -> bool:
        if _call(executor, spin_until, names, GetObjectNames.Request()).names == sorted(seen):
            return True
        # Images are sensor data (best effort): a camera sends the next frame; here it sends that one again, the
        # same moment, in case a loaded machine lost it
        publishers['camera_info'].publish(conv.camera_info_msg(2.0, robot.HEAD_CAMERA, intrinsics))
        publishers['color'].publish(conv.color_image_msg(2.0, robot.HEAD_CAMERA, rgb))
        publishers['depth'].publish(conv.depth_image_msg(2.0, robot.HEAD_CAMERA, depth))
        return False

    assert spin_until(executor, seen_all)
    for name, position in seen.items():
        answer = _call(executor, spin_until, state, GetObjectState.Request(name=name))
        point = answer.state.position
        assert math.dist((point.x, point.y, point.z), position) < 0.015, name
    world.close()
