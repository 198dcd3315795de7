"""Every reference program, run in the sandbox against a table model, leaves a state its checker accepts."""
import numpy as np
import pytest
import shapely

from cap_bench.tabletop.oracle import oracle_program
from cap_bench.tabletop.sampling import sample_episode
from cap_bench.tabletop.success import check
from cap_bench.tabletop.templates import GROUPS
from cap_lmp.sandbox import Sandbox
from cap_lmp_ros.domains.tabletop.lmps import denormalize_xy
from cap_lmp_ros.testing.table import Table

ROWS = [(group, template) for group, (_, templates) in GROUPS.items() for template in templates]


def _positions(table, episode):
    # The table model keeps the base height of each object; blocks are 4 cm cubes.
    return {name: (*table.objects[name].xy, table.objects[name].height + (0.02 if name.endswith('block') else 0.0))
            for name in (o.name for o in episode.objects)}


@pytest.mark.parametrize('group, template', ROWS)
def test_reference_program_succeeds_on_a_table_model(group, template):
    sandbox = Sandbox()
    for seed in range(10):
        episode = sample_episode(group, template, seed)
        table = Table.with_objects({o.name: o.xy for o in episode.objects})
        initial = _positions(table, episode)
        api = table.api()
        api.update(np=np, shapely=shapely, denormalize_xy=denormalize_xy)
        program = sandbox.compile(oracle_program(episode), f'oracle {template}')
        sandbox.execute(program, sandbox.new_scope(api))
        verdict = check(episode, initial, _positions(table, episode))
        assert verdict.success, f'{episode.instruction} (seed {seed}): {verdict.reason}'
