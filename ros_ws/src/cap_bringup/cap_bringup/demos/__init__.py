"""The demos: one module per domain (tabletop.py, whiteboard.py, mobile.py, controllers.py), each a sequence of
plain-language commands run through the whole graph in simulation and checked on the simulator's state.

A demo is a plug-in of the entry-point group `cap_ros.demos` (name: its domain's name, value: its
`main(argv) -> int`), read through cap_ros_common.plugins like the domains and scenes. This package's setup.py offers
every module of this folder whose name does not start with an underscore; the modules that do (`_support.py`, the
mobile demo's `_mobile_map.py`) hold what demos share or use, never a demo. Another package offers a demo with a
line in its own setup.py::

    entry_points={'cap_ros.demos': ['greenhouse = greenhouse_demo:main']}

and `cap demo greenhouse [options]` runs it. No demo imports another.
"""
from __future__ import annotations

from typing import Callable, Sequence

from cap_ros_common.plugins import PluginGroup

ENTRY_POINT_GROUP = 'cap_ros.demos'
DEFAULT_DEMO = 'tabletop'  # what `cap demo` runs without a name

DemoMain = Callable[[Sequence[str]], int]  # argv (the demo's options) -> exit code
DEMOS: PluginGroup[DemoMain] = PluginGroup(ENTRY_POINT_GROUP, 'demo', callable)

__all__ = ['DEFAULT_DEMO', 'DEMOS', 'DemoMain', 'ENTRY_POINT_GROUP']
