"""The demos as plug-ins: every module of demos/ is a demo found by its name (the shared modules are not), `cap demo`
runs one by name or lists them, and a demo another package offers runs the same way; the controllers demo's checks
judge what a person would see."""
from __future__ import annotations

import pathlib
import types

import numpy as np
import pytest

from cap_bringup import cli
from cap_bringup.demos import DEFAULT_DEMO, DEMOS, ENTRY_POINT_GROUP

DEMOS_DIR = pathlib.Path(__file__).resolve().parents[1] / 'cap_bringup' / 'demos'
TOY_DEMO = '''
def main(argv):
    print('toy demo ran with', list(argv))
    return 7
'''


def test_every_module_of_the_demos_folder_is_a_demo_and_the_shared_ones_are_not():
    modules = sorted(path.stem for path in DEMOS_DIR.glob('*.py') if not path.stem.startswith('_'))
    assert modules == ['controllers', 'mobile', 'tabletop', 'whiteboard']
    assert set(modules) <= set(DEMOS.names())
    assert DEFAULT_DEMO in modules
    for name in modules:
        main = DEMOS.get(name)
        assert callable(main) and main.__module__ == f'cap_bringup.demos.{name}'


def test_an_unknown_demo_is_one_error_line_naming_the_known_ones(capsys):
    assert cli.main(['demo', 'spaceship']) == cli.EXIT_UNREACHABLE
    error = capsys.readouterr().err.strip()
    assert len(error.splitlines()) == 1
    assert "unknown demo 'spaceship'" in error and 'tabletop' in error and 'controllers' in error


def test_cap_demo_help_lists_every_demo(capsys):
    assert cli.main(['demo', '--help']) == cli.EXIT_OK
    shown = capsys.readouterr().out
    assert 'usage: cap demo [NAME]' in shown
    for name in DEMOS.names():
        assert f'\n  {name}' in shown
    assert 'tabletop (default)' in shown


def test_a_demo_of_another_package_runs_by_its_name_with_its_options(install_plugin, capsys):
    install_plugin({'toy_demo': TOY_DEMO}, {ENTRY_POINT_GROUP: {'toy': 'toy_demo:main'}})
    assert cli.main(['demo', 'toy', '--', '--fast']) == 7
    assert "toy demo ran with ['--fast']" in capsys.readouterr().out


# ------------------------------------------------------------------------------------- the controllers demo's checks
def _seen(times, lean=None, tool=None, said=(), run=None, pushed_at=None, failure=''):
    from cap_bringup.demos.controllers import Seen

    times = np.asarray(times, dtype=float)
    lean = np.zeros(len(times)) if lean is None else np.asarray(lean, dtype=float)
    tool = np.zeros((len(times), 3)) if tool is None else np.asarray(tool, dtype=float)
    return Seen(times, np.zeros(len(times)), lean, tool, list(said), failure, run, pushed_at)


def _run(start: float, seconds: float):
    return types.SimpleNamespace(start_time=start, simulated_time=seconds, calls=int(seconds * 100))


def test_the_lean_said_must_be_the_poles():
    from cap_bringup.demos.controllers import _says_the_lean

    held = _seen([0.0, 0.5], lean=[np.radians(-1.3)] * 2, said=['The pole leans -1.3 degrees'])
    assert _says_the_lean(held) == ''
    wrong = _seen([0.0, 0.5], lean=[np.radians(-1.3)] * 2, said=['The pole leans 4.0 degrees'])
    assert 'but the pole leans -1.30 degrees' in _says_the_lean(wrong)


def test_a_balanced_pole_stays_within_twelve_degrees_for_the_whole_run_and_a_fall_after_it_does_not_count():
    from cap_bringup.demos.controllers import _balanced

    times = np.arange(0.0, 33.0, 0.01)
    lean = np.where(times < 31.05, 0.02 * np.sin(times), 1.2)  # falls once the run (1..31 s) is over
    assert _balanced(30.0)(_seen(times, lean, run=_run(1.0, 30.0))) == ''
    assert 'ran 4.20 s of 30' in _balanced(30.0)(_seen(times, lean, run=_run(1.0, 4.2)))
    leaning = np.where((times > 10) & (times < 10.5), 0.3, 0.0)
    assert 'the pole leaned 17.19 degrees' in _balanced(30.0)(_seen(times, leaning, run=_run(1.0, 30.0)))
    assert _balanced(30.0)(_seen(times, lean, failure='refused')) == 'refused'


def test_a_held_tool_must_yield_to_the_push_and_come_back():
    from cap_bringup.demos.controllers import _held_under_push

    times = np.arange(0.0, 10.0, 0.01)
    pushed = (times >= 2.0) & (times < 3.0)  # the run starts at 1 s, the push one second later
    back = np.zeros((len(times), 3))
    back[pushed, 1] = 0.04
    assert _held_under_push('+y')(_seen(times, tool=back, run=_run(1.0, 8.0), pushed_at=2.0)) == ''
    stays = back.copy()
    stays[times >= 3.0, 1] = 0.03
    assert 'mm from its goal' in _held_under_push('+y')(_seen(times, tool=stays, run=_run(1.0, 8.0), pushed_at=2.0))
    assert _held_under_push('+y')(_seen(times, tool=back, run=_run(1.0, 8.0))) == 'the run ended before the push'


def test_a_circle_is_judged_on_the_tools_path():
    from cap_bringup.demos.controllers import _went_round
    from cap_controllers.judging import circle_goal

    times = np.arange(0.0, 12.0, 0.01)
    start = np.array([0.0, -0.45, 0.35])
    round_ = np.array([circle_goal(0.04, start, max(t - 1.0, 0.0)) for t in times])
    assert _went_round(0.04, 10.0)(_seen(times, tool=round_, run=_run(1.0, 10.0))) == ''
    still = np.tile(start, (len(times), 1))
    assert 'RMS error' in _went_round(0.04, 10.0)(_seen(times, tool=still, run=_run(1.0, 10.0)))


@pytest.mark.parametrize('name', ['tabletop', 'whiteboard', 'mobile', 'controllers'])
def test_every_demo_takes_the_common_options(name, capsys):
    with pytest.raises(SystemExit) as ended:
        DEMOS.get(name)(['--help'])
    assert ended.value.code == 0
    shown = capsys.readouterr().out
    for option in ('--out', '--backend', '--cassette', '--no-video'):
        assert option in shown
