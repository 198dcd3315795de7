"""Profiles read as a person wrote them: the shipped ones load, a mistake names its file and field, the gripper's
units map to metres, and the preflight lists exactly what is missing."""
from __future__ import annotations

import pathlib
import re
import shutil

import pytest

from cap_hardware.preflight import GRIPPER_COMMAND, problems, requirements
from cap_hardware.profile import SHIPPED, ProfileError, load_profile, shipped_profiles


def test_the_shipped_profiles_load():
    assert shipped_profiles() == ['mobile_manipulator_nav2', 'ur5e_robotiq_d435']
    arm = load_profile('ur5e_robotiq_d435')
    assert arm.domain == 'tabletop' and arm.world_frame == 'base' and arm.navigation is None
    assert arm.arm.controller_action == '/scaled_joint_trajectory_controller/follow_joint_trajectory'
    assert arm.calibration.camera_mount.parent == 'base' and arm.require_approval
    mobile = load_profile(SHIPPED / 'mobile_manipulator_nav2.yaml')
    assert mobile.domain == 'mobile' and mobile.navigation.navigate_to_pose == '/navigate_to_pose'


def test_the_gripper_command_maps_metres_to_the_controllers_units():
    gripper = load_profile('ur5e_robotiq_d435').gripper
    assert gripper.position_for(0.085) == 0.0 and gripper.position_for(0.0) == 0.8
    assert gripper.position_for(0.2) == 0.0  # clamped to what the gripper can
    assert gripper.opening_of(0.4) == pytest.approx(0.0425)


def _copy(tmp_path: pathlib.Path, name: str = 'ur5e_robotiq_d435') -> pathlib.Path:
    for path in SHIPPED.glob(f'{name}*.yaml'):
        shutil.copy(path, tmp_path / path.name)
    return tmp_path / f'{name}.yaml'


@pytest.mark.parametrize('edit, message', [
    (('  action: /robotiq_gripper_controller/gripper_cmd\n', ''), 'gripper.action` is missing'),
    (('speed_scale: 0.25', 'speed_scale: 3'), 'speed_scale must be in'),
    (('world_frame: base', 'world_frame: base\nwheels: 4'), "unknown fields ['wheels']"),
    (('open_position: 0.0', 'open_position: 0.8'), 'must differ'),
])
def test_a_mistake_in_a_profile_names_the_file_and_the_field(tmp_path, edit, message):
    path = _copy(tmp_path)
    path.write_text(path.read_text().replace(*edit))
    with pytest.raises(ProfileError, match=re.escape(message)) as error:
        load_profile(path)
    assert str(path) in str(error.value)


def test_a_calibration_without_a_unit_quaternion_is_refused(tmp_path):
    path = _copy(tmp_path)
    calibration = tmp_path / 'ur5e_robotiq_d435_calibration.yaml'
    calibration.write_text(calibration.read_text().replace('[0.0, 0.70710678, 0.0, 0.70710678]', '[0, 0, 0, 0]'))
    with pytest.raises(ProfileError, match='unit quaternion'):
        load_profile(path)


def test_the_preflight_names_what_is_missing_with_its_type():
    profile = load_profile('ur5e_robotiq_d435')
    offered = {need.name: [need.type] for need in requirements(profile) if need.kind != 'frame'}
    everything = dict(actions={k: v for k, v in offered.items() if 'action' in v[0]},
                      topics={k: v for k, v in offered.items() if '/msg/' in v[0]})
    assert problems(profile, **everything, connected=lambda a, b: True, joint_names=profile.arm.joints) == []
    actions = dict(everything['actions'])
    del actions[profile.gripper.action]
    found = problems(profile, actions, everything['topics'], lambda a, b: True, profile.arm.joints)
    assert found == [f'missing action {profile.gripper.action} ({GRIPPER_COMMAND}): the gripper\'s action '
                     'controller']
    topics = dict(everything['topics'], **{profile.camera.color: ['sensor_msgs/msg/CompressedImage']})
    found = problems(profile, everything['actions'], topics, lambda a, b: a != profile.camera.frame, ['elbow_joint'])
    assert any(line.startswith(f'wrong type: topic {profile.camera.color} is sensor_msgs/msg/CompressedImage')
               for line in found)
    assert any(line.startswith(f'missing frame {profile.camera.frame} connected to base') for line in found)
    assert any('lacks the joints' in line and 'shoulder_pan_joint' in line for line in found)
