"""The simulated mobile base: three joints (x, y, yaw) on position servos, driven like the arm by timed references.

A model with the joints base_x, base_y and base_yaw (and position actuators of the same names) has a base; the
world steps it (`MobileBase.update` before each physics step while a trajectory runs). Its pose is the joints'
values: x, y [m] and yaw [rad] in the world frame (yaw is not wrapped: it counts whole turns). A trajectory is given
in those joints, so a turn of more than pi is one the caller means. No ROS here; the world's lock guards every call.
"""
from __future__ import annotations

from typing import Sequence

import mujoco
import numpy as np
from cap_mobile.robot import BASE_JOINT_NAMES

from cap_sim_bridge.trajectory import JointTrajectory


class MobileBase:
    joint_names = BASE_JOINT_NAMES

    def __init__(self, model: mujoco.MjModel, command_serial: int = 0) -> None:
        """command_serial: where the count of commands starts (a world that recompiles its model carries it over,
        so that a follower of the old base never takes a new trajectory for its own)."""
        ids = [model.joint(name).id for name in BASE_JOINT_NAMES]
        self._qpos_adr = model.jnt_qposadr[ids]
        self._dof_adr = model.jnt_dofadr[ids]
        self._actuator_ids = np.array([model.actuator(name).id for name in BASE_JOINT_NAMES])
        bias = model.actuator_biasprm[self._actuator_ids]
        # Velocity feed-forward through the position servos, as for the arm: ctrl = q_ref + (kv / kp) qdot_ref.
        self._feedforward = bias[:, 2] / bias[:, 1]
        self._trajectory: JointTrajectory | None = None
        self._hold = np.zeros(len(BASE_JOINT_NAMES))
        self.command_serial = command_serial  # counts trajectories and holds: a change tells a follower it was replaced

    @staticmethod
    def in_model(model: mujoco.MjModel) -> bool:
        return all(mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name) >= 0 for name in BASE_JOINT_NAMES)

    @property
    def moving(self) -> bool:
        """Whether a trajectory is running (the references change every step)."""
        return self._trajectory is not None

    @property
    def end_time(self) -> float | None:
        return None if self._trajectory is None else self._trajectory.end_time

    def positions(self, data: mujoco.MjData) -> np.ndarray:
        """(x, y, yaw) now."""
        return data.qpos[self._qpos_adr].copy()

    def set_positions(self, data: mujoco.MjData, pose: Sequence[float]) -> None:
        """Put the joints at (x, y, yaw) directly (the caller recomputes the kinematics; the servos are not told)."""
        data.qpos[self._qpos_adr] = np.asarray(pose, dtype=float)[:3]

    def velocities(self, data: mujoco.MjData) -> np.ndarray:
        """(x', y', yaw') now, in the world frame."""
        return data.qvel[self._dof_adr].copy()

    def reference(self, time: float) -> tuple[np.ndarray, np.ndarray]:
        """The servos' reference (position, velocity) at `time`."""
        if self._trajectory is None:
            return self._hold.copy(), np.zeros(len(BASE_JOINT_NAMES))
        return self._trajectory.sample(time)

    def hold_here(self, data: mujoco.MjData) -> None:
        """Stop any trajectory and hold the pose the base has now (a reset, a cancel, a stop)."""
        self._trajectory = None
        self.command_serial += 1
        self._hold = self.positions(data)
        data.ctrl[self._actuator_ids] = self._hold

    def follow(self, now: float, times: np.ndarray, positions: np.ndarray,
               velocities: np.ndarray | None = None) -> float:
        """Track (times [s from now], positions (N, 3), velocities (N, 3) or None); returns the end time. When
        times[0] > 0 the trajectory starts from the current reference (continuous when replacing one)."""
        times = np.asarray(times, dtype=float)
        positions = np.asarray(positions, dtype=float)
        if positions.ndim != 2 or positions.shape[1] != len(BASE_JOINT_NAMES):
            raise ValueError(f'positions must have shape (N, {len(BASE_JOINT_NAMES)})')
        if times.ndim != 1 or len(times) == 0 or times[0] < 0:
            raise ValueError('times must be a non-empty sequence of seconds from now, >= 0')
        if not (np.all(np.isfinite(positions)) and np.all(np.isfinite(times))):
            raise ValueError('the trajectory has values that are not finite')
        velocities = None if velocities is None else np.asarray(velocities, dtype=float)
        if times[0] > 0:
            position, velocity = self.reference(now)
            times = np.concatenate([[0.0], times])
            positions = np.vstack([position, positions])
            if velocities is not None:
                velocities = np.vstack([velocity, velocities])
        self._trajectory = JointTrajectory(now + times, positions, velocities)
        self.command_serial += 1
        return self._trajectory.end_time

    def references_for(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """The running trajectory's (positions, velocities) at each of `times` (a chunk of steps), None if idle."""
        if self._trajectory is None:
            return None
        positions, velocities, _ = self._trajectory.sample_many(times)
        return positions, velocities

    def update(self, data: mujoco.MjData, position: np.ndarray, velocity: np.ndarray) -> None:
        """Set the servos for the next step from the reference then; the trajectory ends at its end time."""
        data.ctrl[self._actuator_ids] = position + self._feedforward * velocity
        if data.time >= self._trajectory.end_time:
            self._hold = self._trajectory.positions[-1].copy()
            self._trajectory = None
            data.ctrl[self._actuator_ids] = self._hold
