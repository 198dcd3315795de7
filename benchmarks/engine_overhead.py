"""Engine overhead per command, model time excluded. Prints one JSON object.

A typical table-top command ("put all the blocks in the bowls with matching colors") runs through the full engine
path with the real tabletop_ui prompt (30+ examples): context line from the robot API, prompt assembly, the model
call (answered by a hand-written replay cassette, and its time subtracted), AST check, function discovery and one
generated function, rewrite and compile, sandbox setup and execution including the nested parse_obj_name LMP calls
(each with its own prompt, check and execution), against an in-memory table. The session is reset before every
command so each one pays the same work.

It measures the same command twice: with the engine in this process, and through IsolatedEngine, as lmp_node runs
it (the session in a sandbox process; robot API calls and engine events cross a socket as JSON messages).

    source scripts/env.sh && python benchmarks/engine_overhead.py [--n 300]
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import tempfile
import time
from pathlib import Path

from cap_lmp.cassette import HAND_WRITTEN, Cassette, CassetteClient, CassetteEntry
from cap_lmp.prompts import load_prompt
from cap_lmp_ros.domains.tabletop.lmps import PROMPTS_DIR
from cap_lmp.sandbox import SandboxLimits
from cap_lmp_ros.domains.tabletop.lmps import build_engine
from cap_lmp_ros.testing.table import Table

SCENE = {'blue block': (-0.15, -0.35), 'red block': (0.0, -0.4), 'green block': (0.15, -0.45),
         'yellow block': (-0.1, -0.55), 'blue bowl': (0.05, -0.65), 'red bowl': (-0.2, -0.7),
         'green bowl': (0.2, -0.3), 'yellow bowl': (0.15, -0.6)}
COMMAND = 'put all the blocks in the bowls with matching colors'
MAIN = '''block_names = parse_obj_name('the blocks', f'objects = {get_obj_names()}')
for block_name in block_names:
    bowl_name = parse_obj_name(f'the bowl with the same color as the {block_name}', f'objects = {get_obj_names()}')
    if bowl_name and not is_in(block_name, bowl_name):
        put_first_on_second(block_name, bowl_name)
say(f'Done: {len(block_names)} blocks are in their bowls')'''
IS_IN = '''def is_in(obj_name, container_name, tol=0.06):
    return float(np.linalg.norm(get_obj_pos(obj_name) - get_obj_pos(container_name))) < tol'''
BLOCKS = "ret_val = [name for name in objects if 'block' in name]"


def cassette_entries() -> list[CassetteEntry]:
    entries = [CassetteEntry('tabletop_ui', COMMAND, '*', MAIN, HAND_WRITTEN),
               CassetteEntry('parse_obj_name', 'the blocks', '*', BLOCKS, HAND_WRITTEN),
               CassetteEntry('fgen', 'define function: is_in(block_name, bowl_name)', '', IS_IN, HAND_WRITTEN)]
    for name in SCENE:
        if name.endswith('block'):
            color = name.split()[0]
            entries.append(CassetteEntry('parse_obj_name', f'the bowl with the same color as the {name}', '*',
                                         f"ret_val = '{color} bowl'", HAND_WRITTEN))
    return entries


def percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    index = min(len(ordered) - 1, max(0, round(q / 100 * (len(ordered) - 1))))
    return ordered[index]


def stop_overshoot_ms(runs: int = 5, limit_s: float = 0.2) -> float:
    """How long after the time limit an infinite loop is stopped (median over runs)."""
    from cap_lmp.errors import ExecutionStopped
    from cap_lmp.sandbox import Sandbox

    sandbox = Sandbox(SandboxLimits(time_limit_s=limit_s))
    program = sandbox.compile('while True:\n    pass')
    overshoots = []
    for _ in range(runs):
        started = time.monotonic()
        try:
            sandbox.execute(program, sandbox.new_scope({}))
        except ExecutionStopped:
            overshoots.append((time.monotonic() - started - limit_s) * 1000)
    return statistics.median(overshoots)


def summary(values: list[float]) -> dict[str, float]:
    return {'p50': round(percentile(values, 50), 3), 'p90': round(percentile(values, 90), 3),
            'p99': round(percentile(values, 99), 3), 'mean': round(statistics.mean(values), 3)}


def isolated_overhead_ms(path: Path, n: int, warmup: int) -> dict:
    """Overhead per command through IsolatedEngine: wall time of run() minus the model time the sandbox reports."""
    from cap_lmp.isolated_engine import IsolatedEngine
    from cap_lmp_ros.domains.tabletop.lmps import build_engine

    current = {'table': Table.with_objects(SCENE)}

    def bound(name: str):
        return lambda *args, **kwargs: getattr(current['table'], name)(*args, **kwargs)

    api = {name: bound(name) for name in current['table'].api()}
    engine = IsolatedEngine(build_engine, api, CassetteClient(path))
    overhead_ms = []
    try:
        for i in range(warmup + n):
            current['table'] = Table.with_objects(SCENE)
            engine.reset()
            started = time.perf_counter()
            result = engine.run(COMMAND)
            wall = time.perf_counter() - started
            if not result.success:
                raise SystemExit(f'benchmark command failed in the sandbox process: {result.message}')
            if i >= warmup:
                overhead_ms.append((wall - result.timings['model_s']) * 1000)
    finally:
        engine.close()
    return summary(overhead_ms)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--n', type=int, default=300, help='measured commands')
    parser.add_argument('--warmup', type=int, default=20)
    args = parser.parse_args()

    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / 'benchmark.yaml'
        Cassette(path, cassette_entries()).save()
        table = Table.with_objects(SCENE)
        engine = build_engine(table.api(), CassetteClient(path))
        overhead_ms, total_ms, model_ms, execute_ms = [], [], [], []
        calls = 0
        for i in range(args.warmup + args.n):
            table = Table.with_objects(SCENE)
            engine.api.update(table.api())
            engine.reset()  # a new session, bound to the fresh table
            result = engine.run(COMMAND)
            if not result.success:
                raise SystemExit(f'benchmark command failed: {result.message}')
            if i >= args.warmup:
                overhead_ms.append(result.timings['overhead_s'] * 1000)
                total_ms.append(result.timings['total_s'] * 1000)
                model_ms.append(result.timings['model_s'] * 1000)
                execute_ms.append(result.timings['execute_s'] * 1000)
                calls = result.model_calls
        moved = all(abs(table.get_obj_pos(f'{c} block') - table.get_obj_pos(f'{c} bowl')).max() < 1e-9
                    for c in ('blue', 'red', 'green', 'yellow'))
        isolated = isolated_overhead_ms(path, args.n, args.warmup)
    prompt = load_prompt(PROMPTS_DIR, 'tabletop_ui')
    print(json.dumps({
        'benchmark': 'engine_overhead',
        'measured': ('wall time of Engine.run for one table-top command minus the time inside the LLM client: '
                     'context line, prompt assembly, AST check, function discovery (1 generated function), rewrite '
                     'and compile, sandbox scope setup and execution of the program with its nested LMP calls '
                     f'({calls} model calls per command, answered by a replay cassette) against an in-memory table'),
        'command': COMMAND,
        'n': args.n,
        'overhead_ms': summary(overhead_ms),
        'overhead_ms_sandbox_process': isolated,
        'execute_ms_p50': round(percentile(execute_ms, 50), 3),
        'model_ms_p50': round(percentile(model_ms, 50), 3),
        'total_ms_p50': round(percentile(total_ms, 50), 3),
        'model_calls_per_command': calls,
        'tabletop_ui_prompt': {'examples': prompt.count('\nobjects = ['), 'chars': len(prompt)},
        'blocks_in_matching_bowls': moved,
        'infinite_loop_stop_after_limit_ms_p50': round(stop_overshoot_ms(), 3),
        'load_average_1min': round(os.getloadavg()[0], 2),
        'target': 'overhead p50 <= 5 ms',
        'target_met': percentile(overhead_ms, 50) <= 5.0 and isolated['p50'] <= 5.0,
    }, indent=2))


if __name__ == '__main__':
    main()
