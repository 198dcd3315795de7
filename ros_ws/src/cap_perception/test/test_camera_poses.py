"""Which camera pose a frame is analysed with: the tf lookup perception makes (world <- the images' frame at their
stamp), for a camera the robot carries and for one on a fixed mount."""
import numpy as np
import pytest

from cap_ros_common.transforms import Transform, TransformBuffer, TransformError

IDENTITY = (0.0, 0.0, 0.0, 1.0)


def test_a_moving_cameras_frame_gets_the_pose_of_its_own_stamp_or_none_yet():
    buffer = TransformBuffer(history_s=0.25)
    buffer.add([Transform('base_link', 'head_optical_frame', 0.0, (0.1, 0, 1.0), IDENTITY)], static=True)
    for stamp in (0.1, 0.2, 0.3):
        buffer.add([Transform('world', 'base_link', stamp, (stamp, 0, 0), IDENTITY)])
    assert buffer.lookup('world', 'head_optical_frame', 0.2)[0, 3] == pytest.approx(0.3)  # not the latest
    with pytest.raises(TransformError):
        buffer.lookup('world', 'head_optical_frame', 0.4)  # its pose has not come yet
    buffer.add([Transform('world', 'base_link', 0.4, (0.4, 0, 0), IDENTITY)])
    assert buffer.lookup('world', 'head_optical_frame', 0.4)[0, 3] == pytest.approx(0.5)
    with pytest.raises(TransformError):
        buffer.lookup('world', 'head_optical_frame', 0.1)  # only the recent history is kept


def test_a_fixed_cameras_frames_get_its_latest_pose():
    buffer = TransformBuffer()
    with pytest.raises(TransformError):
        buffer.lookup('world', 'top_optical_frame', 5.0)
    buffer.add([Transform('world', 'top_optical_frame', 0.0, (1.0, 0, 0), IDENTITY)], static=True)
    assert buffer.lookup('world', 'top_optical_frame', 5.0)[0, 3] == 1.0
    buffer.add([Transform('world', 'top_optical_frame', 10.0, (2.0, 0, 0), IDENTITY)], static=True)  # recalibrated
    assert np.allclose(buffer.lookup('world', 'top_optical_frame', 7.0)[:3, 3], (2.0, 0, 0))
