"""Test fixtures shared by every package's tests and the integration tests in tests/.

Every test runs with DDS discovery limited to this host and a ROS_DOMAIN_ID of its own, so tests never see each
other's nodes (nor anything else on the machine) and no traffic leaves loopback.
"""
from __future__ import annotations

import itertools
import os
import pathlib
import time
from typing import Callable, Iterator

import pytest

# 1..101 are the domain ids whose DDS ports fit below Linux's ephemeral port range. Start at a pid-dependent
# offset so that two test runs on one machine are unlikely to share a domain at the same moment.
_FIRST_DOMAIN = 1
_DOMAIN_COUNT = 101
_domain_ids = itertools.count(os.getpid() % _DOMAIN_COUNT)


def next_domain_id() -> int:
    return _FIRST_DOMAIN + next(_domain_ids) % _DOMAIN_COUNT


def pytest_configure(config: pytest.Config) -> None:
    # Tests bring up graphs in this process: keep its threads on one CPU, as Graph does (cap_bringup/cpu_affinity.py).
    from cap_bringup.cpu_affinity import pin_to_one_cpu

    pin_to_one_cpu(0)


def _brings_up_ros(item: pytest.Item) -> bool:
    """Whether a test talks over DDS: its module uses rclpy or the lmp_node test graph, or it asks for ros_context."""
    source = getattr(item.module, '__cap_source__', None) if hasattr(item, 'module') else ''
    if source is None:
        source = pathlib.Path(item.module.__file__).read_text(encoding='utf-8')
        item.module.__cap_source__ = source
    return 'ros_context' in getattr(item, 'fixturenames', ()) or 'rclpy' in source or 'lmp_graph' in source


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    # `make test-fast` deselects these: the integration tests in tests/ and every test that brings up ROS nodes.
    for item in items:
        if item.path.parent.name == 'tests' or _brings_up_ros(item):
            item.add_marker(pytest.mark.graph)


@pytest.fixture(autouse=True)
def ros_isolation(monkeypatch: pytest.MonkeyPatch) -> str:
    """Give this test localhost-only discovery and its own ROS_DOMAIN_ID (inherited by any process it starts)."""
    domain_id = str(next_domain_id())
    monkeypatch.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    monkeypatch.setenv('ROS_DOMAIN_ID', domain_id)
    monkeypatch.delenv('ROS_LOCALHOST_ONLY', raising=False)
    return domain_id


@pytest.fixture
def install_plugin(tmp_path: pathlib.Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Callable[..., pathlib.Path]]:
    """install_plugin(modules, entry_points, name='test-plugin'): a package of this test, installed for this test only
    (cap_ros_common.testing.write_distribution into a folder put first on sys.path; processes the test starts
    inherit it through PYTHONPATH). Its modules are forgotten afterwards."""
    import sys

    from cap_ros_common.testing import write_distribution

    folder = tmp_path / 'installed'
    monkeypatch.setenv('PYTHONPATH', os.pathsep.join([str(folder), *filter(None, sys.path)]))

    def install(modules, entry_points, name: str = 'test-plugin') -> pathlib.Path:
        write_distribution(folder, name, modules, entry_points)
        monkeypatch.syspath_prepend(str(folder))
        return folder

    yield install
    for name, module in list(sys.modules.items()):
        if str(getattr(module, '__file__', None) or '').startswith(str(folder)):
            del sys.modules[name]


@pytest.fixture
def ros_context(ros_isolation: str) -> Iterator[object]:
    """An initialised rclpy context for this test only; nodes take it as `context=`."""
    import rclpy
    from rclpy.context import Context

    context = Context()
    rclpy.init(context=context, domain_id=int(ros_isolation))
    try:
        yield context
    finally:
        context.try_shutdown()


@pytest.fixture
def spin_until() -> Callable[..., bool]:
    """spin_until(executor, predicate, timeout=10.0) -> bool: spin until predicate() holds or the timeout passes."""

    def _spin_until(executor, predicate: Callable[[], bool], timeout: float = 10.0) -> bool:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if predicate():
                return True
            executor.spin_once(timeout_sec=0.05)
        return predicate()

    return _spin_until
