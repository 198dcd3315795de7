"""The mobile kitchen's and the controllers' development sets: enough commands, worded their own way, each with a
reference program and a judge of the benchmark's."""
import pytest

from cap_bench.controllers import devset as controllers_devset, templates
from cap_bench.mobile import devset as mobile_devset
from cap_bench.mobile.episodes import TEMPLATES, oracle_program


def test_the_mobile_set_has_fifteen_commands_of_the_benchmarks_kinds_in_words_of_its_own():
    assert len(mobile_devset.COMMANDS) >= 15 and len(mobile_devset.BY_KEY) == len(mobile_devset.COMMANDS)
    assert set(mobile_devset.KINDS) <= set(TEMPLATES)
    for command in mobile_devset.COMMANDS:
        assert len(command.references) == len(command.instructions)
        for instruction in command.instructions:
            with pytest.raises(ValueError):
                oracle_program(instruction)  # the benchmark's own wording is what this parser reads
            compile(mobile_devset.reference_program(instruction), instruction, 'exec')


def test_mobile_episodes_hold_what_their_commands_need_with_unique_keys():
    episodes = mobile_devset.episodes(trials=2)
    assert len({episode.key for episode in episodes}) == len(episodes) == 2 * len(mobile_devset.COMMANDS)
    for episode, command in zip(episodes, mobile_devset.COMMANDS * 2):
        names = [thing.name for thing in episode.objects]
        assert all(name in names for name in command.must_have)
        assert episode.template == command.kind and episode.attributes['dev'] == command.key


def test_the_controllers_set_has_six_commands_none_a_benchmark_instruction():
    benchmark = {templates.episode(name, seed).instruction for name in templates.TEMPLATES for seed in range(50)}
    episodes = controllers_devset.episodes(trials=2)
    assert len(controllers_devset.COMMANDS) >= 6 and len({e.key for e in episodes}) == len(episodes)
    assert {e.template for e in controllers_devset.COMMANDS} == set(templates.TEMPLATES)
    for item in controllers_devset.COMMANDS:
        assert item.instruction not in benchmark and item.reference
        if item.template == templates.TRACK:
            assert f'{round(item.radius_m * 100)} cm' in item.instruction
