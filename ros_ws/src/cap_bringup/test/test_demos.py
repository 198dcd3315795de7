"""The demos as plug-ins: every module of demos/ is a demo found by its name (the shared modules are not), `cap demo`
runs one by name or lists them, and a demo another package offers runs the same way."""
from __future__ import annotations

import pathlib

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
    assert modules == ['mobile', 'tabletop', 'whiteboard']
    assert set(modules) <= set(DEMOS.names())
    assert DEFAULT_DEMO in modules
    for name in modules:
        main = DEMOS.get(name)
        assert callable(main) and main.__module__ == f'cap_bringup.demos.{name}'


def test_an_unknown_demo_is_one_error_line_naming_the_known_ones(capsys):
    assert cli.main(['demo', 'spaceship']) == cli.EXIT_UNREACHABLE
    error = capsys.readouterr().err.strip()
    assert len(error.splitlines()) == 1
    assert "unknown demo 'spaceship'" in error and 'tabletop' in error and 'mobile' in error


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


@pytest.mark.parametrize('name', ['tabletop', 'whiteboard', 'mobile'])
def test_every_demo_takes_the_common_options(name, capsys):
    with pytest.raises(SystemExit) as ended:
        DEMOS.get(name)(['--help'])
    assert ended.value.code == 0
    shown = capsys.readouterr().out
    for option in ('--out', '--backend', '--cassette', '--no-video'):
        assert option in shown
