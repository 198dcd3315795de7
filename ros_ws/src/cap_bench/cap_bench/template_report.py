"""The report of a benchmark counted per instruction template (the whiteboard's, the mobile kitchen's): passed /
trials per template and overall, the figures the benchmark adds per template, its criteria, each failure's reason;
written as report.json and report.md, with a bar chart (report.png) where the benchmark draws one."""
from __future__ import annotations

import json
import pathlib
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from cap_bench.charts import Bar, bar_chart
from cap_bench.run_facts import run_facts


def summarise(records: Sequence[dict], templates: Sequence[str], title: str, policy: str,
              criteria: Mapping[str, float], wall_seconds: float,
              figures: Callable[[list[dict]], dict[str, Any]]) -> dict:
    """Per template (in the order of `templates`, those with records) and overall: passed / trials, and the
    benchmark's `figures(records of the template)`; the run's wall time and each failure's reason."""
    rows = []
    for template in templates:
        mine = [r for r in records if r['template'] == template]
        if mine:
            rows.append({'template': template, 'trials': len(mine), 'successes': sum(r['success'] for r in mine),
                         'percent': 100.0 * sum(r['success'] for r in mine) / len(mine), **figures(mine)})
    total, passed = len(records), sum(r['success'] for r in records)
    return {'title': title, 'policy': policy, 'criteria': dict(criteria),
            'rows': rows, 'overall': {'trials': total, 'successes': passed,
                                      'percent': 100.0 * passed / total if total else None},
            'wall_seconds': round(wall_seconds, 1),
            'episode_wall_seconds_median': float(np.median([r['wall_seconds'] for r in records])) if records else 0,
            'failures': {r['key']: r['reason'] for r in records if not r['success']},
            'run': run_facts(records, wall_seconds)}


def _figure(value: float | None, form: str) -> str:
    return '—' if value is None else format(value, form)


def write_report(summary: dict, out: pathlib.Path, columns: Sequence[tuple[str, str, str]], note: str = '') -> None:
    """report.json and report.md: a table of the templates with the benchmark's `columns` (header, row field,
    format) after passed %, `note` (what passing means) above it, the failures below."""
    (out / 'report.json').write_text(json.dumps(summary, indent=2), encoding='utf-8')
    lines = [f"# {summary['title']}", '', f"Policy: {summary['policy']}", ''] + ([note, ''] if note else [])
    lines += ['| template | trials | passed % | ' + ''.join(f'{header} | ' for header, _, _ in columns).rstrip(),
              '|---|---|---|' + '---|' * len(columns)]
    for row in summary['rows']:
        lines.append(f"| {row['template']} | {row['trials']} | {row['percent']:.1f} | "
                     + ''.join(f'{_figure(row[field], form)} | ' for _, field, form in columns).rstrip())
    overall = summary['overall']
    lines.append(f"| **all** | {overall['trials']} | **{_figure(overall['percent'], '.1f')}** |" + ' |' * len(columns))
    if summary['failures']:
        lines += ['', '## Failures', ''] + [f'- `{key}`: {reason}' for key, reason in summary['failures'].items()]
    (out / 'report.md').write_text('\n'.join(lines) + '\n', encoding='utf-8')


def draw_chart(summary: dict, path: pathlib.Path) -> None:
    """report.png: a bar per template and one for all, titled with the run and its policy."""
    bars = [Bar(row['template'], row['percent'], None, f"{row['successes']}/{row['trials']}")
            for row in summary['rows']]
    overall = summary['overall']
    bars.append(Bar('all', overall['percent'], None, f"{overall['successes']}/{overall['trials']}", bold=True))
    bar_chart(path, [summary['title'], f"policy: {summary['policy']}"], bars)
