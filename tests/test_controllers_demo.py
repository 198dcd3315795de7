"""The controllers demo through the whole graph (simulator, controller_node, lmp_node and its sandbox over DDS) with
the controllers domain's reference cassette: every command does what it asks, judged on the simulator's state."""
from cap_bringup.demos.controllers import STEPS, run_demo


def test_the_controllers_demo_balances_the_pole_holds_the_pushed_tool_and_moves_it_round(tmp_path):
    summary = run_demo(tmp_path / 'demo', log=lambda *_: None)
    failed = [(s['command'], s['problems']) for s in summary['steps'] if not s['as_expected']]
    assert failed == []
    assert [s['command'] for s in summary['steps']] == [step.command for step in STEPS]
    assert summary['all_as_expected'] and summary['commands'] == len(STEPS) == 4
    # Each controller ran its whole time: 30 s of balance, 10 s of holding, 10 s round the circle.
    assert [round(s.get('controller_seconds', 0.0), 1) for s in summary['steps']] == [0.0, 30.0, 10.0, 10.0]
    assert summary['video_frames'] > 0 and (tmp_path / 'demo' / 'demo.mp4').stat().st_size > 10_000
    assert (tmp_path / 'demo' / 'summary.json').is_file()
