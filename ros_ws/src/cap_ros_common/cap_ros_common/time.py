"""Conversions between seconds (float) and ROS time messages: the one place they are written."""
from __future__ import annotations

import math

from builtin_interfaces.msg import Duration, Time

_NS = 1_000_000_000


def _split(seconds: float) -> tuple[int, int]:
    whole = math.floor(seconds)
    nanoseconds = int(round((seconds - whole) * _NS))
    if nanoseconds >= _NS:  # rounding up to the next second
        whole, nanoseconds = whole + 1, nanoseconds - _NS
    return int(whole), nanoseconds


def time_msg(seconds: float) -> Time:
    """builtin_interfaces/Time of `seconds` since the epoch (or since the simulator started)."""
    sec, nanosec = _split(seconds)
    return Time(sec=sec, nanosec=nanosec)


def duration_msg(seconds: float) -> Duration:
    """builtin_interfaces/Duration of `seconds` (non-negative)."""
    sec, nanosec = _split(max(0.0, seconds))
    return Duration(sec=sec, nanosec=nanosec)


def to_seconds(stamp: Time | Duration) -> float:
    """Seconds of a Time or Duration message."""
    return stamp.sec + stamp.nanosec / _NS
