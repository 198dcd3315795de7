"""Quality-of-service profiles that several nodes share: the one place they are written."""
from __future__ import annotations

from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

# A message that stands until the next one (a map, a description, the scene's objects): the latest is kept for late
# subscribers and delivered for sure.
LATCHED_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)

__all__ = ['LATCHED_QOS']
