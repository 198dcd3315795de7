"""The plants a generated controller drives, and what a controller sees of them.

Units: metres, radians, seconds, newtons. Two plants:

- **cartpole**: a cart on a straight rail along the world x axis with a pole hinged on it (the classic parameters of
  Barto, Sutton and Anderson's balancing task: cart 1.0 kg, pole 0.1 kg and 1.0 m long, push at most 10 N, the
  episode fails when the cart leaves +-2.4 m or the pole leans more than 12 degrees). theta = 0 is upright; a
  positive theta leans the pole's top towards +x, and a positive force pushes the cart towards +x, so a pole
  leaning right is caught by pushing right. The controller's output is the force on the cart [N].
- **arm**: the UR5e with its joints under torque control (the links' gravity is compensated, as a torque-controlled
  arm's own controller does); the controller's output is the six joint torques [N m] on top of that.

Every run starts from a defined plant state (the simulator's lockstep puts the plant there before the first tick,
or refuses the run saying why): the cart-pole at the seeded start of the last scene reset, at rest and held until the
controller takes it over; the arm on its position servos, at rest where it is (ARM_REST_SPEED).

Every tick the control loop sends the controller one flat state vector; `cartpole_state` / `ArmState.unpack` read
it (the layout's one home, used by the control node that packs it and by the sandbox side that unpacks it).
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

# ------------------------------------------------------------------------------------------------ the cart-pole
CART_MASS = 1.0  # [kg]
POLE_MASS = 0.1  # [kg], spread along the pole
POLE_LENGTH = 1.0  # [m], hinge to tip
CART_FORCE_LIMIT = 10.0  # [N] the cart's motor, either way
RAIL_LIMIT = 2.4  # [m] the cart must stay within +-RAIL_LIMIT of the rail's centre
POLE_ANGLE_LIMIT = math.radians(12.0)  # [rad] the pole counts as fallen beyond this lean
INITIAL_STATE_RANGE = 0.05  # each of x, x_dot, theta, theta_dot starts uniform in +-this (seeded)
# Where the rail's centre is in the world: behind the arm's base, out of its reach, at the height of its base.
RAIL_CENTRE = (0.0, 1.5, 0.3)

CART_JOINT = 'cart_slide'
POLE_JOINT = 'pole_hinge'
CARTPOLE_JOINTS = (CART_JOINT, POLE_JOINT)
CART_ACTUATOR = 'cart_motor'
CARTPOLE_STATE_NAMES = ('x', 'x_dot', 'theta', 'theta_dot')

# ------------------------------------------------------------------------------------------------ the arm
ARM_JOINTS = ('shoulder_pan_joint', 'shoulder_lift_joint', 'elbow_joint', 'wrist_1_joint', 'wrist_2_joint',
              'wrist_3_joint')
ARM_ACTUATORS = ('shoulder_pan', 'shoulder_lift', 'elbow', 'wrist_1', 'wrist_2', 'wrist_3')
ARM_TORQUE_LIMITS = (150.0, 150.0, 150.0, 28.0, 28.0, 28.0)  # [N m] Universal Robots' published limits
ARM_JOINT_SPEED_LIMIT = 1.5  # [rad/s] a controller that moves a joint faster is stopped (the UR5e can do pi)
# The tool centre point must stay inside this box while a controller drives the arm [m, world frame].
ARM_WORKSPACE_MIN = (-0.7, -0.9, 0.05)
ARM_WORKSPACE_MAX = (0.7, 0.1, 0.9)
# Arm pose where the impedance templates start: the tool points down at (0.0, -0.45, 0.35), over the middle of the
# table top's front half, elbow up (every joint well inside its range).
ARM_READY_POSITION = (0.0, -0.45, 0.35)
# A run of the arm starts with the arm on its position servos and at rest: every joint slower than this [rad/s],
# reached within ARM_SETTLE_LIMIT_S [s of simulated time] of holding, or the run is refused.
ARM_REST_SPEED = 0.01
ARM_SETTLE_LIMIT_S = 2.0

# ------------------------------------------------------------------------------------------------ the loop
DEFAULT_RATE = 100.0  # [Hz] of simulated time
MIN_RATE, MAX_RATE = 1.0, 500.0
MAX_DURATION = 600.0  # [s] of simulated time, one run
# The controller function's own time per call, by default, as a share of the period: it leaves the rest of the
# period to the transport, the plant and the limits.
DEFAULT_BUDGET_SHARE = 0.5
# A controller asking for more than this multiple of an actuator's limit is stopped rather than clamped: it is
# unstable or in the wrong units.
EFFORT_STOP_FACTOR = 5.0


@dataclasses.dataclass(frozen=True)
class PlantSpec:
    """One plant: the joints whose state the loop reads, the actuators its output drives, their limits."""

    name: str
    joints: tuple[str, ...]
    actuators: tuple[str, ...]
    effort_limits: tuple[float, ...]
    state_size: int  # length of the flat state vector a controller is sent, time included
    description: str


CARTPOLE = PlantSpec('cartpole', CARTPOLE_JOINTS, (CART_ACTUATOR,), (CART_FORCE_LIMIT,), 1 + 4,
                     'a cart on a rail with a hinged pole; output: the force on the cart [N]')
ARM = PlantSpec('arm', ARM_JOINTS, ARM_ACTUATORS, ARM_TORQUE_LIMITS, 1 + 6 + 6 + 16 + 6 + 36,
                'the UR5e under torque control; output: six joint torques [N m]')
PLANTS: dict[str, PlantSpec] = {CARTPOLE.name: CARTPOLE, ARM.name: ARM}


def plant(name: str) -> PlantSpec:
    """The plant called `name`; ValueError naming the plants there are."""
    spec = PLANTS.get(name)
    if spec is None:
        raise ValueError(f'unknown plant {name!r}; the plants are: {", ".join(sorted(PLANTS))}')
    return spec


def default_budget(rate: float) -> float:
    """The controller function's time budget per call at `rate` [s]."""
    return DEFAULT_BUDGET_SHARE / rate


# ------------------------------------------------------------------------------------------------ state vectors
def cartpole_vector(time: float, x: float, x_dot: float, theta: float, theta_dot: float) -> np.ndarray:
    return np.array([time, x, x_dot, theta, theta_dot], dtype=float)


def cartpole_state(vector: np.ndarray) -> np.ndarray:
    """[x, x_dot, theta, theta_dot] out of a cart-pole state vector."""
    return np.asarray(vector, dtype=float)[1:5].copy()


@dataclasses.dataclass(frozen=True)
class ArmState:
    """What a controller of the arm sees at one tick (world frame; the tool centre point's pose and velocity)."""

    time: float
    q: np.ndarray  # (6,) joint positions [rad]
    qd: np.ndarray  # (6,) joint velocities [rad/s]
    ee_pose: np.ndarray  # (4, 4) world_T_tcp
    ee_velocity: np.ndarray  # (6,) linear [m/s] then angular [rad/s] velocity of the tcp
    jacobian: np.ndarray  # (6, 6) rows: linear then angular; ee_velocity = jacobian @ qd

    def pack(self) -> np.ndarray:
        return np.concatenate([[self.time], self.q, self.qd, np.asarray(self.ee_pose).reshape(16),
                               self.ee_velocity, np.asarray(self.jacobian).reshape(36)]).astype(float)

    @staticmethod
    def unpack(vector: np.ndarray) -> 'ArmState':
        values = np.asarray(vector, dtype=float)
        if values.shape != (ARM.state_size,):
            raise ValueError(f'an arm state has {ARM.state_size} values, not {values.shape}')
        return ArmState(time=float(values[0]), q=values[1:7].copy(), qd=values[7:13].copy(),
                        ee_pose=values[13:29].reshape(4, 4).copy(), ee_velocity=values[29:35].copy(),
                        jacobian=values[35:71].reshape(6, 6).copy())


def rotation_error(goal: np.ndarray, actual: np.ndarray) -> np.ndarray:
    """Rotation vector [rad] that turns the rotation matrix `actual` into `goal`, in the world frame."""
    relative = np.asarray(goal, dtype=float) @ np.asarray(actual, dtype=float).T
    cos_angle = float(np.clip((np.trace(relative) - 1.0) / 2.0, -1.0, 1.0))
    angle = math.acos(cos_angle)
    axis = np.array([relative[2, 1] - relative[1, 2], relative[0, 2] - relative[2, 0], relative[1, 0] - relative[0, 1]])
    if angle < 1e-9:
        return 0.5 * axis  # small angles: the skew part is the rotation vector
    if math.pi - angle < 1e-6:  # half a turn: the axis from the symmetric part
        symmetric = (relative + np.eye(3)) / 2.0
        column = int(np.argmax(np.diag(symmetric)))
        axis = symmetric[:, column] / math.sqrt(max(symmetric[column, column], 1e-12))
        return angle * axis
    return angle / (2.0 * math.sin(angle)) * axis


def pose_error(goal_pose: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """(6,) error from `pose` to `goal_pose` (4x4 each): position difference [m], then rotation vector [rad]."""
    goal_pose, pose = np.asarray(goal_pose, dtype=float), np.asarray(pose, dtype=float)
    return np.concatenate([goal_pose[:3, 3] - pose[:3, 3], rotation_error(goal_pose[:3, :3], pose[:3, :3])])


__all__ = ['ARM', 'ARM_ACTUATORS', 'ARM_JOINTS', 'ARM_JOINT_SPEED_LIMIT', 'ARM_READY_POSITION', 'ARM_REST_SPEED',
           'ARM_SETTLE_LIMIT_S', 'ARM_TORQUE_LIMITS', 'ARM_WORKSPACE_MAX', 'ARM_WORKSPACE_MIN', 'ArmState', 'CARTPOLE',
           'CARTPOLE_JOINTS', 'CARTPOLE_STATE_NAMES', 'CART_ACTUATOR', 'CART_FORCE_LIMIT', 'CART_JOINT', 'CART_MASS',
           'DEFAULT_BUDGET_SHARE', 'DEFAULT_RATE', 'EFFORT_STOP_FACTOR', 'INITIAL_STATE_RANGE', 'MAX_DURATION',
           'MAX_RATE', 'MIN_RATE', 'PLANTS', 'POLE_ANGLE_LIMIT', 'POLE_JOINT', 'POLE_LENGTH', 'POLE_MASS', 'PlantSpec',
           'RAIL_CENTRE', 'RAIL_LIMIT', 'cartpole_state', 'cartpole_vector', 'default_budget', 'plant', 'pose_error',
           'rotation_error']
