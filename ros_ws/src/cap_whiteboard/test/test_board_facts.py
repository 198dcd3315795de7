import numpy as np

from cap_whiteboard import board, objects, tool


def test_named_places_leave_room_for_a_ten_centimetre_shape_on_the_board():
    for name, (x, y) in board.PLACES.items():
        assert board.on_board(x - 0.05, y - 0.05, board.DRAW_MARGIN), name
        assert board.on_board(x + 0.05, y + 0.05, board.DRAW_MARGIN), name
    assert np.allclose(board.NORMALISED_ORIGIN + 0.5 * board.NORMALISED_SPAN, board.MIDDLE)


def test_ink_pixels_map_to_the_board_one_millimetre_each():
    assert (board.INK_HEIGHT, board.INK_WIDTH) == (400, 500)
    centres = board.ink_pixel_centres()
    assert np.allclose(centres[0, 0], (board.X_RANGE[0] + 0.0005, board.Y_RANGE[1] - 0.0005))  # top left
    assert np.allclose(board.world_to_ink(centres[123, 456]), (123, 456))


def test_the_tool_frames_point_into_the_board():
    marker, eraser = tool.flange_to_tool(tool.TOOL_MARKER), tool.flange_to_tool(tool.TOOL_ERASER)
    assert np.allclose(marker[:3, 3], (0, 0, tool.MARKER_TIP_OFFSET)) and np.allclose(marker[:3, :3], np.eye(3))
    assert np.allclose(eraser[:3, 2], (1, 0, 0))  # the pad faces along the flange's +x
    assert np.isclose(np.linalg.det(eraser[:3, :3]), 1.0)
    for name in tool.TOOLS:
        low, high = tool.compression_band(name)
        assert low < tool.press_depth(name) < high


def test_default_objects_are_two_blocks_and_two_fruit_and_fit_the_spawn_region():
    for seed in range(20):
        chosen = objects.default_objects(seed)
        assert [category == 'block' for _, category, _ in chosen] == [True, True, False, False]
        assert len({name for name, _, _ in chosen}) == 4
    for x in objects.SPAWN_X_RANGE:
        for y in objects.SPAWN_Y_RANGE:
            assert board.on_board(x, y, margin=0.06)
