"""lmp_node's side of the twin that rehearses programs (cap_lmp.rehearsal): build it from the world as perceived,
bind the domain's robot API to it, ask it what it saw.

The twin is a simulator (sim_bridge with twin:=true) and the domain's perception and control nodes, run under the
graph's namespace + GraphNames.TWIN_NAMESPACE (cap_bringup.graph starts them). This side talks to them from a node
of its own in that namespace, on the twin's clock: the domain's robot binding is made on it, so the program's calls
on the twin go through the same binding, control nodes and executors as on the robot.

Building the twin: every object real perception knows (name, centre, rotation about the vertical; what it cannot
measure, the object's size and mass, comes from its kind in the simulator; one placed into another, which
perception saw twice, as a ghost nothing touches) and the arm's joints from the real joint states are sent in one
reset; then the twin's perception is waited for until it reports those objects.
"""
from __future__ import annotations

import math
import threading
import time
from typing import Any, Callable, Sequence

import rclpy
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from std_srvs.srv import Trigger

from cap_interfaces.msg import GraphNames, ObjectSpec
from cap_interfaces.srv import GetObjectNames, GetTwinReport, ResetScene
from cap_lmp.errors import RobotApiError
from cap_lmp.rehearsal import Position, TwinHarm, TwinVerdict, harm_text
from cap_lmp_ros.domains.ros_api import wait_for_future

PERCEPTION_WAIT_S = 5.0  # for the twin's perception to report the scene it was reset to [s, wall]
SETTLE_S = 2.0  # at the end of a rehearsal the objects come to rest for at most this long [s, simulated]
EVENT_QOS_DEPTH = 10


def twin_namespace(namespace: str) -> str:
    """The twin's namespace inside a graph's ('/' or '/robot1')."""
    return f"{namespace.rstrip('/')}/{GraphNames.TWIN_NAMESPACE}"


def _yaw(orientation) -> float:
    x, y, z, w = orientation.x, orientation.y, orientation.z, orientation.w
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def positions(states: Sequence[Any]) -> dict[str, Position]:
    """{name: (x, y, z)} of ObjectState messages."""
    return {state.name: (state.position.x, state.position.y, state.position.z) for state in states}


class Twin:
    """The twin as lmp_node uses it. `robot` is lmp_node's binding of the real robot (its perception is read to
    build the twin); `make_binding(node, say_publisher)` makes the domain's binding on the twin's node."""

    def __init__(self, lmp: Node, robot: Any, make_binding: Callable[[Node, Any], Any],
                 joint_states_topic: str, arm_joints: Sequence[str], service_timeout_s: float) -> None:
        namespace = twin_namespace(lmp.get_namespace())
        self.node = rclpy.create_node(
            'lmp_node_twin', namespace=namespace, context=lmp.context,
            cli_args=['--ros-args', '-r', f'{GraphNames.CLOCK_TOPIC}:={namespace}{GraphNames.CLOCK_TOPIC}'],
            parameter_overrides=[Parameter('use_sim_time', value=True)])
        self._robot = robot
        self.service_timeout_s = service_timeout_s
        group = ReentrantCallbackGroup()
        # The twin's `say` goes to the twin's own topic: nobody hears a rehearsal speak.
        self.binding = make_binding(self.node, self.node.create_publisher(String, GraphNames.SAY_TOPIC,
                                                                          EVENT_QOS_DEPTH))
        self._reset = self.node.create_client(ResetScene, GraphNames.SIM_RESET_SERVICE, callback_group=group)
        self._report = self.node.create_client(GetTwinReport, GraphNames.SIM_TWIN_REPORT_SERVICE,
                                               callback_group=group)
        self._forget = self.node.create_client(Trigger, GraphNames.PERCEPTION_FORGET_SERVICE, callback_group=group)
        self._names = self.node.create_client(GetObjectNames, GraphNames.PERCEPTION_OBJECT_NAMES_SERVICE,
                                              callback_group=group)
        # Control nodes that remember what they did (the mobile gripper's load) start afresh with each twin.
        self._control_forget = self.node.create_client(Trigger, GraphNames.CONTROL_FORGET_SERVICE,
                                                       callback_group=group)
        self._arm_joints = tuple(arm_joints)
        self._joints_lock = threading.Lock()
        self._joints: dict[str, float] = {}
        lmp.create_subscription(JointState, joint_states_topic, self._on_joint_state, 10, callback_group=group)
        self.stop_requested = threading.Event()

    def _on_joint_state(self, message: JointState) -> None:
        with self._joints_lock:
            self._joints.update(zip(message.name, message.position))

    def arm_positions(self) -> list[float]:
        """The real arm's joints in the twin's order; empty while unknown (the twin then starts it at home)."""
        with self._joints_lock:
            if not all(name in self._joints for name in self._arm_joints):
                return []
            return [float(self._joints[name]) for name in self._arm_joints]

    def _call(self, client, request, what: str, timeout_s: float | None = None):
        timeout_s = timeout_s or self.service_timeout_s
        if not client.wait_for_service(timeout_sec=timeout_s):
            raise RobotApiError(f'the twin\'s {what} ({client.srv_name}) is not running')
        return wait_for_future(client.call_async(request), timeout_s, f"the twin's {what}", self.stop_requested,
                               timeout_s)

    # ------------------------------------------------------------------------------------------------ build
    def build(self) -> dict[str, Position]:
        """Reset the twin to the world as perceived now; the objects it was built from. RobotApiError when it
        cannot be built (the rehearsal then fails, and nothing moves)."""
        # Seen now first: of two objects perception reports in one place, the later becomes the ghost.
        states = sorted(self._robot.object_states(), key=lambda state: not state.visible)
        specs = [ObjectSpec(name=state.name, category=state.category, color_name=state.color_name,
                            use_position=True, position=state.position, use_height=True,
                            yaw=_yaw(state.orientation)) for state in states]
        base_pose: list[float] = []
        base = getattr(self._robot, 'get_robot_pos_and_angle', None)  # a mobile base: the twin's stands there too
        if base is not None:
            (x, y), yaw = base()
            base_pose = [float(x), float(y), float(yaw)]
        self._call(self._forget, Trigger.Request(), 'perception')
        response = self._call(self._reset, ResetScene.Request(objects=specs, exactly=True, ghost_overlaps=True,
                                                              base_pose=base_pose,
                                                              arm_joint_positions=self.arm_positions()), 'simulator')
        if not response.success:
            raise RobotApiError(f'the twin could not be built from the scene as perceived: {response.message}')
        wanted = sorted(state.name for state in states)
        deadline = time.monotonic() + PERCEPTION_WAIT_S
        while True:  # the twin's perception answers from the reset scene, not from the one before
            names = sorted(self._call(self._names, GetObjectNames.Request(), 'perception').names)
            if names == wanted:
                break
            if time.monotonic() > deadline:
                raise RobotApiError(f"the twin's perception did not report the scene it was built from within "
                                    f'{PERCEPTION_WAIT_S:g} s (it sees {names}, the robot\'s {wanted})')
            time.sleep(0.02)
        # Offered by the domains whose control nodes remember (mobile pick-and-place): found by now, as the twin's
        # other services were, and not waited for where no node offers it.
        if self._control_forget.service_is_ready():
            self._call(self._control_forget, Trigger.Request(), 'control node')
        self.binding.stop_requested.clear()
        begin_command = getattr(self.binding, 'begin_command', None)
        if begin_command is not None:
            begin_command()
        return positions(states)

    # ------------------------------------------------------------------------------------------------ watch
    def check_harm(self, function: str) -> None:
        """After an acting call on the twin: TwinHarm if the twin saw harm so far."""
        report = self._call(self._report, GetTwinReport.Request(settle_s=0.0), 'simulator')
        if report.findings:
            raise TwinHarm(harm_text(list(report.findings), function))

    def verdict(self, verdict: TwinVerdict) -> TwinVerdict:
        """Fill `verdict` with what the twin saw once its objects came to rest, where it left them and a picture."""
        report = self._call(self._report, GetTwinReport.Request(settle_s=SETTLE_S, picture=True), 'simulator',
                            timeout_s=max(self.service_timeout_s, 15.0))
        verdict.findings = list(report.findings)
        verdict.predicted = positions(report.objects)
        verdict.simulated_s = report.simulated_s
        verdict.image_png = bytes(report.image.data)
        return verdict

    def observe(self) -> dict[str, Position]:
        """Where real perception sees the objects now (those it sees)."""
        return positions([state for state in self._robot.object_states() if state.visible])

    def stop(self) -> None:
        self.stop_requested.set()
        self.binding.stop()

    def destroy(self) -> None:
        self.node.destroy_node()


__all__ = ['Twin', 'positions', 'twin_namespace']
