"""How far past its limits an attack program gets. Prints one JSON object.

Every attack of the limit tests (cap_lmp/testing/attack_programs.py: programs that loop, disable tracing, sit
in one C call or in GEOS, call the robot forever, or ask a slow model in a loop) runs once through IsolatedEngine,
as lmp_node runs it: a real sandbox process, the model a real HTTP server on 127.0.0.1, the robot the in-memory
table. For each: how long the command took, its overshoot past the limit that applies (time_limit_s, or for the
model loop model_time_limit_s plus the time limit), how it ended, and whether the next command moved the block.

    source scripts/env.sh && python benchmarks/limits.py [--time-limit 2.0]
"""
from __future__ import annotations

import argparse
import json
import time

import numpy as np

from cap_lmp.isolated_engine import KILL_MARGIN_S, IsolatedEngine
from cap_lmp.llm import OpenAICompatibleClient
from cap_lmp_ros.domains.tabletop.lmps import build_engine
from cap_lmp.sandbox import SandboxLimits
from cap_lmp.testing.attack_programs import MOVE, PROGRAMS, SCENE, TIME_ATTACKS
from cap_lmp.testing.openai_server import ScriptedOpenAIServer, ScriptedReply
from cap_lmp_ros.testing.table import Table

MODEL_LIMIT_S = 2.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--time-limit', type=float, default=2.0, help='time_limit_s of the sandbox [s]')
    options = parser.parse_args()
    table = Table.with_objects(SCENE)
    rows = {}
    with ScriptedOpenAIServer(PROGRAMS) as server:
        client = OpenAICompatibleClient(server.base_url, 'scripted-model', max_retries=0)
        engine = IsolatedEngine(build_engine, table.api(), client,
                                SandboxLimits(time_limit_s=options.time_limit), stall_limit_s=30.0,
                                model_time_limit_s=MODEL_LIMIT_S)
        try:
            attacks = {name: options.time_limit for name in TIME_ATTACKS}
            attacks['ask forever'] = MODEL_LIMIT_S  # against a model that takes 0.4 s per answer
            for command, limit in attacks.items():
                if command == 'ask forever':
                    server.push(ScriptedReply(), *[ScriptedReply(delay_s=0.4) for _ in range(20)])
                started = time.monotonic()
                result = engine.run(command)
                elapsed = time.monotonic() - started
                server._queue.clear()
                table.put_first_on_second('red block', SCENE['red block'])
                moved = engine.run(MOVE).success and bool(np.allclose(table.get_obj_pos('red block'),
                                                                       SCENE['red bowl']))
                rows[command] = {'elapsed_s': round(elapsed, 3), 'overshoot_s': round(elapsed - limit, 3),
                                 'stop_reason': result.stop_reason, 'model_s': round(result.timings['model_s'], 3),
                                 'session_kept': result.error_type != 'SandboxProcessLost',
                                 'next_command_moved_the_block': moved}
        finally:
            engine.close()
    worst = max(rows.items(), key=lambda item: item[1]['overshoot_s'])
    print(json.dumps({'time_limit_s': options.time_limit, 'model_time_limit_s': MODEL_LIMIT_S,
                      'kill_margin_s': KILL_MARGIN_S, 'worst_overshoot_s': worst[1]['overshoot_s'],
                      'worst_attack': worst[0], 'attacks': rows}, indent=2))


if __name__ == '__main__':
    main()
