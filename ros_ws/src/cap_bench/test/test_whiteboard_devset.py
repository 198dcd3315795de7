"""The whiteboard's development set: its own commands (none renders a benchmark template), a reference for each
instruction, objects clear of every path, targets on the board."""
import numpy as np
import pytest
from cap_whiteboard import board

from cap_bench.whiteboard import devset
from cap_bench.whiteboard.episodes import CLEARANCE, oracle_program
from cap_whiteboard.objects import footprint_radius


def test_at_least_fifteen_commands_none_of_them_a_benchmark_template():
    assert len(devset.COMMANDS) >= 15 and len(devset.BY_KEY) == len(devset.COMMANDS)
    for command in devset.COMMANDS:
        for instruction in command.instructions:
            with pytest.raises((ValueError, IndexError)):
                oracle_program(instruction)  # the benchmark's own wording is what this parser reads


def test_every_instruction_has_a_reference_that_compiles():
    for command in devset.COMMANDS:
        assert len(command.references) == len(command.instructions)
        for instruction in command.instructions:
            compile(devset.reference_program(instruction), instruction, 'exec')


def test_objects_stand_clear_of_every_path_and_the_targets_lie_on_the_board():
    for episode in devset.episodes(trials=2):
        dense = np.vstack([np.linspace(a, b, 50) for path in episode.drawn for a, b in zip(path[:-1], path[1:])])
        for thing in episode.objects:
            gap = np.min(np.linalg.norm(dense - thing.xy, axis=1))
            assert gap >= footprint_radius(thing.name) + CLEARANCE - 1e-9, (episode.key, thing.name)
        for target in episode.targets:
            assert all(board.on_board(x, y, board.DRAW_MARGIN) for x, y in target), episode.key
    assert {e.key for e in devset.episodes(trials=2)} >= {'house/0', 'house/1'}
