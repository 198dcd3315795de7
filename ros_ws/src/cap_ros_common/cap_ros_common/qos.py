"""Quality-of-service profiles that several nodes share: the one place they are written."""
from __future__ import annotations

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

# A message that stands until the next one (a map, a description, the scene's objects): the latest is kept for late
# subscribers and delivered for sure.
LATCHED_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)

# /tf and /tf_static as tf2's broadcasters and listeners use them: /tf reliable with a deep queue (many transforms a
# second from several publishers), /tf_static latched so a listener that starts later still gets every fixed frame.
# Each static broadcaster keeps its last message (depth 1); a listener keeps many (depth 100), one per broadcaster:
# with one, the latched messages of several broadcasters arriving together replaced each other.
TF_QOS = QoSProfile(depth=100, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE)
TF_STATIC_QOS = LATCHED_QOS
TF_STATIC_LISTENER_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                                    durability=DurabilityPolicy.TRANSIENT_LOCAL)

__all__ = ['LATCHED_QOS', 'TF_QOS', 'TF_STATIC_LISTENER_QOS', 'TF_STATIC_QOS']
