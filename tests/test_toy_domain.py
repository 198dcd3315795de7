"""A second domain plugs in from a test alone: a toy prompt, a toy robot API and a toy scene, through the whole graph.

Nothing of the project is edited: the scene goes into the simulator's scene registry, the domain into lmp_node's
domain registry, and `GraphOptions(domain=...)` brings up the graph with both (the simulator loads the domain's
scene, lmp_node its prompt and API). The toy API rings a bell (a message on `toy/bell`) and counts the objects
perception sees, so the command "ring the bell once for every object" shows the three parts working as one.
"""
from __future__ import annotations

import time

import pytest
import rclpy
from std_msgs.msg import String

from cap_bringup.graph import Graph, GraphOptions
from cap_interfaces.action import ExecuteCommand
from cap_interfaces.msg import GraphNames
from cap_lmp.cassette import ANY_CONTEXT, Cassette, CassetteEntry
from cap_lmp_ros.domains import registry
from cap_lmp_ros.domains.tabletop.robot_api import RosTabletopApi
from cap_lmp_ros.testing import toy_domain
from cap_perception.sources import NoObservationError
from cap_sim_bridge import scenes
from cap_sim_bridge.scene import ObjectSpec

# A small round table with the robot; three blocks stand on it in the domain's default episode.
TOY_MJCF = """
<mujoco model="bell table">
  <compiler angle="radian" autolimits="true"/>
  <option timestep="0.002" integrator="implicitfast" cone="elliptic"/>
  <include file="ur5e_gripper.xml"/>
  <worldbody>
    <geom name="table" type="cylinder" size="0.25 0.02" pos="0 -0.5 -0.02" contype="1" conaffinity="3"/>
    <camera name="overhead" pos="0 -0.5 1.0"/>
  </worldbody>
</mujoco>
"""
TOY_OBJECTS = [ObjectSpec('red block', 'block', 'red', position=(-0.1, -0.45)),
               ObjectSpec('green block', 'block', 'green', position=(0.0, -0.55)),
               ObjectSpec('blue block', 'block', 'blue', position=(0.1, -0.45))]
COMMAND = 'ring the bell once for every object'


class BellAndEyes(RosTabletopApi):
    """The toy robot API: `ring_bell(times)` over ROS, plus the table top's `get_obj_names` (perception's service)."""

    def __init__(self, node, say_publisher, service_timeout_s: float = 5.0, motion_timeout_s: float = 180.0):
        super().__init__(node, say_publisher, service_timeout_s, motion_timeout_s)
        self._bell = toy_domain.RosToyApi(node, say_publisher, service_timeout_s, motion_timeout_s)

    def functions(self):
        return {'get_obj_names': super().functions()['get_obj_names'], 'ring_bell': self._bell.ring_bell}


@pytest.fixture
def bell_domain(tmp_path):
    cassette = Cassette(tmp_path / 'bell.yaml', [CassetteEntry(
        lmp='toy_ui', query=COMMAND, context=ANY_CONTEXT, completion='ring_bell(len(get_obj_names()))',
        source='written by hand for the toy-domain test')])
    cassette.save()
    scenes.register_scene(scenes.SceneSpec('bell table', build=scenes.mjcf_builder(TOY_MJCF),
                                           default_objects=lambda seed: list(TOY_OBJECTS),
                                           camera_names=('overhead',)))
    registry.register_domain(registry.Domain(
        name='bell', build_engine=toy_domain.build_engine, robot_functions=('get_obj_names', 'ring_bell'),
        robot_api=BellAndEyes, scene='bell table', cassette=cassette.path))
    yield 'bell'
    scenes.unregister_scene('bell table')
    registry.unregister_domain('bell')


def _seen(graph: Graph) -> list[str]:
    """The names perception serves; none before its first observation of the simulator."""
    try:
        return graph.nodes['perception_node'].source.names()
    except NoObservationError:
        return []


def _wait(predicate, timeout=60.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.01)
    return predicate()


def test_a_toy_domain_registered_from_a_test_runs_through_the_whole_graph(ros_context, bell_domain):
    graph = Graph(ros_context, GraphOptions(domain=bell_domain))
    user = rclpy.create_node('bell_listener', context=ros_context)
    graph.executor.add_node(user)
    rings = []
    user.create_subscription(String, toy_domain.BELL_TOPIC, lambda message: rings.append(message.data), 10)
    try:
        assert graph.world.scene.name == 'bell table'
        assert sorted(state.name for state in graph.world.object_states()) == sorted(o.name for o in TOY_OBJECTS)
        execute = rclpy.action.ActionClient(user, ExecuteCommand, GraphNames.EXECUTE_ACTION)
        assert _wait(execute.server_is_ready)
        assert _wait(lambda: len(_seen(graph)) == 3)
        box = {}
        execute.send_goal_async(ExecuteCommand.Goal(command=COMMAND)).add_done_callback(
            lambda future: box.update(handle=future.result()))
        assert _wait(lambda: 'handle' in box)
        result = box['handle'].get_result_async()
        assert _wait(result.done)
        answer = result.result().result
        assert answer.outcome == ExecuteCommand.Result.OUTCOME_DONE, answer.message
        assert answer.code.strip() == 'ring_bell(len(get_obj_names()))'
        assert _wait(lambda: rings == ['ring x3'], 10)
    finally:
        user.destroy_node()
        graph.close()
