"""A hardware profile: what a real robot offers the graph (actions, topics, frames), its calibration and its limits.

The graph's skills speak standard interfaces; a profile says under which names a given robot serves them, so that
ur_robot_driver's `/scaled_joint_trajectory_controller/follow_joint_trajectory` and the simulator's own trajectory
action are one parameter apart. A profile is a YAML file (profiles/ holds the shipped ones; README "Running on a
real robot" explains every field):

    name: ur5e_robotiq_d435
    domain: tabletop                    # which domain's prompts, robot API and detector run
    world_frame: base                   # the frame positions are given in (the arm's base frame, or map)
    require_approval: true              # every program waits for a person's yes before anything moves
    rehearse: always                    # every program runs on a twin first (always, on_approval, off)
    arm: {controller_action, joint_states, joints, speed_scale}
    gripper: {action, open_position, closed_position, max_opening, max_effort}
    camera: {color, depth, camera_info, frame}
    navigation: {navigate_to_pose, navigate_through_poses, costmap, base_frame}   # a mobile robot only
    calibration: calibration.yaml       # relative to the profile: camera mount and workspace

Plain Python and PyYAML, no ROS.
"""
from __future__ import annotations

import dataclasses
import math
import pathlib
from typing import Any

import yaml

UR_JOINTS = ('shoulder_pan_joint', 'shoulder_lift_joint', 'elbow_joint', 'wrist_1_joint', 'wrist_2_joint',
             'wrist_3_joint')
SHIPPED = pathlib.Path(__file__).resolve().parent / 'profiles'
_FLOAT_TUPLES = ('translation', 'rotation', 'x_range', 'y_range')


class ProfileError(ValueError):
    """A profile or calibration file that cannot be used; the message names the file and the field."""


@dataclasses.dataclass(frozen=True)
class ArmProfile:
    controller_action: str  # control_msgs/action/FollowJointTrajectory
    joint_states: str = '/joint_states'  # sensor_msgs/msg/JointState
    joints: tuple[str, ...] = UR_JOINTS  # in the kinematics' order: base to wrist
    # Fraction of the UR5e's joint speeds and of the tool's line speed the graph plans with (1 = the full speeds
    # the simulator uses); a first run on a new cell wants a small one.
    speed_scale: float = 0.25


@dataclasses.dataclass(frozen=True)
class GripperProfile:
    action: str  # control_msgs/action/GripperCommand
    # The command positions of a fully open and a fully closed gripper, in the controller's units (a Robotiq
    # 2F-85's knuckle joint: 0.0 open, 0.8 closed [rad]; the simulator's: the opening itself, 0.085 and 0 [m]).
    open_position: float = 0.0
    closed_position: float = 0.8
    max_opening: float = 0.085  # [m] between the fingers when open
    max_effort: float = 100.0  # [N] the largest grip force the graph asks for
    # A joint of the joint states whose position is in the command's units (a Robotiq's knuckle joint), read for
    # how far the fingers are open; empty: the opening is known only from each command's result.
    joint: str = ''

    def position_for(self, opening: float) -> float:
        """The command position that opens the fingers `opening` metres (clamped to what the gripper can)."""
        fraction = min(max(opening / self.max_opening, 0.0), 1.0)
        return self.closed_position + fraction * (self.open_position - self.closed_position)

    def opening_of(self, position: float) -> float:
        """The opening [m] a reported position means."""
        span = self.open_position - self.closed_position
        return self.max_opening * (position - self.closed_position) / span


@dataclasses.dataclass(frozen=True)
class CameraProfile:
    color: str  # sensor_msgs/msg/Image, rgb8 or bgr8
    depth: str  # sensor_msgs/msg/Image aligned with the colour image, 16UC1 [mm] or 32FC1 [m]
    camera_info: str  # sensor_msgs/msg/CameraInfo of the colour image
    frame: str  # the images' frame_id (an optical frame, REP-103), found on tf


@dataclasses.dataclass(frozen=True)
class NavigationProfile:
    navigate_to_pose: str = '/navigate_to_pose'  # nav2_msgs/action/NavigateToPose
    navigate_through_poses: str = '/navigate_through_poses'  # nav2_msgs/action/NavigateThroughPoses
    # Where the base's centre may not stand (nav_msgs/msg/OccupancyGrid, 99 or more = not): nav2's global costmap.
    costmap: str = '/global_costmap/costmap'
    base_frame: str = 'base_link'  # REP-105: map -> odom -> base_link


@dataclasses.dataclass(frozen=True)
class Mount:
    """A calibrated transform the graph publishes on /tf_static: `child`'s pose in `parent`."""

    parent: str
    child: str
    translation: tuple[float, float, float]
    rotation: tuple[float, float, float, float]  # quaternion x, y, z, w


@dataclasses.dataclass(frozen=True)
class Workspace:
    """The table's bounds in world_frame [m], where objects are looked for and placed."""

    x_range: tuple[float, float] = (-0.3, 0.3)
    y_range: tuple[float, float] = (-0.8, -0.2)
    surface_z: float = 0.0


@dataclasses.dataclass(frozen=True)
class Calibration:
    camera_mount: Mount
    workspace: Workspace = Workspace()


@dataclasses.dataclass(frozen=True)
class HardwareProfile:
    name: str
    domain: str
    world_frame: str
    arm: ArmProfile
    gripper: GripperProfile
    camera: CameraProfile
    calibration: Calibration
    navigation: NavigationProfile | None = None
    require_approval: bool = True
    rehearse: str = 'always'  # lmp_node's rehearse on this robot (it checks the value)
    path: pathlib.Path | None = None  # the file it was read from


def _section(data: dict, key: str, kind: type, where: str, required: bool = True) -> Any:
    """A dataclass from data[key] (a mapping), naming a missing or unknown field in the error."""
    value = data.get(key)
    if value is None:
        if required:
            raise ProfileError(f'{where}: `{key}` is missing')
        return None
    if not isinstance(value, dict):
        raise ProfileError(f'{where}: `{key}` must be a mapping of fields')
    fields = {field.name: field for field in dataclasses.fields(kind)}
    unknown = sorted(set(value) - set(fields))
    if unknown:
        raise ProfileError(f'{where}: `{key}` has unknown fields {unknown}; known: {sorted(fields)}')
    missing = [name for name, field in fields.items() if name not in value and
               field.default is dataclasses.MISSING and field.default_factory is dataclasses.MISSING]
    if missing:
        raise ProfileError(f'{where}: `{key}.{missing[0]}` is missing')
    converted = {}
    for name, raw in value.items():
        default = fields[name].default
        try:
            if name in _FLOAT_TUPLES:
                converted[name] = tuple(float(item) for item in raw)
            elif name == 'joints':
                converted[name] = tuple(str(item) for item in raw)
            elif isinstance(default, float):
                converted[name] = float(raw)
            elif not isinstance(raw, str) or not raw:
                raise ValueError('expected a name')
            else:
                converted[name] = raw
        except (TypeError, ValueError) as error:
            raise ProfileError(f'{where}: `{key}.{name}` is not what it should be ({error})') from None
    return kind(**converted)


def _read(path: pathlib.Path) -> dict:
    try:
        data = yaml.safe_load(path.read_text(encoding='utf-8'))
    except OSError as error:
        raise ProfileError(f'{path}: cannot be read ({error.strerror})') from None
    except yaml.YAMLError as error:
        raise ProfileError(f'{path}: not YAML ({error})') from None
    if not isinstance(data, dict):
        raise ProfileError(f'{path}: expected a mapping of fields')
    return data


def load_calibration(path: pathlib.Path) -> Calibration:
    data = _read(path)
    mount = _section(data, 'camera_mount', Mount, str(path))
    if len(mount.translation) != 3 or len(mount.rotation) != 4 or not all(map(math.isfinite, mount.translation)) \
            or not 0.5 < math.hypot(*mount.rotation) < 1.5:
        raise ProfileError(f'{path}: camera_mount needs a translation x, y, z and a unit quaternion x, y, z, w')
    workspace = _section(data, 'workspace', Workspace, str(path), required=False) or Workspace()
    return Calibration(mount, workspace)


def load_profile(path: str | pathlib.Path) -> HardwareProfile:
    """The profile in `path` (a file, or the name of a shipped profile); ProfileError saying what is wrong."""
    path = pathlib.Path(path)
    if not path.suffix and not path.exists():
        path = SHIPPED / f'{path}.yaml'
    data = _read(path)
    where = str(path)
    known = {field.name for field in dataclasses.fields(HardwareProfile)} - {'path'}
    unknown = sorted(set(data) - known)
    if unknown:
        raise ProfileError(f'{where}: unknown fields {unknown}; known: {sorted(known)}')
    for key in ('name', 'domain', 'world_frame', 'calibration'):
        if not isinstance(data.get(key), str) or not data[key]:
            raise ProfileError(f'{where}: `{key}` is missing (a name)')
    arm = _section(data, 'arm', ArmProfile, where)
    gripper = _section(data, 'gripper', GripperProfile, where)
    if gripper.open_position == gripper.closed_position or gripper.max_opening <= 0:
        raise ProfileError(f'{where}: gripper.open_position and closed_position must differ, max_opening > 0')
    if not 0 < arm.speed_scale <= 1:
        raise ProfileError(f'{where}: arm.speed_scale must be in (0, 1]')
    profile = HardwareProfile(
        name=data['name'], domain=data['domain'], world_frame=data['world_frame'], arm=arm, gripper=gripper,
        camera=_section(data, 'camera', CameraProfile, where),
        calibration=load_calibration(path.parent / data['calibration']),
        navigation=_section(data, 'navigation', NavigationProfile, where, required=False),
        require_approval=bool(data.get('require_approval', True)), rehearse=str(data.get('rehearse', 'always')),
        path=path)
    return profile


def shipped_profiles() -> list[str]:
    """The names of the profiles shipped with this package."""
    return sorted(path.stem for path in SHIPPED.glob('*.yaml') if not path.stem.endswith('calibration'))


__all__ = ['ArmProfile', 'Calibration', 'CameraProfile', 'GripperProfile', 'HardwareProfile', 'Mount',
           'NavigationProfile', 'ProfileError', 'SHIPPED', 'UR_JOINTS', 'Workspace', 'load_calibration',
           'load_profile', 'shipped_profiles']
