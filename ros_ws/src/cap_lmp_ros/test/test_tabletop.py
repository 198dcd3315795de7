"""The table-top helpers generated code relies on, and the reference cassette kept in the repository."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import cap_lmp_ros.domains.tabletop as tabletop_domain
from cap_lmp.cassette import Cassette, CassetteClient
from cap_lmp_ros.domains.tabletop.lmps import build_engine, denormalize_xy, get_corner_name, get_side_name
from cap_lmp_ros.testing.table import Table

REFERENCE = Path(tabletop_domain.__file__).parent / 'cassettes' / 'tabletop_reference.yaml'


def test_normalised_coordinates_follow_the_paper():
    assert np.allclose(denormalize_xy([0, 0]), [-0.25, -0.75])
    assert np.allclose(denormalize_xy([1, 1]), [0.25, -0.25])
    assert np.allclose(denormalize_xy([0.5, 0.5]), [0.0, -0.5])


def test_corner_and_side_names():
    assert get_corner_name([-0.2, -0.3]) == 'top left corner'
    assert get_corner_name([0.2, -0.7]) == 'bottom right corner'
    assert get_side_name([0.0, -0.27]) == 'top side'
    assert get_side_name([-0.24, -0.5]) == 'left side'


def test_the_reference_cassette_states_its_provenance():
    cassette = Cassette.load(REFERENCE)
    assert len(cassette) >= 4
    assert all(entry.source == 'written by hand as a reference program' for entry in cassette.entries())


SCENE = {'blue block': (-0.15, -0.35), 'red block': (0.0, -0.4), 'green block': (0.15, -0.45),
         'blue bowl': (0.05, -0.65), 'red bowl': (-0.2, -0.7), 'green bowl': (0.2, -0.3)}


@pytest.mark.parametrize('command, expected', [
    ('put all the blocks in the bowls with matching colors',
     {'blue block': 'blue bowl', 'red block': 'red bowl', 'green block': 'green bowl'}),
    ('put the blocks in the green bowl', {'blue block': 'green bowl', 'red block': 'green bowl'}),
])
def test_reference_programs_replay_offline(command, expected):
    table = Table.with_objects(SCENE)
    result = build_engine(table.api(), CassetteClient(REFERENCE)).run(command)
    assert result.success, result.message
    for block, bowl in expected.items():
        assert np.allclose(table.get_obj_pos(block), table.get_obj_pos(bowl)), block


def test_stacking_reference_program_builds_one_stack():
    table = Table.with_objects(SCENE)
    result = build_engine(table.api(), CassetteClient(REFERENCE)).run('stack all the blocks')
    assert result.success, result.message
    blocks = [table.objects[name] for name in ('blue block', 'red block', 'green block')]
    assert all(np.allclose(block.xy, blocks[0].xy) for block in blocks)
    assert sorted(block.height for block in blocks) == pytest.approx([0.0, 0.04, 0.08])
