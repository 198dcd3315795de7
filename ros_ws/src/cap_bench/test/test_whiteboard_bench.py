"""The whiteboard benchmark's episodes, reference programs and ink checks, and the honesty of the prompts."""
import ast

import numpy as np
import pytest

from cap_bench.whiteboard import shapes
from cap_bench.whiteboard.episodes import CLEARANCE, TEMPLATES, oracle_program, sample_episode
from cap_bench.whiteboard.ink_check import check_drawing, check_erased
from cap_lmp_ros.domains.whiteboard.lmps import PROMPTS_DIR
from cap_whiteboard import board, objects
from cap_whiteboard.board import INK_HEIGHT, INK_WIDTH


def _ink_of(points: np.ndarray, offset: float = 0.0, width: float = 0.003) -> np.ndarray:
    """An ink image with the polyline drawn `width` wide, shifted by `offset` in y (pixel-centre test)."""
    ink = np.zeros((INK_HEIGHT, INK_WIDTH), np.uint8)
    centres = board.ink_pixel_centres().reshape(-1, 2)
    from cap_bench.whiteboard.ink_check import distance_to_polylines
    near = distance_to_polylines(centres, [points + [0.0, offset]]) <= width / 2
    ink.reshape(-1)[near] = 255
    return ink


@pytest.mark.parametrize('template', TEMPLATES)
def test_episodes_are_reproducible_on_the_board_and_keep_objects_clear_of_the_pen(template):
    for seed in range(6):
        episode = sample_episode(template, seed)
        again = sample_episode(template, seed)
        assert episode.instructions == again.instructions and episode.objects == again.objects
        for path in episode.drawn:
            assert all(board.on_board(x, y, board.DRAW_MARGIN) for x, y in path), episode.instructions
        around = episode.attributes.get('object')
        for obj in episode.objects:
            if obj.name == around:
                continue
            for path in episode.drawn:
                dense = np.vstack([np.linspace(a, b, 50) for a, b in zip(path[:-1], path[1:])])
                gap = np.min(np.linalg.norm(dense - obj.xy, axis=1)) - objects.footprint_radius(obj.name)
                assert gap >= CLEARANCE - 1e-9, (episode.key, obj.name)
        for instruction in episode.instructions:
            ast.parse(oracle_program(instruction))


def test_a_reference_program_depends_on_its_words_only():
    assert oracle_program('draw a circle around the apple').startswith("center = get_obj_pos('apple')")
    assert 'np.array([0.19, -0.36])' in oracle_program('draw a 6 cm hexagon at the top right corner')
    assert oracle_program('erase it') == 'erase(shape_pts)\n'
    with pytest.raises(ValueError):
        oracle_program('draw a happy face')


def test_the_checker_passes_a_true_drawing_and_fails_a_shifted_or_partial_one():
    square = shapes.polygon(board.MIDDLE, 0.08, 4)
    good = check_drawing(_ink_of(square), [square])
    assert good.success and good.p95_mm <= 1.6 and good.coverage == 1.0
    shifted = check_drawing(_ink_of(square, offset=0.004), [square])
    assert not shifted.success and 'strays' in shifted.reason
    half = check_drawing(_ink_of(square[:3]), [square])
    assert not half.success and 'of the target is inked' in half.reason
    assert not check_drawing(np.zeros((INK_HEIGHT, INK_WIDTH), np.uint8), [square]).success
    assert check_erased(np.zeros((INK_HEIGHT, INK_WIDTH), np.uint8)).success
    left = check_erased(_ink_of(square[:2]))
    assert not left.success and 'ink left' in left.reason


def test_no_prompt_holds_a_benchmark_instruction_or_a_demo_command():
    from cap_bringup.demos.whiteboard import STEPS
    prompts = ' '.join(path.read_text().lower() for path in PROMPTS_DIR.glob('*.txt'))
    instructions = {i.lower() for t in TEMPLATES for seed in range(20) for i in sample_episode(t, seed).instructions}
    instructions |= {step.command.lower() for step in STEPS}
    assert [i for i in instructions if i in prompts and i != 'erase it'] == []
