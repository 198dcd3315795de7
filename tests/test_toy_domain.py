"""A new domain plugs in from another package alone: a toy prompt, a toy robot API and a toy scene, through the whole
graph, following docs/architecture.md's "Adding a domain".

Nothing of the project is edited: the test installs a package (a module and its entry points, as pip would) that
offers the scene in `cap_ros.scenes` and the domain in `cap_ros.domains`, under the domain's one name; then
`GraphOptions(domain=...)` brings up the graph with both (the simulator loads the domain's scene, lmp_node its prompt
and API). The toy API rings a bell (a message on `toy/bell`) and counts the objects perception sees, so the command
"ring the bell once for every object" shows the three parts working as one.
"""
from __future__ import annotations

import time

import pytest
import rclpy
from std_msgs.msg import String

from cap_bringup import cli
from cap_bringup.cli import BENCHMARK_GROUP
from cap_bringup.demos import DEMOS
from cap_bringup.graph import Graph, GraphOptions
from cap_interfaces.action import ExecuteCommand
from cap_interfaces.msg import GraphNames
from cap_lmp.cassette import ANY_CONTEXT, Cassette, CassetteEntry
from cap_lmp_ros.domains import registry
from cap_lmp_ros.testing import toy_domain
from cap_perception.sources import NoObservationError
from cap_sim_bridge import scenes

COMMAND = 'ring the bell once for every object'
OBJECTS = ['red block', 'green block', 'blue block']
# The package the test installs: the domain's scene, its robot API and the domain itself, in one module.
PLUGIN = '''
from pathlib import Path

from cap_lmp_ros.domains.registry import Domain
from cap_lmp_ros.domains.tabletop.robot_api import RosTabletopApi
from cap_lmp_ros.testing import toy_domain
from cap_sim_bridge import scenes
from cap_sim_bridge.objects import ObjectSpec

NAME = 'bell'
# Step 2, the scene: a small round table with the robot; three blocks stand on it in the default episode.
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
OBJECTS = [ObjectSpec('red block', 'block', 'red', position=(-0.1, -0.45)),
           ObjectSpec('green block', 'block', 'green', position=(0.0, -0.55)),
           ObjectSpec('blue block', 'block', 'blue', position=(0.1, -0.45))]
SCENE = scenes.SceneSpec(NAME, build=scenes.mjcf_builder(TOY_MJCF), default_objects=lambda seed: list(OBJECTS),
                         camera_names=('overhead',))


class BellAndEyes(RosTabletopApi):
    """Step 4, the robot API: `ring_bell(times)` over ROS, plus the table top's `get_obj_names` (perception)."""

    def __init__(self, node, say_publisher, service_timeout_s=5.0, motion_timeout_s=180.0):
        super().__init__(node, say_publisher, service_timeout_s, motion_timeout_s)
        self._bell = toy_domain.RosToyApi(node, say_publisher, service_timeout_s, motion_timeout_s)

    def functions(self):
        return {'get_obj_names': super().functions()['get_obj_names'], 'ring_bell': self._bell.ring_bell}


# Step 5, the domain: the toy LMP's engine, the API, the scene by its name, and the cassette.
DOMAIN = Domain(name=NAME, build_engine=toy_domain.build_engine, robot_functions=('get_obj_names', 'ring_bell'),
                robot_api=BellAndEyes, scene=NAME, cassette=Path(%r))


# Step 7, a demo and a benchmark (each a main(argv) -> exit code; a real one runs the graph).
def demo(argv):
    return 0


def bench(argv):
    return 0
'''


@pytest.fixture
def bell_domain(tmp_path, install_plugin):
    cassette = Cassette(tmp_path / 'bell.yaml', [CassetteEntry(
        lmp='toy_ui', query=COMMAND, context=ANY_CONTEXT, completion='ring_bell(len(get_obj_names()))',
        source='written by hand for the toy-domain test')])
    cassette.save()
    # Step 6, the entry points, under the domain's one name.
    install_plugin({'bell_domain': PLUGIN % str(cassette.path)},
                   {scenes.ENTRY_POINT_GROUP: {'bell': 'bell_domain:SCENE'},
                    registry.ENTRY_POINT_GROUP: {'bell': 'bell_domain:DOMAIN'},
                    DEMOS.group: {'bell': 'bell_domain:demo'}, BENCHMARK_GROUP: {'bell': 'bell_domain:bench'}},
                   name='bell-domain')
    return 'bell'


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
        # The cap command finds the domain's demo and benchmark by the domain's name.
        assert cli.main(['demo', 'bell']) == 0 and cli.main(['bench', 'bell']) == 0
        assert graph.world.scene.name == 'bell'
        assert sorted(state.name for state in graph.world.object_states()) == sorted(OBJECTS)
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
