"""The table-top development set: its references satisfy its judges, its scenes are sound, it stays clear of the
benchmark's unseen attributes and templates, and two commands pass through the real graph with the oracle."""
import itertools
import json
import re

import numpy as np
import pytest

from cap_bench.tabletop import table
from cap_bench.devset.bench import item_record, main, run_devset, summarise, write_oracle_cassette
from cap_bench.devset.commands import COMMANDS, DevCommand, select
from cap_bench.tabletop.options import TabletopOptions
from cap_bench.tabletop.templates import ATTRIBUTE_POOLS, SEEN_COLORS, TEMPLATES, UNSEEN_TEMPLATES
from cap_lmp.cassette import Cassette
from cap_lmp.sandbox import Sandbox
from cap_lmp_ros.testing.table import Table
from cap_tabletop.objects import BLOCK_SIZE
from cap_tabletop.workspace import on_table

# Centre distances a fixed scene keeps (bowls are about 14 cm across the rim, blocks 4 cm).
MIN_APART = {('block', 'block'): 0.10, ('block', 'bowl'): 0.12, ('bowl', 'bowl'): 0.15}
# A point a reference sets a block down on keeps this far from the centre of every other object.
POINT_CLEAR_OF = {'block': 0.06, 'bowl': 0.10}
# Words for unseen attribute values a dev instruction must not use either.
UNSEEN_SYNONYMS = ('furthest', 'down', 'lowest', 'rightmost', 'diagonally', 'a lot')

IDS = [command.key for command in COMMANDS]


def _state(tabletop: Table, command: DevCommand) -> dict[str, tuple[float, float, float]]:
    # The table model keeps each object's base height; a block's centre is half a block above it.
    return {o.name: (*tabletop.objects[o.name].xy, tabletop.objects[o.name].height
                     + (BLOCK_SIZE / 2 if o.category == 'block' else 0.0)) for o in command.objects}


def _run_references(command: DevCommand) -> tuple[dict, dict, Table]:
    """Initial and final state of the command's scene after its reference programs ran in one sandbox scope."""
    tabletop = Table.with_objects({o.name: o.xy for o in command.objects})
    place = tabletop.put_first_on_second

    def put_first_on_second(obj_name, target):
        # Like the controller: a point target lies on the table, clear of the other objects.
        if not isinstance(target, str):
            xy = np.asarray(target, dtype=float)[:2]
            assert on_table(*xy, margin=BLOCK_SIZE), f'{command.key}: {obj_name} set down at {xy}, off the table'
            for name, other in tabletop.objects.items():
                gap = float(np.linalg.norm(other.xy - xy))
                assert name == obj_name or gap >= POINT_CLEAR_OF[other.kind], \
                    f'{command.key}: {obj_name} set down {gap:.3f} m from the {name}'
        place(obj_name, target)

    sandbox = Sandbox()
    initial = _state(tabletop, command)
    scope = sandbox.new_scope({**tabletop.api(), 'put_first_on_second': put_first_on_second, 'np': np})
    for index, program in enumerate(command.reference):
        sandbox.execute(sandbox.compile(program, f'{command.key} reference {index}'), scope)
    return initial, _state(tabletop, command), tabletop


def test_the_set_has_over_twenty_commands_with_distinct_keys_and_instructions():
    assert len(COMMANDS) >= 20
    assert len({c.key for c in COMMANDS}) == len(COMMANDS)
    # One cassette entry per instruction: no two commands may send the same text.
    instructions = [' '.join(i.lower().split()).rstrip('.') for c in COMMANDS for i in c.instructions]
    assert len(set(instructions)) == len(instructions)
    assert all(len(c.reference) == len(c.instructions) for c in COMMANDS)
    assert any(len(c.instructions) > 1 for c in COMMANDS), 'an item refers back to an earlier instruction'


@pytest.mark.parametrize('command', COMMANDS, ids=IDS)
def test_scene_is_on_the_table_spread_out_and_small(command):
    assert 3 <= len(command.objects) <= 6
    assert len({o.name for o in command.objects}) == len(command.objects)
    for obj in command.objects:
        assert obj.color in SEEN_COLORS and obj.name == f'{obj.color} {obj.category}'
        assert table.SPAWN_X[0] <= obj.xy[0] <= table.SPAWN_X[1] and table.SPAWN_Y[0] <= obj.xy[1] <= table.SPAWN_Y[1]
    for a, b in itertools.combinations(command.objects, 2):
        gap = float(np.hypot(a.xy[0] - b.xy[0], a.xy[1] - b.xy[1]))
        if gap == 0.0 and {a.category, b.category} == {'block', 'bowl'}:
            continue  # a block lying in a bowl
        assert gap >= MIN_APART[tuple(sorted((a.category, b.category)))], f'{a.name} and {b.name}: {gap:.3f} m'


def test_some_scenes_start_with_a_block_in_a_bowl():
    def has_block_in_bowl(command):
        return any(a.xy == b.xy for a, b in itertools.combinations(command.objects, 2))
    assert sum(has_block_in_bowl(c) for c in COMMANDS) >= 2


@pytest.mark.parametrize('command', COMMANDS, ids=IDS)
def test_reference_meets_the_judge_and_the_initial_state_does_not(command):
    initial, final, _ = _run_references(command)
    verdict = command.judge(initial, final)
    assert verdict.success, verdict.reason
    untouched = command.judge(initial, initial)
    assert not untouched.success and untouched.reason


@pytest.mark.parametrize('command', COMMANDS, ids=IDS)
def test_judge_names_an_object_that_moved_out_of_place(command):
    initial, final, _ = _run_references(command)
    still = next(name for name in final if np.allclose(final[name][:2], initial[name][:2]))
    pushed = dict(final)
    pushed[still] = (final[still][0] + 0.1, final[still][1], final[still][2])
    verdict = command.judge(initial, pushed)
    assert not verdict.success and still in verdict.reason


def test_judge_reports_missing_objects():
    command = COMMANDS[0]
    initial, final, _ = _run_references(command)
    gone = command.objects[0].name
    verdict = command.judge(initial, {k: v for k, v in final.items() if k != gone})
    assert not verdict.success and gone in verdict.reason


def _masked(text: str) -> str:
    """The instruction without the seen attribute values (so 'top right corner' does not read as 'right')."""
    text = text.lower()
    seen = sorted((v for values, _ in ATTRIBUTE_POOLS.values() for v in values), key=len, reverse=True)
    for value in seen:
        text = re.sub(rf'\b{re.escape(value)}\b', ' ', text)
    return text


def _template_pattern(text: str) -> str:
    parts = re.split(r'\{\w+\}', text.lower())
    return '.+'.join(re.escape(part) for part in parts)


@pytest.mark.parametrize('command', COMMANDS, ids=IDS)
def test_instructions_use_no_unseen_attribute_and_no_benchmark_template(command):
    unseen = [v for _, values in ATTRIBUTE_POOLS.values() for v in values] + list(UNSEEN_SYNONYMS)
    seen_texts = [t.text.lower() for t in TEMPLATES.values() if t.seen]
    for instruction in command.instructions:
        masked = _masked(instruction)
        assert not [v for v in unseen if re.search(rf'\b{re.escape(v)}\b', masked)], instruction
        for template in TEMPLATES.values():
            assert not re.fullmatch(_template_pattern(template.text), instruction.lower().rstrip('.')), \
                f'{instruction!r} renders the {template.key} template'
        for key in UNSEEN_TEMPLATES:
            for fragment in re.split(r'\{\w+\}', TEMPLATES[key].text.lower()):
                fragment = fragment.strip()
                if fragment and not any(fragment in text for text in seen_texts):
                    assert not re.search(rf'\b{re.escape(fragment)}\b', instruction.lower()), \
                        f'{instruction!r} uses "{fragment}" of the unseen {key} template'


def test_the_honesty_check_catches_unseen_words():
    assert re.search(r'\bright\b', _masked('move it to the right'))
    assert not re.search(r'\bright\b', _masked('put it in the top right corner'))
    assert re.search(r'\bbottom\b', _masked('the bottom right corner'))


def test_oracle_cassette_answers_every_instruction(tmp_path):
    path = tmp_path / 'cassette.yaml'
    write_oracle_cassette(COMMANDS, path)
    cassette = Cassette.load(path)
    assert len(cassette) == sum(len(c.instructions) for c in COMMANDS)
    for command in COMMANDS:
        for instruction, program in zip(command.instructions, command.reference):
            entry = cassette.find('tabletop_ui', instruction.capitalize() + '.', "objects = ['any']")
            assert entry is not None and entry.completion == program


def test_select_keeps_the_order_asked_and_refuses_unknown_keys():
    assert [c.key for c in select(['swap', 'tower'])] == ['swap', 'tower']
    assert select([]) == COMMANDS
    with pytest.raises(KeyError, match='no_such'):
        select(['swap', 'no_such'])


def test_cli_refuses_an_unknown_command_before_starting_anything(tmp_path, capsys):
    assert main(['--commands', 'no_such', '--out', str(tmp_path)]) == 2
    assert 'no_such' in capsys.readouterr().err
    assert not list(tmp_path.iterdir())


def test_summary_counts_passes_and_lists_failures():
    command = COMMANDS[0]
    good = item_record(command, {'success': True, 'wall_seconds': 2.5, 'model_calls': 1})
    bad = item_record(COMMANDS[1], {'success': False, 'reason': 'the final state is wrong: x'})
    summary = summarise(TabletopOptions(policy='oracle'), [good, bad], 10.0)
    assert (summary['passed'], summary['total'], summary['rate']) == (1, 2, 0.5)
    assert summary['failures'] == {COMMANDS[1].key: 'the final state is wrong: x'}
    assert good['instructions'] == list(command.instructions) and good['latency_s'] == 2.5


@pytest.mark.graph
def test_two_commands_pass_through_the_graph_with_the_oracle(ros_isolation, tmp_path):
    commands = select(['bowl_by_name', 'undo_last'])  # one single instruction, one three-instruction session
    summary = run_devset(TabletopOptions(out=str(tmp_path), first_domain_id=int(ros_isolation)), commands)
    items = [json.loads(line) for line in (tmp_path / 'items.jsonl').read_text().splitlines()]
    assert [item['key'] for item in items] == ['bowl_by_name', 'undo_last']
    assert all(item['success'] for item in items), summary['failures']
    assert (summary['passed'], summary['total'], summary['failures']) == (2, 2, {})
    assert items[1]['code'].count('# ---') == 2
    assert json.loads((tmp_path / 'summary.json').read_text()) == summary
