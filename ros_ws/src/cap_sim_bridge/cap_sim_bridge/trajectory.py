"""Timed joint trajectories, sampled as the simulation clock advances (pure NumPy)."""
from __future__ import annotations

import numpy as np


class JointTrajectory:
    """Waypoints at absolute times; sample(t) gives the reference position and velocity at time t.

    Segments are cubic Hermite splines through the waypoints with their velocities. Without given velocities
    (positions only) the velocities are estimated: zero at both ends, the mean of the neighbouring segments'
    slopes at an interior waypoint, and zero where the motion turns back, so the arm starts and stops smoothly
    and never overshoots a waypoint. Before the first time the first point is held; after the last, the last
    point is held with zero velocity.
    """

    def __init__(self, times: np.ndarray, positions: np.ndarray, velocities: np.ndarray | None = None) -> None:
        self.times = np.asarray(times, dtype=float)
        self.positions = np.asarray(positions, dtype=float)
        self.velocities = None if velocities is None else np.asarray(velocities, dtype=float)
        if self.times.ndim != 1 or self.positions.ndim != 2 or len(self.times) != len(self.positions):
            raise ValueError('times must be (N,) and positions (N, joints)')
        if len(self.times) == 0:
            raise ValueError('a trajectory needs at least one point')
        if np.any(np.diff(self.times) <= 0):
            raise ValueError('trajectory times must increase strictly')
        if self.velocities is None:
            self.velocities = _estimated_velocities(self.times, self.positions)
        elif self.velocities.shape != self.positions.shape:
            raise ValueError('velocities must have the shape of positions')

    @property
    def start_time(self) -> float:
        return float(self.times[0])

    @property
    def end_time(self) -> float:
        return float(self.times[-1])

    @property
    def final_positions(self) -> np.ndarray:
        return self.positions[-1].copy()

    def sample(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """(position, velocity) references at time t."""
        positions, velocities, _ = self.sample_many(np.array([t]))
        return positions[0], velocities[0]

    def sample_acceleration(self, t: float) -> np.ndarray:
        """The reference acceleration at time t (the second derivative of the segment's spline; zero outside)."""
        return self.sample_many(np.array([t]))[2][0]

    def sample_many(self, ts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(positions, velocities, accelerations), each (len(ts), joints), at the times ts, computed for all of them
        at once (the physics loop samples every step of a chunk of steps; per step, the NumPy calls on six-vectors
        cost more than the physics step). Cubic Hermite basis on s in [0, 1] within each segment, the velocities
        scaled by the segment's duration."""
        ts = np.asarray(ts, dtype=float)
        times, joints = self.times, self.positions.shape[1]
        inside = (ts > times[0]) & (ts < times[-1])
        positions = np.where((ts >= times[-1])[:, None], self.positions[-1], self.positions[0])
        velocities = np.zeros((len(ts), joints))
        accelerations = np.zeros((len(ts), joints))
        if not inside.any():
            return positions, velocities, accelerations
        t = ts[inside]
        i = np.searchsorted(times, t, side='right') - 1
        duration = (times[i + 1] - times[i])[:, None]
        s = (t - times[i])[:, None]
        s = s / duration
        p0, p1 = self.positions[i], self.positions[i + 1]
        v0, v1 = self.velocities[i] * duration, self.velocities[i + 1] * duration
        s2, s3 = s * s, s * s * s
        positions[inside] = ((2 * s3 - 3 * s2 + 1) * p0 + (s3 - 2 * s2 + s) * v0 + (-2 * s3 + 3 * s2) * p1
                             + (s3 - s2) * v1)
        velocities[inside] = ((6 * s2 - 6 * s) * p0 + (3 * s2 - 4 * s + 1) * v0 + (-6 * s2 + 6 * s) * p1
                              + (3 * s2 - 2 * s) * v1) / duration
        accelerations[inside] = ((12 * s - 6) * p0 + (6 * s - 4) * v0 + (6 - 12 * s) * p1
                                 + (6 * s - 2) * v1) / (duration * duration)
        return positions, velocities, accelerations


def _estimated_velocities(times: np.ndarray, positions: np.ndarray) -> np.ndarray:
    velocities = np.zeros_like(positions)
    if len(times) > 2:
        slopes = np.diff(positions, axis=0) / np.diff(times)[:, None]
        before, after = slopes[:-1], slopes[1:]
        velocities[1:-1] = np.where(before * after > 0, (before + after) / 2, 0.0)
    return velocities
