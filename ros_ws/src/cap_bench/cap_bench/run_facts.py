"""What every benchmark's report.json says about its run, whatever the benchmark: the command that ran it, its wall
time, items, passed, tokens and failures by kind. The results page (cap_bench/results.py) reads these, so a figure
there always names the command and the run that printed it."""
from __future__ import annotations

import collections
import pathlib
import re
import shlex
import sys
from typing import Any, Mapping, Sequence

_EXCEPTION = re.compile(r'\s*([A-Z]\w*(?:Error|Exception|Exceeded|Stopped|Rejected|Refusal|Timeout))\b')
_NUMBER = re.compile(r'-?\d+(?:\.\d+)?')
_QUOTED = re.compile(r"'[^']*'|\"[^\"]*\"|`[^`]*`")


def invocation(argv: Sequence[str] | None = None) -> str:
    """The command line as typed: `cap bench humaneval --policy llm ...`."""
    argv = list(sys.argv if argv is None else argv)
    return shlex.join([pathlib.Path(argv[0]).name, *argv[1:]]) if argv else ''


def failure_kind(reason: str) -> str:
    """A failure's kind, for counting: the reason's first clause, with the exception it names, numbers and quoted
    names left out ('the test failed: AssertionError'; 'the completion did not run: the code calls …')."""
    head, _, rest = reason.partition(':')
    exception = _EXCEPTION.match(rest)
    kind = head + (f': {exception.group(1)}' if exception else '')
    kind = _NUMBER.sub('N', _QUOTED.sub('…', kind)).strip()
    return (kind[:77] + '...') if len(kind) > 80 else (kind or 'no reason given')


def _passed(record: Mapping[str, Any]) -> bool:
    return bool(record.get('passed', record.get('success', False)))


def run_facts(records: Sequence[Mapping[str, Any]], wall_s: float, command: str | None = None) -> dict[str, Any]:
    """The `run` block of report.json."""
    failures = collections.Counter(failure_kind(str(record.get('reason', ''))) for record in records
                                   if not _passed(record))
    return {'command': invocation() if command is None else command, 'wall_s': round(float(wall_s), 1),
            'items': len(records), 'passed': sum(_passed(record) for record in records),
            'prompt_tokens': sum(int(record.get('prompt_tokens', 0) or 0) for record in records),
            'completion_tokens': sum(int(record.get('completion_tokens', 0) or 0) for record in records),
            'failure_kinds': dict(failures.most_common()),
            # lmp_node's feedback rounds (0: the paper's protocol, one answer per command)
            'feedback_rounds': max((int(record.get('feedback_rounds', 0) or 0) for record in records), default=0)}
