"""The graph's process keeps its threads, old and new, on one CPU."""
import os
import subprocess
import sys

import pytest

pytestmark = pytest.mark.skipif((os.cpu_count() or 1) < 2, reason='needs two CPUs to choose from')

CHILD = '''
import os, threading
from cap_bringup.cpu_affinity import pin_to_one_cpu
os.sched_setaffinity(0, range(os.cpu_count()))  # this test process may be pinned already (conftest.py)
started = threading.Event(); done = threading.Event(); seen = {}
def before():
    started.set(); done.wait(); seen['before'] = sorted(os.sched_getaffinity(0))
t = threading.Thread(target=before); t.start(); started.wait()
cpu = pin_to_one_cpu(1)
after = threading.Thread(target=lambda: seen.update(after=sorted(os.sched_getaffinity(0)))); after.start(); after.join()
done.set(); t.join()
print(cpu, seen['before'], seen['after'], sorted(os.sched_getaffinity(0)))
'''


def test_every_thread_running_or_started_later_is_on_the_chosen_cpu():
    allowed = list(range(os.cpu_count()))
    done = subprocess.run([sys.executable, '-c', CHILD], capture_output=True, text=True, timeout=60,
                          env={**os.environ, 'PYTHONPATH': os.pathsep.join(sys.path)})
    assert done.returncode == 0, done.stderr
    cpu = allowed[1 % len(allowed)]
    assert done.stdout.split() == [str(cpu), f'[{cpu}]', f'[{cpu}]', f'[{cpu}]']


def test_the_cpus_besides_the_graphs_are_the_others():
    from cap_bringup.cpu_affinity import cpus_besides

    assert cpus_besides(0, [0, 1]) == [1] and cpus_besides(3, [2, 0, 1]) == [1, 2] and cpus_besides(0, [5]) == []
