"""How long `cap up --backend local` takes until the model is ready, on a cold start and on the next one.

The first start in an empty cache folder reads every prompt of the domain into the llama.cpp server's cache and
saves it; each later start restores the saved prompts. Both are measured as a user sees them: from starting
`cap up` to the line "model ready" in its output (the graph's own start, the model's loading and the prompts).

Prints one JSON object per domain: `graph_s` (to lmp_node's "ready"), `model_ready_s` and the "model ready" line, for
the cold start and for `--starts - 1` warm ones.

Run: source scripts/env.sh && ROS_DOMAIN_ID=93 python benchmarks/model_ready.py [--domain tabletop] [--starts 3]
(set ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST, as for every graph; the model must be installed: make model)
"""
from __future__ import annotations

import argparse
import json
import os
import pathlib
import signal
import subprocess
import sys
import tempfile
import time

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
READY_LINE = '[lmp_node]: model ready'  # what `cap up` logs once the model has its prompts


def one_start(domain: str, env: dict[str, str], log: pathlib.Path, timeout_s: float) -> dict:
    started = time.monotonic()
    with open(log, 'w') as out:
        graph = subprocess.Popen([sys.executable, '-m', 'cap_bringup.cli', 'up', '--backend', 'local', '--domain',
                                  domain], stdout=out, stderr=subprocess.STDOUT, env=env, start_new_session=True)
    figures: dict = {}
    try:
        while time.monotonic() - started < timeout_s and graph.poll() is None:
            text = log.read_text(errors='replace')
            if 'graph_s' not in figures and '[lmp_node]: ready: domain' in text:
                figures['graph_s'] = round(time.monotonic() - started, 1)
            lines = [line for line in text.splitlines() if READY_LINE in line]
            if lines:
                figures['model_ready_s'] = round(time.monotonic() - started, 1)
                figures['line'] = lines[0].split(READY_LINE, 1)[1].strip(' :')
                break
            time.sleep(0.2)
    finally:
        if graph.poll() is None:
            os.killpg(graph.pid, signal.SIGINT)
        try:
            graph.wait(60)
        except subprocess.TimeoutExpired:
            os.killpg(graph.pid, signal.SIGKILL)
    if 'model_ready_s' not in figures:
        raise SystemExit(f'no "model ready" within {timeout_s:g} s; the output:\n{log.read_text()[-3000:]}')
    return figures


def main() -> None:
    from cap_lmp.local_model import default_model_path

    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--domain', default='tabletop')
    parser.add_argument('--starts', type=int, default=3, help='the cold start and starts-1 warm ones [3]')
    parser.add_argument('--timeout', type=float, default=1200.0, help='per start [1200 s]')
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix='cap-model-ready-') as folder:
        # a cache folder of its own (empty: the first start is cold), the installed model file
        env = {**os.environ, 'CAP_CACHE': folder, 'CAP_MODEL_FILE': str(default_model_path())}
        starts = [one_start(args.domain, env, pathlib.Path(folder) / f'start{index}.log', args.timeout)
                  for index in range(args.starts)]
    print(json.dumps({'domain': args.domain, 'cpus': len(os.sched_getaffinity(0)), 'cold': starts[0],
                      'warm': starts[1:]}, indent=2))


if __name__ == '__main__':
    main()
