"""Make the ROS 2 Jazzy PyPI wheels' CMake exports usable in this virtual environment.

The wheels were built in a manylinux container, and their exported CMake targets name that container's Python
and NumPy include folders. CMake refuses targets with non-existent include paths, so every interface package
build fails until those paths point at this interpreter's folders. Idempotent: a second run changes nothing.
"""
from __future__ import annotations

import pathlib
import sys
import sysconfig

import numpy

BUILD_CONTAINER_PATHS = {
    '/opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include': numpy.get_include(),
    '/opt/python/cp311-cp311/include/python3.11': sysconfig.get_paths()['include'],
}


def fix_cmake_exports(prefix: pathlib.Path) -> int:
    """Rewrite build-container include paths in prefix/share/**/*.cmake; return the number of files changed."""
    changed = 0
    for cmake_file in (prefix / 'share').rglob('*.cmake'):
        text = cmake_file.read_text(encoding='utf-8', errors='surrogateescape')
        if '/opt/python/cp311-cp311' not in text:
            continue
        # Longest path first: the NumPy path starts with the interpreter prefix too.
        for old, new in BUILD_CONTAINER_PATHS.items():
            text = text.replace(old, new)
        cmake_file.write_text(text, encoding='utf-8', errors='surrogateescape')
        changed += 1
    return changed


if __name__ == '__main__':
    venv = pathlib.Path(sys.prefix)
    count = fix_cmake_exports(venv)
    print(f'fix_ros_wheels: {count} CMake export file(s) rewritten under {venv / "share"}')
