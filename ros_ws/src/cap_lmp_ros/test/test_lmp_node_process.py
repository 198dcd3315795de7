"""The standalone lmp_node process (its `main`): a configuration error is one line and exit status 2; a thread it
depends on that dies is one line naming the thread and the error, and a non-zero exit, not a zombie node."""
import os
import subprocess
import sys

import pytest
from rclpy.parameter import Parameter

from cap_lmp_ros.lmp_node import LmpNode
from cap_lmp_ros.thread_watch import FATAL_EXIT_CODE, ThreadWatch, death_line

MAIN = 'from cap_lmp_ros.lmp_node import main; main()'
# A fault of the node's own making in its worker thread, the kind no program or command can cause any more.
BROKEN_WORKER = ('import cap_lmp_ros.command_queue as q\n'
                 'def next_job(self, timeout=None):\n'
                 '    raise RuntimeError("the queue is broken")\n'
                 'q.CommandQueue.next_job = next_job\n' + MAIN)


def run_lmp_node(code, *ros_args, timeout=60.0):
    environment = {**os.environ}
    environment.pop('CAP_LLM_MODEL', None)
    return subprocess.run([sys.executable, '-c', code, '--ros-args', *ros_args], env=environment,
                          capture_output=True, text=True, timeout=timeout)


def test_http_backend_without_a_model_says_in_one_line_what_to_set():
    finished = run_lmp_node(MAIN, '-p', 'llm_backend:=http')
    assert finished.returncode == 2
    lines = finished.stderr.strip().splitlines()
    assert len(lines) == 1, finished.stderr
    assert 'CAP_LLM_MODEL' in lines[0] and 'model' in lines[0] and 'CAP_LLM_BASE_URL' in lines[0] \
        and 'base_url' in lines[0]


def test_the_node_refuses_to_start_without_a_model_with_a_value_error(ros_context, monkeypatch):
    monkeypatch.delenv('CAP_LLM_MODEL', raising=False)
    with pytest.raises(ValueError, match=r'set CAP_LLM_MODEL \(parameter model\) and CAP_LLM_BASE_URL'):
        LmpNode(context=ros_context, parameter_overrides=[Parameter('llm_backend', value='http')])


def test_a_dead_worker_thread_ends_the_process_saying_which_and_why():
    finished = run_lmp_node(BROKEN_WORKER, '-p', 'sandbox_process:=false')
    assert finished.returncode == FATAL_EXIT_CODE, finished.stderr
    deaths = [line for line in finished.stderr.splitlines() if 'died' in line]
    assert len(deaths) == 1, finished.stderr
    assert "thread 'lmp_worker' died: RuntimeError: the queue is broken" in deaths[0]
    assert 'Traceback' not in finished.stderr


def test_a_watch_reports_the_first_death_once_in_one_printable_line():
    lines, calls = [], []
    watch = ThreadWatch(on_death=calls.append, log=lines.append)
    watch.start(lambda: 1 / 0, 'first').join()
    watch.start(lambda: [][1], 'second').join()
    assert watch.died.is_set() and lines == calls == [watch.failure]
    assert watch.failure == "thread 'first' died: ZeroDivisionError: division by zero"
    assert death_line('w', ValueError('a\nb\x1b[2J' + chr(55296))).isprintable()
    stopped = ThreadWatch(log=lines.append)
    stopped.stop()  # shutting down: a thread ending by an exception then is no failure
    stopped.start(lambda: 1 / 0, 'late').join()
    assert not stopped.died.is_set() and len(lines) == 1


def test_the_environment_chooses_the_protocol_and_timeout_unless_a_parameter_does(ros_context, monkeypatch):
    monkeypatch.setenv('CAP_LLM_API', 'completions')
    monkeypatch.setenv('CAP_LLM_TIMEOUT_S', '7.5')
    monkeypatch.setenv('CAP_LLM_BASE_URL', 'http://127.0.0.1:9/v1')
    http = [Parameter('llm_backend', value='http'), Parameter('model', value='m'),
            Parameter('sandbox_process', value=False)]
    from_environment = LmpNode(context=ros_context, parameter_overrides=http)
    try:
        assert (from_environment.engine.client.api, from_environment.engine.client.timeout_s) == ('completions', 7.5)
    finally:
        from_environment.destroy_node()
    chosen = LmpNode(context=ros_context, parameter_overrides=http + [Parameter('api', value='chat'),
                                                                        Parameter('request_timeout_s', value=3.0)])
    try:
        assert (chosen.engine.client.api, chosen.engine.client.timeout_s) == ('chat', 3.0)
    finally:
        chosen.destroy_node()
    monkeypatch.setenv('CAP_LLM_API', 'telepathy')
    with pytest.raises(ValueError, match="CAP_LLM_API='telepathy' is not one of chat, completions"):
        LmpNode(context=ros_context, parameter_overrides=http)
