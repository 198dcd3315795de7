"""Hardware mode: the graph's node parameters that point it at a real robot, from its hardware profile (no rclpy).

The skills' nodes take the names and units of the robot's controllers (cap_control.robot_interfaces), perception
the RGB-D detector of the profile's domain on the profile's camera topics with the camera's pose from tf (a real
robot has no ground truth), the calibration node the profile's camera mount, lmp_node the domain and approval; the
skills plan with the profile's speed scale inside the calibration's workspace. Both `cap up --hardware` (graph.py)
and hardware.launch.py use these values.
"""
from __future__ import annotations

from typing import Any

from cap_control.pick_place.plan import PickPlaceConfig
from cap_hardware.profile import HardwareProfile


HARDWARE_VIEW_TIMEOUT_S = 10.0  # pick_place's view_timeout on a real robot [s]

def _arm(profile: HardwareProfile) -> dict[str, Any]:
    arm, gripper = profile.arm, profile.gripper
    return {'joint_states_topic': arm.joint_states, 'arm_controller_action': arm.controller_action,
            'arm_joints': list(arm.joints), 'gripper_action': gripper.action,
            'gripper_open_position': gripper.open_position, 'gripper_closed_position': gripper.closed_position,
            'gripper_max_opening': gripper.max_opening, 'gripper_joint': gripper.joint}


def _pick_place(profile: HardwareProfile) -> dict[str, Any]:
    """Pick-and-place inside the calibration's workspace, at the profile's speed, clearing the camera's view."""
    scale, workspace = profile.arm.speed_scale, profile.calibration.workspace
    limits = PickPlaceConfig().cartesian_limits
    values = {**_arm(profile), 'velocity_scale': scale, 'acceleration_scale': scale,
              'cartesian_limits.speed': limits.speed * scale,
              'cartesian_limits.acceleration': limits.acceleration * scale,
              'workspace.x_min': workspace.x_range[0], 'workspace.x_max': workspace.x_range[1],
              'workspace.y_min': workspace.y_range[0], 'workspace.y_max': workspace.y_range[1],
              'workspace.table_z': workspace.surface_z}
    mount = profile.calibration.camera_mount
    if mount.parent == profile.world_frame:  # a camera over the table: keep out of its line of sight
        values.update(clear_view=True, camera_position=list(mount.translation))
    # A real camera's frames reach the detector later than a simulator's, and the detector shares its CPU with the
    # whole graph: a place is judged on a view taken after it, waited for this long before the last one is used.
    values['view_timeout'] = HARDWARE_VIEW_TIMEOUT_S
    return values


def hardware_overrides(profile: HardwareProfile) -> dict[str, dict[str, Any]]:
    """{node name: {parameter: value}} of the graph's nodes on the profile's robot (nodes it lacks are ignored)."""
    camera = profile.camera
    values: dict[str, dict[str, Any]] = {
        'calibration': {'profile': str(profile.path)},
        'perception_node': {'source': 'rgbd', 'detector': profile.domain, 'color_topic': camera.color,
                            'depth_topic': camera.depth, 'camera_info_topic': camera.camera_info,
                            'world_frame': profile.world_frame},
        'pick_place': _pick_place(profile),
        'follow_path': _arm(profile),
        # Programs are rehearsed on a twin first (the profile says when); the twin starts its arm where the robot's is.
        'lmp_node': {'domain': profile.domain, 'require_approval': profile.require_approval,
                     'rehearse': profile.rehearse,
                     'twin_joint_states_topic': profile.arm.joint_states, 'twin_arm_joints': list(profile.arm.joints)},
        'visualization': {'frame_id': profile.world_frame},
    }
    navigation = profile.navigation
    if navigation is not None:
        values['mobile_pick_place'] = {**_arm(profile), 'navigate_to_pose_action': navigation.navigate_to_pose,
                                       'costmap_topic': navigation.costmap, 'world_frame': profile.world_frame,
                                       'base_frame': navigation.base_frame}
    for node in values.values():
        node['use_sim_time'] = False  # a real robot's clock is the wall clock
    return values


def robot_api_remappings(profile: HardwareProfile) -> list[tuple[str, str]]:
    """Remappings of the robot API's node: the mobile API asks nav2 under nav2's own names (navigate_to_pose, ...),
    which a profile may name otherwise."""
    navigation = profile.navigation
    if navigation is None:
        return []
    return [(name, target) for name, target in (('navigate_to_pose', navigation.navigate_to_pose),
                                                ('navigate_through_poses', navigation.navigate_through_poses))
            if target.lstrip('/') != name]


__all__ = ['hardware_overrides', 'robot_api_remappings']
