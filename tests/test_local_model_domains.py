"""The whiteboard, the mobile kitchen and the controllers with the real local model: `cap up --domain NAME` with the
llama.cpp server and the default model of `make model`, one everyday command each, judged on the simulator's state
by the domain's benchmark judge (the ink, where the base stopped, how long the pole stood).

Each test brings up its domain's graph with lmp_node supervising the model server (llm_backend=local), so the
model reads that domain's prompts (from its prompt cache after the first start). Without the installed model the
module is skipped, unless CAP_REQUIRE_LOCAL_MODEL=1 (CI, after `make model`) makes that a failure.
"""
import dataclasses
import os

import pytest

from cap_bench.bench_options import BenchOptions
from cap_lmp.local_server import local_model_installed
from conftest import next_domain_id

pytestmark = [pytest.mark.slow, pytest.mark.graph, pytest.mark.timeout(1800), pytest.mark.skipif(
    not local_model_installed() and os.environ.get('CAP_REQUIRE_LOCAL_MODEL') != '1',
    reason='the local model is not installed (make model)')]

LOCAL = BenchOptions(policy='llm', backend='local', model_threads=1, episode_timeout_s=600.0)


@pytest.fixture
def own_domain(monkeypatch):
    monkeypatch.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    monkeypatch.setenv('ROS_DOMAIN_ID', str(next_domain_id()))


def _assert_done(record: dict) -> None:
    assert record['success'], f"{record['reason']}\n{record['code']}"
    assert record['model_calls'] >= 1


def test_the_local_model_draws_on_the_whiteboard(own_domain):
    from cap_bench.whiteboard import devset
    from cap_bench.whiteboard.bench import WhiteboardRunner

    episode = devset.BY_KEY['square_by_side'].episode()  # a square with 6 cm sides in the middle, objects clear of it
    runner = WhiteboardRunner(LOCAL, None)
    try:
        record = runner.run(episode)
    finally:
        runner.close()
    _assert_done(record)
    assert record['p95_mm'] <= 3.0 and record['coverage'] >= 0.95  # the ink, as the benchmark judges it


def test_the_local_model_drives_the_mobile_robot(own_domain):
    from cap_bench.mobile.bench import MobileRunner
    from cap_bench.mobile.episodes import sample_episode

    episode = dataclasses.replace(sample_episode('goto', 0), instructions=('drive over to the desk',))
    runner = MobileRunner(LOCAL, None)
    try:
        record = runner.run(episode)
    finally:
        runner.close()
    _assert_done(record)  # the base at the desk's approach pose (the benchmark's judge)
    assert record['travelled_m'] > 0.5


def test_the_local_model_balances_the_pole(own_domain):
    from cap_bench.controllers import templates
    from cap_bench.controllers.bench import Runner
    from cap_bench.bench_options import lmp_parameters
    from cap_bringup.graph import GraphOptions

    episode = dataclasses.replace(templates.episode(templates.BALANCE, 0, 10.0),
                                  instruction='balance the pole on the cart for 10 seconds')
    backend, lmp = lmp_parameters(LOCAL)
    runner = Runner(GraphOptions(domain='controllers', llm_backend=backend, extra={'lmp_node': lmp}),
                    LOCAL.episode_timeout_s)
    try:
        record = runner.run(episode)
    finally:
        runner.close()
    _assert_done(record)  # the controller node ran the whole 10 s: the pole never passed 12 degrees
