"""How a controller's run is judged: a balance needs the whole run and, where the lean was recorded, a pole within
the limit."""
import numpy as np

from cap_controllers import judging, plants


def test_a_balance_needs_the_whole_run_and_a_pole_that_stayed_within_the_limit():
    assert judging.judge_balance(30.0, 30.0, '').success
    assert judging.judge_balance(30.0, 30.0, '', np.full(10, 0.9 * plants.POLE_ANGLE_LIMIT)).success
    short = judging.judge_balance(30.0, 4.2, '')
    assert not short.success and short.reason == 'ran 4.20 s of 30'
    fallen = judging.judge_balance(30.0, 30.0, '', [0.0, -1.1 * plants.POLE_ANGLE_LIMIT])
    assert not fallen.success and fallen.reason == 'the pole leaned 13.2 degrees'
    assert fallen.figures['max_lean_deg'] == 13.2
    stopped = judging.judge_balance(30.0, 3.0, 'the pole leaned 12.3 degrees')
    assert not stopped.success and stopped.reason == 'the pole leaned 12.3 degrees'
