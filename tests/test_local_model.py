"""The whole graph with the real local model (llama.cpp server and the default model of `make model`).

lmp_node starts and supervises the server itself (llm_backend=local). One graph for the module: the model loads
and reads its prompts once (minutes on one core). Without the installed model the module is skipped, unless
CAP_REQUIRE_LOCAL_MODEL=1 (CI, after `make model`) makes that a failure.
"""
import os
import signal
import subprocess
import sys
import time

import pytest

from cap_bench.devset.bench import _episode_judge
from cap_bench.devset.commands import BY_KEY
from cap_bench.tabletop.options import TabletopOptions
from cap_bench.tabletop.runner import TabletopRunner
from cap_lmp.local_model import default_model_path
from cap_lmp.local_server import local_model_installed
from conftest import next_domain_id

# The first test also waits for the model to load and read its prompts (the module's graph), the last for it to
# read them again after a restart: minutes each on one core, more on a loaded machine.
pytestmark = [pytest.mark.slow, pytest.mark.graph, pytest.mark.timeout(1800), pytest.mark.skipif(
    not local_model_installed() and os.environ.get('CAP_REQUIRE_LOCAL_MODEL') != '1',
    reason='the local model is not installed (make model)')]

READY_LINE = '[lmp_node]: model ready'  # what `cap up` logs once the model has its prompts
# Everyday commands of the development set, each judged on the simulator's final state.
COMMANDS = ('bowl_by_name', 'block_on_block', 'to_corner')


@pytest.fixture(scope='module')
def local_graph():
    with pytest.MonkeyPatch.context() as env:
        env.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
        env.setenv('ROS_DOMAIN_ID', str(next_domain_id()))
        runner = TabletopRunner(TabletopOptions(policy='llm', backend='local', episode_timeout_s=300.0), None)
        try:
            yield runner
        finally:
            runner.close()


def run(runner: TabletopRunner, key: str) -> dict:
    command = BY_KEY[key]
    return runner.run(command.episode(), judge=_episode_judge(command), instructions=command.instructions)


@pytest.mark.parametrize('key', COMMANDS)
def test_the_local_model_does_an_everyday_command(local_graph, key):
    record = run(local_graph, key)
    assert record['success'], f"{record['reason']}\n{record['code']}"
    assert record['model_calls'] >= 1 and record['completion_tokens'] > 0


def test_the_servers_death_mid_command_is_a_clear_error_and_the_server_comes_back(local_graph):
    from cap_interfaces.msg import GraphNames, StatusEvent
    from cap_lmp_ros.lmp_node import EVENT_QOS

    node = local_graph.graph.nodes['lmp_node']
    server = node.model_server
    first_pid, first_start = server.pid, node.model_ready_generation
    model_events = []
    local_graph.node.create_subscription(
        StatusEvent, GraphNames.STATUS_TOPIC,
        lambda status: model_events.append(status.message) if status.stage == StatusEvent.STAGE_MODEL else None,
        EVENT_QOS)

    def kill_while_generating(feedback) -> None:
        if feedback.feedback.status.stage == StatusEvent.STAGE_GENERATING and server.pid == first_pid:
            os.kill(first_pid, signal.SIGKILL)

    goal_future = local_graph.execute.send_goal_async(
        local_graph.ExecuteCommand.Goal(command='put the red block in the blue bowl'),
        feedback_callback=kill_while_generating)
    goal = local_graph.call(goal_future, 30, 'lmp_node (goal)')
    result = local_graph.call(goal.get_result_async(), 300, 'lmp_node (result)').result
    assert result.outcome == local_graph.ExecuteCommand.Result.OUTCOME_MODEL_ERROR
    assert 'the local model server stopped during the request (exit code -9)' in result.message
    assert 'send the command again' in result.message

    # restarted, its prompts read again, and answering: the next command is done
    deadline = time.monotonic() + 900
    while node.model_ready_generation <= first_start and time.monotonic() < deadline:
        time.sleep(0.5)
    assert server.pid != first_pid and node.model_ready_generation == first_start + 1
    assert any('died (exit code -9); restarting' in message for message in model_events), model_events
    # the restarted server took the prompts from the files the first start saved, instead of reading them again
    assert any(message.startswith('model ready') and f'server start {first_start + 1};' in message
               and 'restored from' in message for message in model_events), model_events
    record = run(local_graph, 'to_middle')
    assert record['success'], f"{record['reason']}\n{record['code']}"


def test_a_command_sent_before_the_model_is_ready_waits_for_it_and_the_next_start_is_quick(ros_isolation, tmp_path):
    """As a user tried it: `cap up` on a cold start, and 20 s later a command. The model reads its prompts for minutes
    on one core; the command waits for that outside its 120 s model deadline and ends done. The prompts read are kept
    (here in a cache folder of the test's own), so the next start restores them instead of reading them."""
    env = {**os.environ, 'CAP_CACHE': str(tmp_path / 'cache'), 'CAP_MODEL_FILE': str(default_model_path())}
    up = [sys.executable, '-m', 'cap_bringup.cli', 'up', '--backend', 'local', '--seed', '1',
          '--objects', 'green block, cyan bowl, red block']
    first_log = tmp_path / 'first.log'
    first = _start(up, env, first_log)
    try:
        time.sleep(20.0)  # the user's pause, not a measurement
        sent = subprocess.run([sys.executable, '-m', 'cap_bringup.cli', 'send', 'put the green block in the cyan bowl',
                               '--wait', '120', '--timeout', '1200'], capture_output=True, text=True, env=env,
                              timeout=1300)
        assert sent.returncode == 0 and 'success: done' in sent.stdout, sent.stdout + sent.stderr
    finally:
        _stop(first)
    output = first_log.read_text(errors='replace')
    ready = [line for line in output.splitlines() if READY_LINE in line]
    assert ready and 'restored from' not in ready[0], output[-3000:]  # every prompt was read
    assert len(list((tmp_path / 'cache' / 'prompt-kv').glob('*.kv'))) >= 2

    second_log = tmp_path / 'second.log'
    second = _start(up, env, second_log)
    try:
        deadline = time.monotonic() + 600
        while READY_LINE not in second_log.read_text(errors='replace') and time.monotonic() < deadline \
                and second.poll() is None:
            time.sleep(0.5)
    finally:
        _stop(second)
    ready = [line for line in second_log.read_text(errors='replace').splitlines() if READY_LINE in line]
    assert ready and 'restored from' in ready[0] and ', 0 tokens read' in ready[0], second_log.read_text()[-3000:]


def _start(command: list[str], env: dict[str, str], log) -> subprocess.Popen:
    with open(log, 'w') as out:  # a file, not a pipe nobody reads while the graph runs
        return subprocess.Popen(command, stdout=out, stderr=subprocess.STDOUT, env=env, start_new_session=True)


def _stop(process: subprocess.Popen) -> None:
    """Ctrl-C to the graph, as a user stops it."""
    if process.poll() is None:
        os.killpg(process.pid, signal.SIGINT)
    try:
        process.wait(60)
    except subprocess.TimeoutExpired:
        os.killpg(process.pid, signal.SIGKILL)
        process.wait()
