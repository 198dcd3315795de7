"""The whiteboard's ink image: strokes of the tip's width, wipes of the pad's footprint (the physics that lays them
is tested with the path planner, in cap_control's test_whiteboard_ink.py)."""
import numpy as np
import pytest

from cap_sim_bridge.ink import InkCanvas
from cap_sim_bridge.scenes.whiteboard import INK


def test_a_stroke_is_the_tips_width_with_round_ends():
    canvas = InkCanvas(INK)
    canvas.draw_stroke(np.array([-0.1, -0.5005]), np.array([0.1, -0.5005]))  # along a row of pixel centres
    image = canvas.image()
    columns = np.nonzero(image.any(axis=0))[0]
    rows = np.nonzero(image.any(axis=1))[0]
    assert len(rows) == 3  # 3 mm wide: the centre row and one on each side
    assert -0.25 + columns.min() * 0.001 == pytest.approx(-0.1015, abs=0.001)
    assert -0.25 + (columns.max() + 1) * 0.001 == pytest.approx(0.1015, abs=0.001)
    version = canvas.version
    canvas.wipe(np.array([[-0.2, -0.45], [0.0, -0.45], [0.0, -0.55], [-0.2, -0.55]]))
    assert canvas.version > version
    assert np.nonzero(canvas.image().any(axis=0))[0].min() * 0.001 - 0.25 == pytest.approx(0.0, abs=0.0015)
