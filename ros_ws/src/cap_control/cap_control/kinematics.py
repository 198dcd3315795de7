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


def _wrap_array(angles: np.ndarray) -> np.ndarray:
    return np.arctan2(np.sin(angles), np.cos(angles))


BRANCHES = np.arange(8)  # shoulder (theta1) x wrist (theta5 sign) x elbow (theta3 sign), in this nesting order


def _choose(flag: np.ndarray | int, when_set: np.ndarray | float, otherwise: np.ndarray | float) -> np.ndarray:
    """`when_set` where the branch flag is 1, else `otherwise`: elementwise for an array of branches."""
    if isinstance(flag, int):
        return when_set if flag else otherwise
    return np.where(flag == 1, when_set, otherwise)


def _branches(rotation: np.ndarray, position: np.ndarray, branch: np.ndarray | int,
              wrist_singular_q6: np.ndarray | float = 0.0) -> dict[str, np.ndarray]:
    """Analytic IK of the flange poses (`rotation` (3, 3, ...), `position` (3, ...): components first, so that each
    is one contiguous array over the poses) on `branch` (0-7, an int or an array broadcast against the poses),
    elementwise over them; NumPy throughout, so that a whole path is solved in one pass.

    Returns the joints `q` (6, ...) (joint first; not wrapped; NaN where the branch does not exist), `radius` (wrist
    centre to the base axis), `x14`, `y14` (what the elbow chain would need to span), `singular` (theta5 = 0, where
    `wrist_singular_q6` is used for theta6) and `separation`: a lower bound on the joint distance from this branch's
    solution to every other branch's (each other branch differs in theta1, else theta5, else theta3, by at least this
    much, whatever multiple of 2*pi is added), which tells when the nearest branch to a seed cannot be another one.

    The planar chain of joints 2-4 is frame 1's view of frame 4: inv(T01) @ flange @ inv(T45 @ T56), written out
    (alpha1 = pi/2, alpha5 = -pi/2, a1 = a5 = a6 = 0). Sines and cosines of the joints come from the geometry
    (sin(acos(c)) = sqrt(1 - c^2), ...) rather than from the angles: fewer transcendental functions per pose.
    """
    d1, d4, d5, d6 = DH_D[0], DH_D[3], DH_D[4], DH_D[5]
    a2, a3 = DH_A[1], DH_A[2]
    r = np.asarray(rotation, dtype=float)
    p = np.asarray(position, dtype=float)
    if not isinstance(branch, int):
        branch = np.asarray(branch)
    shoulder, wrist_down, elbow_down = (branch >> 2) & 1, (branch >> 1) & 1, branch & 1
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = r
    px, py, pz = p
    # Wrist centre (origin of DH frame 5): d6 back along the flange's z axis.
    wx, wy = px - d6 * r02, py - d6 * r12
    radius = np.sqrt(wx * wx + wy * wy)
    near_axis = radius < d4
    safe_radius = np.maximum(radius, d4)
    sin_lateral = d4 / safe_radius
    cos_lateral = np.sqrt(1.0 - sin_lateral * sin_lateral)
    lateral = np.arcsin(sin_lateral)
    # theta1 = psi + lateral (shoulder 0) or psi + pi - lateral (shoulder 1), psi the wrist centre's bearing.
    cos_psi, sin_psi = wx / safe_radius, wy / safe_radius
    cos_turn = _choose(shoulder, -cos_lateral, cos_lateral)
    theta1 = np.arctan2(wy, wx) + _choose(shoulder, math.pi - lateral, lateral)
    c1 = cos_psi * cos_turn - sin_psi * sin_lateral
    s1 = sin_psi * cos_turn + cos_psi * sin_lateral
    # The flange z axis' component along frame 1's z axis (the parallel axes of joints 2-4) is cos(theta5).
    c5 = np.clip(r02 * s1 - r12 * c1, -1.0, 1.0)
    wrist_angle = np.arccos(c5)
    s5 = np.sqrt(1.0 - c5 * c5)
    theta5, s5 = _choose(wrist_down, -wrist_angle, wrist_angle), _choose(wrist_down, -s5, s5)
    singular = s5 * s5 < _SINGULAR_EPS * _SINGULAR_EPS
    s5_safe = np.where(singular, 1.0, s5)
    x6, y6 = (r00 * s1 - r10 * c1) / s5_safe, -(r01 * s1 - r11 * c1) / s5_safe
    theta6 = np.where(singular, wrist_singular_q6, np.arctan2(y6, x6))
    norm6 = np.where(singular, 1.0, np.sqrt(x6 * x6 + y6 * y6))
    norm6 = np.where(norm6 > 0.0, norm6, 1.0)  # 0 only off the arm's reach (too near the base axis)
    c6 = np.where(singular, np.cos(wrist_singular_q6), x6 / norm6)
    s6 = np.where(singular, np.sin(wrist_singular_q6), y6 / norm6)
    # Column 0 of inv(T46) is (c5 c6, -c5 s6, -s5), its translation (d5 s6, d5 c6, -d6).
    u0, u1, u2 = c5 * c6, -c5 * s6, -s5
    v0, v1 = d5 * s6, d5 * c6
    g0x, g0y, g0z = r00 * u0 + r01 * u1 + r02 * u2, r10 * u0 + r11 * u1 + r12 * u2, r20 * u0 + r21 * u1 + r22 * u2
    g3x = r00 * v0 + r01 * v1 - d6 * r02 + px
    g3y = r10 * v0 + r11 * v1 - d6 * r12 + py
    g3z = r20 * v0 + r21 * v1 - d6 * r22 + pz
    # inv(T01) maps (x, y, z) to (c1 x + s1 y, z - d1, ...).
    x14, y14 = c1 * g3x + s1 * g3y, g3z - d1
    cos3 = (x14 * x14 + y14 * y14 - a2 * a2 - a3 * a3) / (2 * a2 * a3)
    reached = (np.abs(cos3) <= 1.0 + 1e-12) & ~near_axis
    c3 = np.clip(cos3, -1.0, 1.0)
    elbow_angle = np.arccos(c3)
    s3 = np.sqrt(1.0 - c3 * c3)
    theta3, s3 = _choose(elbow_down, -elbow_angle, elbow_angle), _choose(elbow_down, -s3, s3)
    theta2 = np.arctan2(y14, x14) - np.arctan2(a3 * s3, a2 + a3 * c3)
    theta4 = np.arctan2(g0z, c1 * g0x + s1 * g0y) - theta2 - theta3
    q = np.stack(np.broadcast_arrays(theta1, theta2, theta3, theta4, theta5, theta6))
    q[:, ~np.broadcast_to(reached, q.shape[1:])] = np.nan
    # Differences of the other branches: pi - 2 lateral (theta1), 2 theta5 and 2 theta3, each taken modulo 2 pi.
    separation = np.minimum(np.minimum(math.pi - 2 * lateral, math.pi - np.abs(math.pi - 2 * wrist_angle)),
                            math.pi - np.abs(math.pi - 2 * elbow_angle))
    return {'q': q, 'radius': radius, 'x14': x14, 'y14': y14, 'singular': singular, 'separation': separation}


def _flange(pose: np.ndarray, tool_offset: float) -> tuple[np.ndarray, np.ndarray]:
    """(rotation (..., 3, 3), position (..., 3)) of the flange that puts the TCP at `pose` (..., 4, 4)."""
    rotation = pose[..., :3, :3]
    return rotation, pose[..., :3, 3] - tool_offset * rotation[..., :, 2]


def _all_branches(pose: np.ndarray, tool_offset: float, wrist_singular_q6: float) -> np.ndarray:
    """The 8 branches' solutions (8, 6) at one pose, NaN where a branch does not exist; IKError when none does."""
    rotation, position = _flange(pose, tool_offset)
    solved = _branches(rotation, position, BRANCHES, wrist_singular_q6)
    radius = float(solved['radius'])
    if radius < DH_D[3]:
        raise IKError(f'pose too close to the base axis: wrist centre {radius:.3f} m from it, '
                      f'needs at least {DH_D[3]:.4f} m')
    solutions = solved['q'].T
    if np.all(np.isnan(solutions)):
        spans = ', '.join(f'{span:.4f}' for span in np.hypot(solved['x14'], solved['y14'])[::2])
        raise IKError(f'pose out of reach: the elbow chain would need to span {spans} m but spans at most '
                      f'{ARM_REACH:.4f} m (TCP at {np.round(pose[:3, 3], 4).tolist()})')
    return solutions


def inverse_kinematics_all(pose: np.ndarray, tool_offset: float = DEFAULT_TOOL_OFFSET,
                           wrist_singular_q6: float = 0.0) -> list[np.ndarray]:
    """Every analytic solution (up to 8, each angle in (-pi, pi]) reaching `pose` with the TCP.

    Branches: shoulder left/right (theta1), wrist up/down (theta5), elbow up/down (theta3). At the wrist singularity
    (theta5 = 0) theta6 is not determined; `wrist_singular_q6` is used for it. Raises IKError when no branch exists.
    """
    pose = np.asarray(pose, dtype=float)
    if pose.shape != (4, 4):
        raise ValueError(f'expected a 4x4 pose, got shape {pose.shape}')
    solutions = _all_branches(pose, tool_offset, wrist_singular_q6)
    return [_wrap_array(q) for q in solutions if not np.isnan(q[0])]


def _nearest_within_limits(solutions: np.ndarray, seed: np.ndarray) -> np.ndarray:
    """Each solution (rows) shifted joint by joint by multiples of 2*pi to the value nearest `seed` within the limits;
    NaN where a joint cannot be within them."""
    shifted = solutions + 2 * math.pi * np.round((seed - solutions) / (2 * math.pi))
    # The nearest equivalent may lie beyond a limit; the next one toward the middle of the range is then nearest.
    shifted = np.where(shifted > JOINT_UPPER + 1e-9, shifted - 2 * math.pi, shifted)
    shifted = np.where(shifted < JOINT_LOWER - 1e-9, shifted + 2 * math.pi, shifted)
    return np.where((shifted >= JOINT_LOWER - 1e-9) & (shifted <= JOINT_UPPER + 1e-9), shifted, np.nan)


def _nearest_branch(pose: np.ndarray, seed: np.ndarray, tool_offset: float) -> tuple[np.ndarray, int]:
    """The solution nearest `seed` within the joint limits, and its branch; IKError when there is none."""
    candidates = _nearest_within_limits(_all_branches(pose, tool_offset, _wrap(float(seed[5]))), seed)
    distances = np.sum((candidates - seed) ** 2, axis=1)
    if np.all(np.isnan(distances)):
        raise IKError('every solution of the pose lies outside the joint limits')
    branch = int(np.nanargmin(distances))
    return candidates[branch], branch


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
    pose = np.asarray(pose, dtype=float)
    if pose.shape != (4, 4):
        raise ValueError(f'expected a 4x4 pose, got shape {pose.shape}')
    return _nearest_branch(pose, seed, tool_offset)[0]


# Samples a path's branch is followed over at once (`inverse_kinematics_path`); after a sample that needs the full
# search, the window starts small and doubles, so that a stretch near a singularity costs little more than before.
_PATH_WINDOW = 16384


def inverse_kinematics_path(poses: np.ndarray, q_seed: Sequence[float],
                            tool_offset: float = DEFAULT_TOOL_OFFSET) -> tuple[np.ndarray, IKError | None]:
    """Joint angles along a path of TCP poses (N, 4, 4), each the solution nearest the previous one (the first, the
    one nearest `q_seed`): what `inverse_kinematics` called pose after pose, seeded each time with the last
    solution, gives. Returns the solutions (M, 6) up to the first pose that cannot be reached (a transposed view of
    a (6, M) array: `.T` gives each joint's angles contiguous), and the IKError of that pose (M its index), or None
    when every pose is reached.

    Solved in NumPy passes: the branch of the last solution is followed over a window of poses, each angle moved by
    the multiple of 2*pi nearest the previous one, as long as that branch is provably the nearest (its step is less
    than half its separation from every other branch, see `_branches`), within the limits and away from the wrist
    singularity; where not, that one pose gets the full search of `inverse_kinematics`.
    """
    poses = np.asarray(poses, dtype=float)
    count = len(poses)
    rotations, positions = _flange(poses, tool_offset)
    positions = np.ascontiguousarray(positions.T)
    # Components first, contiguous; one rotation for all when it does not change (drawing, straight lines).
    constant = count > 0 and bool(np.all(rotations == rotations[0]))
    rotations = rotations[0] if constant else np.ascontiguousarray(np.moveaxis(rotations, 0, -1))
    solutions = np.empty((6, count))  # joint first: each joint's angles contiguous
    previous = np.asarray(q_seed, dtype=float)
    lower, upper = JOINT_LOWER[:, None] - 1e-9, JOINT_UPPER[:, None] + 1e-9
    done, branch, window = 0, None, 16
    while done < count:
        if branch is None:  # the full search, as inverse_kinematics does it
            try:
                previous, branch = _nearest_branch(poses[done], previous, tool_offset)
            except IKError as error:
                return solutions[:, :done].T, error
            solutions[:, done] = previous
            done += 1
            continue
        end = min(count, done + window)
        solved = _branches(rotations if constant else rotations[..., done:end], positions[:, done:end], branch)
        candidates = solved['q']  # (6, n): joint first, each row contiguous
        # Each angle moved by the multiple of 2 pi that puts it nearest the one before.
        turns = np.empty_like(candidates)
        np.subtract(previous, candidates[:, 0], out=turns[:, 0])
        np.subtract(candidates[:, :-1], candidates[:, 1:], out=turns[:, 1:])
        turns = np.round(turns * (1 / (2 * math.pi)))
        if np.any(turns[:, 1:]):
            chained = candidates + (2 * math.pi) * np.cumsum(turns, axis=1)
        else:  # the usual case: one multiple of 2 pi for the whole window
            chained = candidates + (2 * math.pi) * turns[:, :1]
        steps = np.empty_like(chained)
        np.subtract(chained[:, 0], previous, out=steps[:, 0])
        np.subtract(chained[:, 1:], chained[:, :-1], out=steps[:, 1:])
        good = ((solved['separation'] > 2 * np.sqrt(np.einsum('ij,ij->j', steps, steps)) + 1e-9)
                & ~solved['singular'] & np.all((chained >= lower) & (chained <= upper), axis=0))
        accepted = int(np.argmin(good)) if not np.all(good) else end - done  # NaN columns are not good
        solutions[:, done:done + accepted] = chained[:, :accepted]
        if accepted:
            previous = chained[:, accepted - 1]
        done += accepted
        if done < end:
            branch, window = None, 16
        else:
            window = min(2 * window, _PATH_WINDOW)
    return solutions.T, None


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
