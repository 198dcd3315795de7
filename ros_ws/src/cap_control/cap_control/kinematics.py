"""UR5e forward and inverse kinematics, and the top-down grasp orientation used over the table.

Frames: the world frame is the UR5e's DH base frame (z up, base at the origin). Joint i transforms by
Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i) with Universal Robots' published DH parameters. The tool centre point (TCP,
the grasp point between the fingertips) lies `tool_offset` metres along the flange's (DH frame 6) +z axis.

Inverse kinematics is the analytic closed form of UR arms (three parallel middle axes, offset wrist). It was chosen
over an iterative solver because it returns every solution branch (up to 8) in a few microseconds, never fails to
converge near a reachable pose, and tells plainly *why* a pose is unreachable (too far, too close to the base axis);
picking the branch nearest a seed gives smooth, predictable motions without local-minimum surprises.
"""
from __future__ import annotations

import math
from typing import Iterable, Sequence

import numpy as np

JOINT_NAMES: tuple[str, ...] = (
    'shoulder_pan_joint', 'shoulder_lift_joint', 'elbow_joint', 'wrist_1_joint', 'wrist_2_joint', 'wrist_3_joint',
)

# Universal Robots' published DH parameters of the UR5e [m, rad].
DH_A = np.array([0.0, -0.425, -0.3922, 0.0, 0.0, 0.0])
DH_D = np.array([0.1625, 0.0, 0.0, 0.1333, 0.0997, 0.0996])
DH_ALPHA = np.array([math.pi / 2, 0.0, 0.0, math.pi / 2, -math.pi / 2, 0.0])

# Joint range: +-360 deg, elbow +-180 deg.
JOINT_LOWER = np.array([-2 * math.pi, -2 * math.pi, -math.pi, -2 * math.pi, -2 * math.pi, -2 * math.pi])
JOINT_UPPER = -JOINT_LOWER

DEFAULT_TOOL_OFFSET = 0.15
# Reach of the elbow chain (shoulder-lift axis to wrist-1 axis) when fully stretched.
ARM_REACH = abs(DH_A[1]) + abs(DH_A[2])

# UR's classic ready pose, over the table: TCP at about (0.133, -0.492, 0.338) pointing down, elbow up. The default
# IK seed, so that unseeded solutions land on the branch used for table-top work.
HOME_JOINTS = np.array([math.pi / 2, -math.pi / 2, math.pi / 2, -math.pi / 2, -math.pi / 2, 0.0])

_SINGULAR_EPS = 1e-9


class IKError(ValueError):
    """No joint solution exists for the requested pose (out of reach, or outside the joint limits)."""


def _dh_transform(theta: float, d: float, a: float, alpha: float) -> np.ndarray:
    ct, st = math.cos(theta), math.sin(theta)
    ca, sa = math.cos(alpha), math.sin(alpha)
    return np.array([
        [ct, -st * ca, st * sa, a * ct],
        [st, ct * ca, -ct * sa, a * st],
        [0.0, sa, ca, d],
        [0.0, 0.0, 0.0, 1.0],
    ])


def _rigid_inverse(transform: np.ndarray) -> np.ndarray:
    inverse = np.eye(4)
    inverse[:3, :3] = transform[:3, :3].T
    inverse[:3, 3] = -transform[:3, :3].T @ transform[:3, 3]
    return inverse


def _tool_transform(tool_offset: float) -> np.ndarray:
    tool = np.eye(4)
    tool[2, 3] = tool_offset
    return tool


def forward_kinematics(q: Sequence[float], tool_offset: float = DEFAULT_TOOL_OFFSET) -> np.ndarray:
    """Pose of the TCP in the world frame (4x4 homogeneous matrix) for joint angles q [rad]."""
    q = np.asarray(q, dtype=float)
    if q.shape != (6,):
        raise ValueError(f'expected 6 joint angles, got shape {q.shape}')
    pose = np.eye(4)
    for i in range(6):
        pose = pose @ _dh_transform(q[i], DH_D[i], DH_A[i], DH_ALPHA[i])
    return pose @ _tool_transform(tool_offset)


def jacobian(q: Sequence[float], tool_offset: float = DEFAULT_TOOL_OFFSET) -> np.ndarray:
    """Geometric Jacobian (6x6) of the TCP in the world frame: rows 0-2 map joint velocities to the TCP's linear
    velocity, rows 3-5 to its angular velocity (every joint turns about the z axis of the DH frame before it)."""
    q = np.asarray(q, dtype=float)
    if q.shape != (6,):
        raise ValueError(f'expected 6 joint angles, got shape {q.shape}')
    frames = [np.eye(4)]
    for i in range(6):
        frames.append(frames[-1] @ _dh_transform(q[i], DH_D[i], DH_A[i], DH_ALPHA[i]))
    tcp = (frames[-1] @ _tool_transform(tool_offset))[:3, 3]
    result = np.zeros((6, 6))
    for i in range(6):
        axis, origin = frames[i][:3, 2], frames[i][:3, 3]
        result[:3, i] = np.cross(axis, tcp - origin)
        result[3:, i] = axis
    return result


def _wrap(angle: float) -> float:
    """Angle in (-pi, pi]."""
    return math.atan2(math.sin(angle), math.cos(angle))


def inverse_kinematics_all(pose: np.ndarray, tool_offset: float = DEFAULT_TOOL_OFFSET,
                           wrist_singular_q6: float = 0.0) -> list[np.ndarray]:
    """Every analytic solution (up to 8, each angle in (-pi, pi]) reaching `pose` with the TCP.

    Branches: shoulder left/right (theta1), wrist up/down (theta5), elbow up/down (theta3). At the wrist singularity
    (theta5 = 0) theta6 is not determined; `wrist_singular_q6` is used for it. Raises IKError when no branch exists.
    """
    pose = np.asarray(pose, dtype=float)
    if pose.shape != (4, 4):
        raise ValueError(f'expected a 4x4 pose, got shape {pose.shape}')
    d1, d4, d5, d6 = DH_D[0], DH_D[3], DH_D[4], DH_D[5]
    a2, a3 = DH_A[1], DH_A[2]
    flange = pose @ _tool_transform(-tool_offset)
    rotation = flange[:3, :3]
    x_axis, y_axis, z_axis = rotation[:, 0], rotation[:, 1], rotation[:, 2]
    # Wrist centre (origin of DH frame 5): d6 back along the flange's z axis.
    wrist = flange[:3, 3] - d6 * z_axis
    radius = math.hypot(wrist[0], wrist[1])
    if radius < d4:
        raise IKError(f'pose too close to the base axis: wrist centre {radius:.3f} m from it, '
                      f'needs at least {d4:.4f} m')
    psi = math.atan2(wrist[1], wrist[0])
    lateral = math.asin(d4 / radius)
    solutions: list[np.ndarray] = []
    elbow_reach_problems: list[str] = []
    for theta1 in (psi + lateral, psi + math.pi - lateral):
        s1, c1 = math.sin(theta1), math.cos(theta1)
        # z axis of frame 1 (the parallel axes of joints 2-4) in the world: the flange z axis' component along it
        # is cos(theta5).
        cos5 = min(1.0, max(-1.0, float(z_axis[0] * s1 - z_axis[1] * c1)))
        for sign5 in (1.0, -1.0):
            theta5 = sign5 * math.acos(cos5)
            s5 = math.sin(theta5)
            if abs(s5) < _SINGULAR_EPS:
                theta6 = wrist_singular_q6
            else:
                theta6 = math.atan2(-(y_axis[0] * s1 - y_axis[1] * c1) / s5, (x_axis[0] * s1 - x_axis[1] * c1) / s5)
            # Strip joints 1, 5 and 6 to get the planar chain of joints 2-4 in frame 1.
            t01 = _dh_transform(theta1, d1, 0.0, DH_ALPHA[0])
            t45 = _dh_transform(theta5, d5, 0.0, DH_ALPHA[4])
            t56 = _dh_transform(theta6, d6, 0.0, DH_ALPHA[5])
            t14 = _rigid_inverse(t01) @ flange @ _rigid_inverse(t45 @ t56)
            px, py = t14[0, 3], t14[1, 3]
            cos3 = (px * px + py * py - a2 * a2 - a3 * a3) / (2 * a2 * a3)
            if abs(cos3) > 1.0 + 1e-12:
                elbow_reach_problems.append(f'{math.hypot(px, py):.4f}')
                continue
            cos3 = min(1.0, max(-1.0, float(cos3)))
            for sign3 in (1.0, -1.0):
                theta3 = sign3 * math.acos(cos3)
                theta2 = math.atan2(py, px) - math.atan2(a3 * math.sin(theta3), a2 + a3 * math.cos(theta3))
                theta234 = math.atan2(t14[1, 0], t14[0, 0])
                theta4 = theta234 - theta2 - theta3
                solutions.append(np.array([_wrap(theta1), _wrap(theta2), _wrap(theta3), _wrap(theta4),
                                           _wrap(theta5), _wrap(theta6)]))
    if not solutions:
        raise IKError(
            f'pose out of reach: the elbow chain would need to span {", ".join(elbow_reach_problems)} m '
            f'but spans at most {ARM_REACH:.4f} m (TCP at {np.round(pose[:3, 3], 4).tolist()})')
    return solutions


def _nearest_within_limits(solutions: np.ndarray, seed: np.ndarray) -> np.ndarray:
    """Each solution (rows) shifted joint by joint by multiples of 2*pi to the value nearest `seed` within the limits;
    NaN where a joint cannot be within them."""
    shifted = solutions + 2 * math.pi * np.round((seed - solutions) / (2 * math.pi))
    # The nearest equivalent may lie beyond a limit; the next one toward the middle of the range is then nearest.
    shifted = np.where(shifted > JOINT_UPPER + 1e-9, shifted - 2 * math.pi, shifted)
    shifted = np.where(shifted < JOINT_LOWER - 1e-9, shifted + 2 * math.pi, shifted)
    return np.where((shifted >= JOINT_LOWER - 1e-9) & (shifted <= JOINT_UPPER + 1e-9), shifted, np.nan)


def inverse_kinematics(pose: np.ndarray, q_seed: Sequence[float] | None = None,
                       tool_offset: float = DEFAULT_TOOL_OFFSET) -> np.ndarray:
    """Joint angles [rad] placing the TCP at `pose` (4x4), the solution nearest `q_seed` within the joint limits.

    Of the 8 analytic branches, each angle is first shifted by multiples of 2*pi to its value nearest the seed within
    the limits, then the branch with the smallest joint-space distance to the seed wins. Without a seed, HOME_JOINTS
    (elbow up, wrist down over the table) is the seed. Raises IKError when the pose cannot be reached.
    """
    seed = HOME_JOINTS if q_seed is None else np.asarray(q_seed, dtype=float)
    if seed.shape != (6,):
        raise ValueError(f'expected a seed of 6 joint angles, got shape {seed.shape}')
    solutions = np.array(inverse_kinematics_all(pose, tool_offset, wrist_singular_q6=_wrap(float(seed[5]))))
    candidates = _nearest_within_limits(solutions, seed)
    distances = np.sum((candidates - seed) ** 2, axis=1)
    if np.all(np.isnan(distances)):
        raise IKError('every solution of the pose lies outside the joint limits')
    return candidates[int(np.nanargmin(distances))]


def top_down_pose(xyz: Sequence[float], yaw: float = 0.0) -> np.ndarray:
    """TCP pose at `xyz` with its z axis pointing to world -z, turned by `yaw` [rad] about world z.

    At yaw = 0 the TCP x axis is world +x (so the fingers, which close along the TCP y axis, close along world y
    in the usual gripper layout) and its y axis world -y.
    """
    c, s = math.cos(yaw), math.sin(yaw)
    pose = np.eye(4)
    # Rz(yaw) @ Rx(pi): z -> -z, y -> -y.
    pose[:3, :3] = np.array([[c, s, 0.0], [s, -c, 0.0], [0.0, 0.0, -1.0]])
    pose[:3, 3] = np.asarray(xyz, dtype=float)
    return pose


def top_down_reach_margin(xyz: Sequence[float], tool_offset: float = DEFAULT_TOOL_OFFSET) -> float:
    """Slack [m] of the elbow chain when the TCP is at `xyz` pointing straight down (any yaw).

    Positive: reachable, by this much before the arm is fully stretched; negative: out of reach by that much. The
    pose's yaw only turns the last joint, so the margin does not depend on it. The best branch (wrist 1 folded
    toward the base) is used.
    """
    x, y, z = (float(v) for v in xyz)
    d1, d4, d5, d6 = DH_D[0], DH_D[3], DH_D[4], DH_D[5]
    radius = math.hypot(x, y)
    if radius < d4:
        return -(d4 - radius)
    # Wrist-1 axis centre: above the TCP by tool_offset + d6, then d5 back toward the base in the arm's plane.
    in_plane = math.sqrt(radius * radius - d4 * d4) - d5
    height = z + tool_offset + d6 - d1
    return ARM_REACH - math.hypot(in_plane, height)


def is_reachable_top_down(xyz: Sequence[float], yaw: float = 0.0, tool_offset: float = DEFAULT_TOOL_OFFSET) -> bool:
    """True when the TCP can be at `xyz` pointing straight down with this yaw (joint limits included)."""
    try:
        inverse_kinematics(top_down_pose(xyz, yaw), tool_offset=tool_offset)
    except IKError:
        return False
    return True


def pose_error(expected: np.ndarray, actual: np.ndarray) -> tuple[float, float]:
    """(position error [m], rotation error [rad]) between two 4x4 poses."""
    position_error = float(np.linalg.norm(expected[:3, 3] - actual[:3, 3]))
    relative = expected[:3, :3].T @ actual[:3, :3]
    cos_angle = float(np.clip((np.trace(relative) - 1.0) / 2.0, -1.0, 1.0))
    return position_error, math.acos(cos_angle)


def joint_distance(a: Iterable[float], b: Iterable[float]) -> float:
    """Largest absolute joint difference [rad]."""
    return float(np.max(np.abs(np.asarray(list(a), dtype=float) - np.asarray(list(b), dtype=float))))
