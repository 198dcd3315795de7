"""The `cap` command line as a user runs it: separate processes talking over DDS."""
import os
import signal
import subprocess
import sys

import pytest


def _cap(*args, timeout=120):
    return subprocess.run([sys.executable, '-m', 'cap_llm.cli', *args], capture_output=True, text=True,
                          timeout=timeout, env=os.environ.copy())


@pytest.mark.slow
def test_up_send_snapshot_stop_and_ctrl_c(ros_isolation, tmp_path):
    graph = subprocess.Popen([sys.executable, '-m', 'cap_llm.cli', 'up', '--seed', '2',
                              '--objects', 'red block, blue block, green bowl'],
                             stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=os.environ.copy())
    try:
        ok = _cap('send', 'stack all the blocks', '--wait', '60')
        assert ok.returncode == 0, ok.stdout + ok.stderr
        assert 'put_first_on_second' in ok.stdout and ok.stdout.rstrip().endswith('success: done')

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
    assert 'shutting down' in output


def test_send_without_a_graph_says_so(ros_isolation):
    result = _cap('send', 'hello', '--wait', '1')
    assert result.returncode == 2
    assert 'nobody offers /cap/execute' in result.stderr
