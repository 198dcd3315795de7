import numpy as np

from cap_perception.camera_poses import CameraPoses


def _pose(x: float) -> np.ndarray:
    pose = np.eye(4)
    pose[0, 3] = x
    return pose


def test_a_moving_cameras_frame_gets_the_pose_of_its_own_stamp_or_none_yet():
    poses = CameraPoses(moving=True, keep=3)
    for stamp in (100, 200, 300):
        poses.add(stamp, _pose(stamp))
    assert poses.at(200)[0, 3] == 200  # not the latest, 300
    assert poses.at(400) is None  # its pose has not come yet
    poses.add(400, _pose(400))
    assert poses.at(400)[0, 3] == 400
    assert poses.at(100) is None  # only the latest few are kept


def test_a_fixed_cameras_frames_get_its_latest_pose():
    poses = CameraPoses(moving=False)
    assert poses.at(5) is None
    poses.add(0, _pose(1.0))
    assert poses.at(5)[0, 3] == 1.0
    poses.add(10, _pose(2.0))  # sent again after a reset
    assert poses.at(7)[0, 3] == 2.0
