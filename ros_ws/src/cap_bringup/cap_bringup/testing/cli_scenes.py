"""Programs for tests of the `cap` command line and of the graph's shutdown, written into a cassette.

    cassette = write_cli_cassette(tmp_path / 'cli.yaml')   # then: cap up --cassette <cassette>

Each query answers any scene ('*'): the programs need no particular objects.
"""
from __future__ import annotations

import pathlib

from cap_lmp.cassette import ANY_CONTEXT, Cassette, CassetteEntry

# A program that runs until it is stopped (well within the default time limit of a test).
ENDLESS = 'spin forever'
# A program whose code and said line hold terminal control sequences (colour, bell, carriage return).
CONTROL_CHARACTERS = 'say something colourful'
HELLO = 'say hello'

PROGRAMS = {
    ENDLESS: 'n = 0\nwhile True:\n    n += 1',
    # Raw ESC and BEL in the code itself; the said line also gets a carriage return (from the escape in the code).
    CONTROL_CHARACTERS: 'say("\x1b[31mred\x1b[0m, a bell \x07, a return \\r done")',
    HELLO: 'say("hello")',
}


def write_cli_cassette(path: pathlib.Path) -> pathlib.Path:
    cassette = Cassette(path, [CassetteEntry(lmp='tabletop_ui', query=query, context=ANY_CONTEXT, completion=code,
                                             source='written by hand for the command-line tests')
                               for query, code in PROGRAMS.items()])
    cassette.save()
    return path
