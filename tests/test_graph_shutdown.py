"""A user's script that builds the graph ends cleanly however it ends, and quietly: no crash, no traceback, no
"exception was never retrieved", no sandbox process left behind."""
import os
import signal
import subprocess
import sys
import time

import pytest

from cap_bringup.testing.cli_scenes import ENDLESS, HELLO, write_cli_cassette

# Builds the graph and runs one command through /cap/execute; then the script ends: by returning from a
# `with Graph(...)` block, by just returning (no close(), no reference kept), or by SIGTERM while a program runs.
_SCRIPT = '''
import sys, time
import rclpy
from rclpy.action import ActionClient
from rclpy.context import Context
from cap_interfaces.action import ExecuteCommand
from cap_interfaces.msg import GraphNames
from cap_bringup.graph import Graph, GraphOptions

cassette, command, ending = sys.argv[1:]
context = Context()
rclpy.init(context=context)


def wait(predicate):
    deadline = time.monotonic() + 60
    while not predicate():
        assert time.monotonic() < deadline
        time.sleep(0.01)


def run(graph):
    user = rclpy.create_node('user_script', context=context)
    graph.executor.add_node(user)
    execute = ActionClient(user, ExecuteCommand, GraphNames.EXECUTE_ACTION)
    wait(execute.server_is_ready)
    goal = execute.send_goal_async(ExecuteCommand.Goal(command=command))
    wait(goal.done)
    print('sandbox', graph.nodes['lmp_node'].engine.pid, flush=True)
    if ending == 'sigterm':
        print('running', flush=True)
        time.sleep(120)
    result = goal.result().get_result_async()
    wait(result.done)
    print('result', result.result().result.success, flush=True)


options = GraphOptions(seed=1, cassette=cassette)
if ending == 'with':
    with Graph(context, options) as graph:
        run(graph)
else:
    run(Graph(context, options))  # no reference kept, no close(): the end of the script must do
'''


def _alive(pid: int) -> bool:
    try:
        with open(f'/proc/{pid}/stat') as stat:
            return stat.read().split(')')[-1].split()[0] != 'Z'
    except FileNotFoundError:
        return False


@pytest.mark.parametrize('ending', ['with', 'return', 'sigterm'])
def test_a_script_that_builds_the_graph_exits_cleanly(ros_isolation, tmp_path, ending):
    cassette = write_cli_cassette(tmp_path / 'cli.yaml')
    command = ENDLESS if ending == 'sigterm' else HELLO
    script = subprocess.Popen([sys.executable, '-c', _SCRIPT, str(cassette), command, ending], text=True,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=os.environ.copy())
    try:
        if ending == 'sigterm':
            lines = []
            for line in script.stdout:
                lines.append(line)
                if line.startswith('running'):
                    break
            assert lines and lines[-1].startswith('running'), lines
            time.sleep(1.0)  # the program is running now
            script.send_signal(signal.SIGTERM)
        stdout, stderr = script.communicate(timeout=60)
    finally:
        script.kill()
    if ending == 'sigterm':
        stdout = ''.join(lines) + stdout
    assert script.returncode == (128 + signal.SIGTERM if ending == 'sigterm' else 0), stderr
    for noise in ('Traceback', 'never retrieved', 'Segmentation', 'Exception in thread'):
        assert noise not in stderr, stderr
    if ending != 'sigterm':
        assert 'result True' in stdout
    sandbox = int(stdout.split('sandbox ')[1].split()[0])
    deadline = time.monotonic() + 10
    while _alive(sandbox) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not _alive(sandbox), 'the sandbox process outlived the script'
