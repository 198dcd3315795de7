"""The transform buffer answers as tf2 would: chains through the common ancestor, interpolates between samples,
refuses to extrapolate, and says which frame is missing."""
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from cap_ros_common.transforms import Transform, TransformBuffer, TransformError, pose_matrix, translation_rotation


def _yaw(angle: float) -> tuple[float, float, float, float]:
    return tuple(Rotation.from_euler('z', angle).as_quat())


IDENTITY = (0.0, 0.0, 0.0, 1.0)


@pytest.fixture
def buffer():
    """world -> map -> odom -> base_link (moving) -> camera; world -> table."""
    buffer = TransformBuffer()
    buffer.add([Transform('world', 'map', 0.0, (0, 0, 0), IDENTITY),
                Transform('map', 'odom', 0.0, (1.0, 0, 0), IDENTITY),
                Transform('base_link', 'camera', 0.0, (0.1, 0, 0.5), _yaw(math.pi / 2)),
                Transform('world', 'table', 0.0, (0, -0.5, 0), IDENTITY)], static=True)
    buffer.add([Transform('odom', 'base_link', 1.0, (0, 0, 0), IDENTITY),
                Transform('odom', 'base_link', 2.0, (2.0, 0, 0), _yaw(math.pi / 2))])
    return buffer


def test_a_chain_is_walked_through_the_common_ancestor(buffer):
    pose = buffer.lookup('table', 'camera', 1.0)  # the camera in the table's frame
    assert np.allclose(pose[:3, 3], [1.1, 0.5, 0.5])
    point_in_camera = np.array([1.0, 0.0, 0.0, 1.0])  # 1 m along the camera's x, which points along world +y
    assert np.allclose((buffer.lookup('world', 'camera', 1.0) @ point_in_camera)[:3], [1.1, 1.0, 0.5])


def test_between_two_samples_the_pose_is_interpolated(buffer):
    pose = buffer.lookup('odom', 'base_link', 1.5)
    assert np.allclose(pose[:3, 3], [1.0, 0, 0])
    assert math.isclose(Rotation.from_matrix(pose[:3, :3]).as_euler('xyz')[2], math.pi / 4, abs_tol=1e-9)


def test_a_stamp_outside_the_samples_is_refused_and_none_takes_the_latest(buffer):
    with pytest.raises(TransformError, match='odom -> base_link is known from 1.000 s to 2.000 s, not at 2.500 s'):
        buffer.lookup('world', 'camera', 2.5)
    assert np.allclose(buffer.lookup('map', 'base_link')[:3, 3], [3.0, 0, 0])
    assert buffer.latest_stamp('world', 'camera') == 2.0
    assert buffer.latest_stamp('world', 'table') is None  # static all the way


def test_unknown_and_unconnected_frames_are_named(buffer):
    with pytest.raises(TransformError, match="no transform names the frame 'moon'"):
        buffer.lookup('world', 'moon')
    buffer.add([Transform('island', 'rock', 0.0, (0, 0, 0), IDENTITY)], static=True)
    with pytest.raises(TransformError, match="'rock' and 'world' are not connected"):
        buffer.lookup('world', 'rock')
    assert not buffer.can_transform('world', 'rock') and buffer.can_transform('table', 'map')


def test_old_samples_leave_the_history():
    buffer = TransformBuffer(history_s=1.0)
    for stamp in np.arange(0.0, 3.01, 0.5):
        buffer.add([Transform('a', 'b', float(stamp), (float(stamp), 0, 0), IDENTITY)])
    with pytest.raises(TransformError, match='known from 2.000 s'):
        buffer.lookup('a', 'b', 1.0)
    assert np.allclose(buffer.lookup('a', 'b', 2.25)[:3, 3], [2.25, 0, 0])


def test_pose_matrix_round_trips_and_refuses_a_zero_quaternion():
    matrix = pose_matrix((1, 2, 3), _yaw(0.3))
    translation, rotation = translation_rotation(matrix)
    assert np.allclose(translation, (1, 2, 3)) and np.allclose(pose_matrix(translation, rotation), matrix)
    with pytest.raises(ValueError):
        pose_matrix((0, 0, 0), (0, 0, 0, 0))
    with pytest.raises(ValueError):
        pose_matrix((math.nan, 0, 0), IDENTITY)
