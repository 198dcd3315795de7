"""cap_sim_render writes a PNG per camera that shows the scene's objects in their colours."""
import subprocess
import sys

import cv2
import numpy as np

from cap_sim_bridge.render_cli import main
from cap_tabletop.palette import PALETTE as COLORS


def test_render_writes_one_png_per_camera_with_the_objects_colours(tmp_path, capsys):
    assert main(['--seed', '3', '--objects', 'red block, blue bowl', '--out', str(tmp_path), '--width', '320',
                 '--height', '240', '--depth']) == 0
    written = capsys.readouterr().out.split()
    assert sorted(p.rsplit('/', 1)[1] for p in written) == ['seed3_front.png', 'seed3_front_depth.png',
                                                            'seed3_top.png', 'seed3_top_depth.png']
    top = cv2.cvtColor(cv2.imread(str(tmp_path / 'seed3_top.png')), cv2.COLOR_BGR2RGB)
    assert top.shape == (240, 320, 3)
    for colour in ('red', 'blue'):
        # Pixels within a small distance of the palette colour, allowing for shading.
        close = np.linalg.norm(top.astype(float) - COLORS[colour], axis=2) < 40
        assert close.sum() > 30, colour


def test_render_refuses_unknown_objects_with_a_message(tmp_path):
    process = subprocess.run([sys.executable, '-m', 'cap_sim_bridge.render_cli', '--objects', 'violet block',
                              '--out', str(tmp_path)], capture_output=True, text=True)
    assert process.returncode == 2 and 'violet' in process.stderr
    assert not list(tmp_path.iterdir())
