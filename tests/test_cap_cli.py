"""The `cap` command line as a user runs it: separate processes talking over DDS."""
import json
import os
import queue
import signal
import socket
import subprocess
import sys
import threading
import time
import urllib.error
import urllib.request

import pytest

from cap_bringup.testing.cli_scenes import CONTROL_CHARACTERS, ENDLESS, write_cli_cassette
from cap_lmp_ros.thread_watch import FATAL_EXIT_CODE


def _cap(*args, timeout=120):
    return subprocess.run([sys.executable, '-m', 'cap_bringup.cli', *args], capture_output=True, text=True,
                          timeout=timeout, env=os.environ.copy())


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(('127.0.0.1', 0))
        return probe.getsockname()[1]


def _page(url: str, timeout: float = 60.0) -> str:
    deadline = time.monotonic() + timeout
    while True:
        try:
            with urllib.request.urlopen(url, timeout=5) as response:
                return response.read().decode()
        except (urllib.error.URLError, ConnectionError):
            if time.monotonic() > deadline:
                raise
            time.sleep(0.2)


@pytest.mark.slow
def test_up_send_snapshot_stop_and_ctrl_c(ros_isolation, tmp_path):
    port = _free_port()
    graph = subprocess.Popen([sys.executable, '-m', 'cap_bringup.cli', 'up', '--backend', 'cassette', '--seed', '2',
                              '--objects', 'red block, blue block, green bowl', '--console', '--console-port',
                              str(port), '--require-approval'],
                             stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=os.environ.copy())
    try:
        assert '<title>cap-ros console</title>' in _page(f'http://127.0.0.1:{port}/')  # cap up --console
        # --require-approval: the command waits with its plan until `cap approve`.
        sending = subprocess.Popen([sys.executable, '-m', 'cap_bringup.cli', 'send', 'stack all the blocks', '--wait',
                                    '60'], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                   env=os.environ.copy())
        lines: queue.Queue = queue.Queue()
        threading.Thread(target=_lines, args=(sending.stdout, lines), daemon=True).start()
        seen: list[str] = []
        if not _wait_for_line(lines, seen, '[awaiting_approval]', 120):
            sending.kill()
            raise AssertionError(''.join(seen) + sending.communicate()[1])
        assert 'put the red block on the blue block' in seen[-1]
        approved = _cap('approve')
        assert approved.returncode == 0, approved.stdout + approved.stderr
        assert 'plan: put the red block on the blue block' in approved.stdout
        assert 'approved: it runs now' in approved.stdout
        assert sending.wait(120) == 0
        assert _wait_for_line(lines, seen, 'success: done', 10), ''.join(seen)
        nothing = _cap('approve', '--reject')
        assert nothing.returncode == 1 and 'no command waits for approval' in nothing.stdout

        missing = _cap('send', 'fly to the moon')
        assert missing.returncode == 1
        assert "no answer for LMP 'tabletop_ui' and query 'fly to the moon'" in missing.stdout

        shots = _cap('snapshot', '--out', str(tmp_path))
        assert shots.returncode == 0, shots.stderr
        assert (tmp_path / 'front.png').stat().st_size > 1000 and (tmp_path / 'top.png').stat().st_size > 1000

        assert _cap('stop').returncode == 0
    finally:
        graph.send_signal(signal.SIGINT)
        output, _ = graph.communicate(timeout=30)
    assert graph.returncode == 0
    assert 'shutting down' in output and f'console: http://127.0.0.1:{port}/' in output
    with pytest.raises(urllib.error.URLError):  # the console ended with the graph
        _page(f'http://127.0.0.1:{port}/', timeout=0)


def test_urdf_prints_the_robot_description():
    result = _cap('urdf')
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith('<?xml') and '<joint name="shoulder_pan_joint" type="revolute">' in result.stdout


def test_send_without_a_graph_says_so(ros_isolation):
    result = _cap('send', 'hello', '--wait', '1')
    assert result.returncode == 2
    assert 'nobody offers /cap/execute' in result.stderr


# ------------------------------------------------------------------------------------------------ timeouts, signals
def _lines(stream, into: queue.Queue) -> None:
    for line in stream:
        into.put(line)
    into.put(None)


def _wait_for_line(lines: queue.Queue, seen: list, text: str, timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            line = lines.get(timeout=0.5)
        except queue.Empty:
            continue
        if line is None:
            return False
        seen.append(line)
        if text in line:
            return True
    return False


class _GraphLog:
    """What `cap up` has printed so far, for the message of a failed assertion."""

    def __init__(self, lines: queue.Queue, seen: list) -> None:
        self._lines, self._seen = lines, seen

    def text(self) -> str:
        while not self._lines.empty():
            line = self._lines.get()
            if line is not None:
                self._seen.append(line)
        return ''.join(self._seen)

    def after(self, result: subprocess.CompletedProcess) -> str:
        return f'{result.stdout}{result.stderr}\n--- cap up printed:\n{self.text()}'


@pytest.fixture
def cli_graph(ros_isolation, tmp_path):
    """`cap up` with the command-line test programs (cap_bringup.testing.cli_scenes), stopped with Ctrl-C at the end."""
    cassette = write_cli_cassette(tmp_path / 'cli.yaml')
    graph = subprocess.Popen([sys.executable, '-m', 'cap_bringup.cli', 'up', '--fast', '--cassette', str(cassette)],
                             stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=os.environ.copy())
    lines: queue.Queue = queue.Queue()
    reader = threading.Thread(target=_lines, args=(graph.stdout, lines), daemon=True)
    reader.start()
    seen: list[str] = []
    log = _GraphLog(lines, seen)
    try:
        # The tests time their commands (--timeout): they start once the graph says it is up, not while it loads.
        assert _wait_for_line(lines, seen, 'cap-ros is up', 120), ''.join(seen)
        yield log
    finally:
        graph.send_signal(signal.SIGINT)
        graph.wait(timeout=30)
        reader.join(timeout=10)
    output = log.text()
    assert graph.returncode == 0, output
    assert 'Traceback' not in output and 'never retrieved' not in output, output


def test_send_holds_its_timeout_ends_on_sigterm_and_prints_no_control_characters(cli_graph):
    # --timeout bounds the wait for the result of a program that never ends; the command is cancelled.
    started = time.monotonic()
    late = _cap('send', ENDLESS, '--wait', '60', '--timeout', '8')
    took = time.monotonic() - started
    assert late.returncode == 3, cli_graph.after(late)
    assert 'timed out after 8 s (--timeout) waiting for the result; ' in late.stderr  # then: cancelled, or no answer
    assert took < 8 + 2 + 15, took  # the timeout, the cancel's grace, and a generous start of the process

    # SIGTERM ends a `cap send` that follows an endless program within a few seconds, and cancels the program.
    follow = subprocess.Popen([sys.executable, '-m', 'cap_bringup.cli', 'send', ENDLESS, '--wait', '60'],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=os.environ.copy())
    lines: queue.Queue = queue.Queue()
    threading.Thread(target=_lines, args=(follow.stdout, lines), daemon=True).start()
    seen: list[str] = []
    try:
        assert _wait_for_line(lines, seen, 'while True', 60), ''.join(seen)
        follow.send_signal(signal.SIGTERM)
        signalled = time.monotonic()
        follow.wait(timeout=10)
        ended_after = time.monotonic() - signalled
    finally:
        follow.kill()
    stderr = follow.stderr.read()
    assert follow.returncode == 143, stderr
    assert 'interrupted (SIGTERM): ' in stderr
    assert ended_after < 5, ended_after

    # The graph answers the next command, whose code and said line hold control characters: shown escaped.
    shown = _cap('send', CONTROL_CHARACTERS, '--wait', '60', '--timeout', '120')
    assert shown.returncode == 0, cli_graph.after(shown)
    assert not any(ch in shown.stdout + shown.stderr for ch in '\x1b\x07\r'), repr(shown.stdout)
    assert 'robot says: \\x1b[31mred\\x1b[0m, a bell \\x07, a return \\x0d done' in shown.stdout
    assert 'say("\\x1b[31mred' in shown.stdout  # the code, as printed


def test_up_without_a_model_says_what_to_set_in_one_line(ros_isolation):
    env = {k: v for k, v in os.environ.items() if not k.startswith('CAP_LLM_')}
    result = subprocess.run([sys.executable, '-m', 'cap_bringup.cli', 'up', '--backend', 'http'], capture_output=True,
                            text=True, timeout=120, env=env)
    output = result.stdout + result.stderr
    assert result.returncode == 2, output
    errors = [line for line in output.splitlines() if line.startswith('error:')]
    assert len(errors) == 1 and 'CAP_LLM_MODEL' in errors[0], output
    assert 'Traceback' not in output, output


def test_up_with_a_missing_local_model_says_how_to_install_it_in_one_line(ros_isolation, tmp_path):
    result = subprocess.run([sys.executable, '-m', 'cap_bringup.cli', 'up', '--backend', 'local', '--model-file',
                             str(tmp_path / 'absent.gguf')], capture_output=True, text=True, timeout=120,
                            env=os.environ.copy())
    output = result.stdout + result.stderr
    assert result.returncode == 2, output
    errors = [line for line in output.splitlines() if line.startswith('error:')]
    assert len(errors) == 1 and 'absent.gguf' in errors[0] and 'make model' in errors[0], output
    assert 'Traceback' not in output, output


def test_bench_help_usage_and_domain_ids(ros_isolation, tmp_path):
    shown = _cap('bench', '--help')
    assert shown.returncode == 0, shown.stderr
    assert 'usage: cap bench NAME' in shown.stdout and 'cap bench whiteboard' in shown.stdout
    bare = _cap('bench')
    assert bare.returncode == 2
    assert 'usage: cap bench NAME' in bare.stderr and 'Traceback' not in bare.stderr
    # The run's graphs use the environment's ROS_DOMAIN_ID (job i: ROS_DOMAIN_ID + i); too many jobs are refused.
    empty = _cap('bench', 'tabletop', '--trials', '0', '--out', str(tmp_path))
    assert empty.returncode == 0, empty.stderr
    assert json.loads((tmp_path / 'options.json').read_text())['first_domain_id'] == int(ros_isolation)
    crowded = subprocess.run([sys.executable, '-m', 'cap_bringup.cli', 'bench', 'tabletop', '--jobs', '4'],
                             capture_output=True, text=True, timeout=60, env={**os.environ, 'ROS_DOMAIN_ID': '231'})
    assert crowded.returncode == 2
    assert 'error: 4 job(s) need ROS_DOMAIN_IDs 231..234' in crowded.stderr


# A fault a node's callback may have: the executor thread that ran it dies. Wrapped around the real Graph.
_FAULTY_CALLBACK = '''
import sys
import rclpy
from cap_bringup import cli, graph

built = graph.Graph.__init__

def with_a_faulty_node(self, *args, **kwargs):
    built(self, *args, **kwargs)
    node = rclpy.create_node('faulty', context=self.context)
    node.create_timer(1.0, lambda: (_ for _ in ()).throw(RuntimeError('a callback broke')))
    self.executor.add_node(node)

graph.Graph.__init__ = with_a_faulty_node
sys.exit(cli.main(['up', '--backend', 'cassette']))
'''


def test_up_exits_when_an_executor_thread_dies(ros_isolation):
    result = subprocess.run([sys.executable, '-c', _FAULTY_CALLBACK], capture_output=True, text=True, timeout=120,
                            env=os.environ.copy())
    assert result.returncode == FATAL_EXIT_CODE, result.stdout + result.stderr
    assert ("error: the graph no longer answers: thread 'graph_executor' died: RuntimeError: a callback broke"
            in result.stderr)
    assert 'shutting down: the graph no longer answers' in result.stdout
