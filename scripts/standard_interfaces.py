"""Prints the standard interface packages (ros_ws/standard_interfaces) this workspace must build itself: those that
none of the ament prefixes provides. A regular ROS 2 install has them (from apt), so nothing is built there and
the real packages are used; the PyPI wheels lack them, so the workspace declares them with upstream's fields.

    python scripts/standard_interfaces.py [PREFIX ...]    (default: the prefixes of AMENT_PREFIX_PATH)

One path per line, relative to ros_ws (what `colcon build --base-paths` takes). Standard library only: it runs
before anything is built.
"""
from __future__ import annotations

import os
import pathlib
import sys

ROS_WS = pathlib.Path(__file__).resolve().parents[1] / 'ros_ws'
FOLDER = 'standard_interfaces'


def provided(package: str, prefix: str) -> bool:
    """Whether an install prefix holds the package (its ament index marker, as colcon and ament look for it)."""
    return (pathlib.Path(prefix) / 'share' / 'ament_index' / 'resource_index' / 'packages' / package).is_file()


def to_build(prefixes: list[str]) -> list[str]:
    """The standard interface packages no prefix provides, as paths relative to ros_ws, sorted."""
    packages = sorted(path.parent.name for path in (ROS_WS / FOLDER).glob('*/package.xml'))
    return [f'{FOLDER}/{package}' for package in packages
            if not any(provided(package, prefix) for prefix in prefixes)]


def main(argv: list[str]) -> int:
    prefixes = argv or [prefix for prefix in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep) if prefix]
    for path in to_build(prefixes):
        print(path)
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
