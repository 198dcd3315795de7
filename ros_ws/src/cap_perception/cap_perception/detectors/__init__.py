"""The RGB-D detectors perception can run, one per domain, by name (the `detector` parameter of perception_node).

A detector is a function `detect(view: CameraView) -> list[PerceivedObject]` (cap_perception.rgbd.CameraView: one
RGB-D frame with its intrinsics and the camera's pose in the world frame; objects in the world frame, sorted by
name). It is named after its domain and offered as an entry point of the group `cap_ros.detectors` (value: the
function): this package's setup.py offers every module of this folder (`detectors/<domain>.py` defining DETECTOR),
another package adds a line to its own setup.py. No ROS here.
"""
from __future__ import annotations

from typing import Callable

from cap_ros_common.plugins import PluginGroup

from cap_perception.objects import PerceivedObject
from cap_perception.rgbd import CameraView

Detector = Callable[[CameraView], list[PerceivedObject]]
ENTRY_POINT_GROUP = 'cap_ros.detectors'
_detectors: PluginGroup[Detector] = PluginGroup(ENTRY_POINT_GROUP, 'detector', callable)


def get_detector(name: str) -> Detector:
    """The detector of domain `name`; ValueError naming the known detectors otherwise."""
    return _detectors.get(name)


def detector_names() -> list[str]:
    """Every detector offered, by name."""
    return _detectors.names()


__all__ = ['Detector', 'ENTRY_POINT_GROUP', 'detector_names', 'get_detector']
