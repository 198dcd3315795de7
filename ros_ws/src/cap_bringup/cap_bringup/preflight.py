"""The preflight of hardware mode: before anything moves, every action, topic and frame a profile names answers, with
the right type (cap_hardware.preflight says what is required and words what is missing; this asks the ROS graph).

    cap preflight PROFILE.yaml [--wait 5]    one line per missing piece, exit 1; "preflight passed", exit 0

Discovery takes a moment on a fresh participant, so the check repeats until everything is found or `wait` seconds
have passed; /joint_states must carry the profile's arm joints and tf must join the camera's optical frame (through
the calibration's camera mount, which the graph itself publishes) and, on a mobile robot, base_link to the world
frame.
"""
from __future__ import annotations

import time
from typing import Callable

from cap_hardware.preflight import problems
from cap_hardware.profile import HardwareProfile
from cap_ros_common.tf import TfListener
from cap_ros_common.transforms import Transform
from rclpy.action import get_action_names_and_types
from sensor_msgs.msg import JointState

CHECK_PERIOD_S = 0.2


def calibration_transforms(profile: HardwareProfile) -> list[Transform]:
    """What the graph publishes on /tf_static from the profile's calibration: the camera's mount."""
    mount = profile.calibration.camera_mount
    return [Transform(mount.parent, mount.child, 0.0, mount.translation, mount.rotation)]


def run_preflight(node, spin_once: Callable[[float], None], profile: HardwareProfile, wait_s: float = 5.0,
                  log: Callable[[str], None] = print) -> bool:
    """Check `profile` against the graph `node` sees (spun by `spin_once(timeout)`) for up to `wait_s` seconds;
    log one line per problem (or that it passed) and return whether it passed."""
    tf = TfListener(node)
    tf.buffer.add(calibration_transforms(profile), static=True)
    joint_names: list[list[str]] = []
    node.create_subscription(JointState, profile.arm.joint_states, lambda m: joint_names.append(list(m.name)), 10)

    def connected(frame: str, other: str) -> bool:
        return tf.buffer.can_transform(other, frame)

    deadline = time.monotonic() + wait_s
    while True:
        spin_once(CHECK_PERIOD_S)
        actions = {name: list(types) for name, types in get_action_names_and_types(node)}
        topics = {name: list(types) for name, types in node.get_topic_names_and_types()}
        found = problems(profile, actions, topics, connected, joint_names[-1] if joint_names else None)
        if not found or time.monotonic() >= deadline:
            break
    for line in found:
        log(line)
    if not found:
        log(f'preflight passed: {profile.name} offers everything its profile names')
    return not found


__all__ = ['calibration_transforms', 'run_preflight']
