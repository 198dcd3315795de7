"""Parameters of the sim_bridge node: the one home of their defaults (declared with declare_config)."""
from __future__ import annotations

import dataclasses

from cap_interfaces.msg import GraphNames
from cap_ros_common.parameters import parameter
from cap_tabletop.cameras import CAMERA_NAMES

from cap_sim_bridge import trajectory_goal
from cap_sim_bridge.scenes import DEFAULT_SCENE, GRIPPER_MAX_OPENING

# The bridge publishes the scene's own cameras while `cameras` is left at this default.
DEFAULT_CAMERAS = tuple(CAMERA_NAMES)


@dataclasses.dataclass(frozen=True)
class SimBridgeConfig:
    scene: str = parameter(DEFAULT_SCENE, 'Registered scene loaded at start and by resets with no scene name.')
    seed: int = parameter(0, 'Seed of the scene loaded at start.')
    objects: str = parameter('', 'Objects of the scene loaded at start, comma-separated names '
                                 '("red block, blue bowl"); empty = the default episode of the seed.')
    real_time: bool = parameter(True, 'true: simulated time follows the wall clock (times real_time_factor); '
                                      'false: simulate as fast as possible.')
    real_time_factor: float = parameter(1.0, 'Simulated seconds per wall second when real_time is true.')
    state_rate: float = parameter(100.0, 'Rate of /clock and /joint_states [Hz of simulated time].')
    objects_rate: float = parameter(10.0, 'Rate of the ground-truth object array [Hz of simulated time].')
    camera_rate: float = parameter(10.0, 'Rate of camera images [Hz of simulated time]; 0 = no images.')
    idle_after: float = parameter(1.0, 'After this long [s of simulated time] with no goal running and nothing '
                                       'moving, publish at the idle rates below (and, without real_time, slow down to '
                                       'idle_speed); 0 = never.')
    idle_speed: float = parameter(10.0, 'Without real_time, while idle: simulated seconds per wall second, instead of '
                                        'as fast as possible (a graph waiting for a program or a model leaves them '
                                        'the CPU); 0 = as fast as possible while idle too.')
    idle_state_rate: float = parameter(5.0, 'Rate of /clock and /joint_states while idle [Hz].')
    idle_objects_rate: float = parameter(1.0, 'Rate of the ground-truth object array while idle [Hz].')
    idle_camera_rate: float = parameter(1.0, 'Rate of camera images while idle [Hz]: the frame rendered when the '
                                             'world came to rest, stamped anew (nothing in view moves).')
    cameras: tuple[str, ...] = parameter(DEFAULT_CAMERAS, 'Cameras to publish; left at the default, the cameras of '
                                                          'the scene.')
    image_width: int = parameter(640, 'Width of the published images [pixels].')
    image_height: int = parameter(480, 'Height of the published images [pixels].')
    publish_depth: bool = parameter(True, 'Publish depth images (32FC1, metres).')
    goal_tolerance: float = parameter(trajectory_goal.DEFAULT_GOAL_TOLERANCE,
                                      'Default per-joint goal tolerance of trajectories [rad].')
    goal_time_tolerance: float = parameter(trajectory_goal.DEFAULT_GOAL_TIME_TOLERANCE,
                                           "Default time after a trajectory's end to meet the goal tolerance [s].")
    gripper_timeout: float = parameter(5.0, 'Longest gripper motion [s of simulated time].')
    arm_controller_action: str = parameter(GraphNames.SIM_FOLLOW_JOINT_TRAJECTORY_ACTION,
                                           'control_msgs/FollowJointTrajectory action served for the arm.')
    base_controller_action: str = parameter(GraphNames.SIM_FOLLOW_BASE_TRAJECTORY_ACTION,
                                            'In a scene with a mobile base: control_msgs/FollowJointTrajectory action '
                                            'served for its x, y and yaw joints.')
    gripper_action: str = parameter(GraphNames.SIM_GRIPPER_ACTION, 'control_msgs/GripperCommand action served for '
                                    'the gripper.')
    gripper_open_position: float = parameter(GRIPPER_MAX_OPENING, 'The GripperCommand position of a fully open '
                                             'gripper: the simulator speaks the opening in metres; a stand-in for a '
                                             'Robotiq speaks its knuckle angle (0.0).')
    gripper_closed_position: float = parameter(0.0, 'The GripperCommand position of a fully closed gripper (a '
                                               'Robotiq\'s knuckle: 0.8).')
    joint_states_topic: str = parameter(GraphNames.JOINT_STATES_TOPIC, 'Where the joint states go.')
    # A hardware stand-in (cap_sim_bridge.standin): the simulator plays a real robot for a graph in hardware mode.
    profile: str = parameter('', 'A hardware profile to play (a file or a shipped profile\'s name): serve only what '
                                 'it names, under its names and units, stamped with the wall clock, with no /clock, '
                                 'no ground truth and no scene services, and with the stand-in\'s perturbations. '
                                 'Empty: the simulator\'s own graph.')
    standin_camera: str = parameter('top', 'With a profile: the scene\'s camera that plays the profile\'s camera, '
                                           'mounted where its calibration says.')
    perturbation_seed: int = parameter(0, 'With a profile: the seed of the stand-in\'s differences from the '
                                          'graph\'s simulator (masses, friction, the camera\'s mount, depth noise).')
    serve_gripper: bool = parameter(True, 'With a profile: serve the gripper action (false: a robot whose gripper '
                                          'controller is not running, for the preflight).')
    ink_rate: float = parameter(5.0, 'In a scene with a whiteboard: most ink images a second of simulated time, '
                                     'sent only when the ink changed [Hz].')
    twin: bool = parameter(False, 'Run as the twin that rehearses programs (cap_sim_bridge.twin_watch): watch for harm '
                                  'after every reset and report it on the twin report service.')
    lockstep_timeout: float = parameter(5.0, 'A controller stepping a plant (ControlStep) that sends no request for '
                                             'this long [s of wall time] loses it: the plant is made safe and the '
                                             'simulation runs freely again.')


def gripper_opening(config: SimBridgeConfig, position: float) -> float:
    """The opening [m] a GripperCommand position asks for, in the configured units."""
    span = config.gripper_open_position - config.gripper_closed_position
    return GRIPPER_MAX_OPENING * (position - config.gripper_closed_position) / span


def gripper_position(config: SimBridgeConfig, opening: float) -> float:
    """The GripperCommand position of an opening [m], in the configured units."""
    span = config.gripper_open_position - config.gripper_closed_position
    return config.gripper_closed_position + span * opening / GRIPPER_MAX_OPENING


def cameras_to_publish(requested: tuple[str, ...], scene_default: tuple[str, ...],
                       in_model: tuple[str, ...]) -> list[str]:
    """The requested cameras (the scene's default ones while the parameter is left at its default); ValueError for
    cameras the scene's model lacks."""
    cameras = list(scene_default) if tuple(requested) == DEFAULT_CAMERAS else list(requested)
    unknown = [c for c in cameras if c not in in_model]
    if unknown:
        raise ValueError(f'unknown cameras {unknown}; the scene has {list(in_model)}')
    return cameras
