"""Reports of the language-side benchmarks: report.json, report.md and report.png, titled with the policy."""
from __future__ import annotations

import json
import pathlib
from dataclasses import asdict, dataclass
from typing import Any, Mapping, Sequence

from cap_bench.charts import Bar, bar_chart
from cap_bench.run_facts import run_facts


@dataclass(frozen=True)
class ReportRow:
    """One line of a report: items of a group under one variant, passed, beside the paper's figure."""

    variant: str  # e.g. 'hierarchical prompt, hierarchical generation'
    group: str  # e.g. 'numpy', or 'all'
    items: int
    passed: int
    paper: float | None = None  # the paper's %, when it has one for this line
    metric: str = 'pass'  # what `percent` measures, e.g. 'pass@1'
    value: float | None = None  # the metric in %, when not passed / items (pass@k)

    @property
    def percent(self) -> float | None:
        if self.value is not None:
            return self.value
        return 100.0 * self.passed / self.items if self.items else None


def _percent(value: float | None) -> str:
    return '—' if value is None else f'{value:.1f}'


def _chart_label(row: ReportRow) -> str:
    """A label that fits the chart's margin: 'hier. prompt, flat gen. numpy'."""
    variant = row.variant.replace('hierarchical', 'hier.').replace('generation', 'gen.')
    metric = f' {row.metric}' if row.metric.startswith('pass@') else ''
    return f'{variant} {row.group}{metric}'.strip()


def write_report(out_dir: pathlib.Path, title: str, policy: str, rows: Sequence[ReportRow],
                 notes: Sequence[str] = (), extra: Mapping[str, Any] | None = None,
                 records: Sequence[Mapping[str, Any]] = ()) -> dict[str, Any]:
    """Write the three files; return what report.json holds (with the run's facts from `records`)."""
    extra = dict(extra or {})
    summary = {'title': title, 'policy': policy, 'rows': [{**asdict(row), 'percent': row.percent} for row in rows],
               'notes': list(notes), **extra, 'run': run_facts(records, extra.get('wall_s', 0.0))}
    (out_dir / 'report.json').write_text(json.dumps(summary, indent=2), encoding='utf-8')
    lines = [f'# {title}', '', f'Policy: {policy}', '',
             '| variant | group | metric | items | passed | this run % | paper % |', '|---|---|---|---|---|---|---|']
    for row in rows:
        name = f'**{row.group}**' if row.group == 'all' else row.group
        lines.append(f'| {row.variant} | {name} | {row.metric} | {row.items} | {row.passed} | '
                     f'{_percent(row.percent)} | {_percent(row.paper)} |')
    if notes:
        lines += [''] + [f'- {note}' for note in notes]
    (out_dir / 'report.md').write_text('\n'.join(lines) + '\n', encoding='utf-8')
    bars = [Bar(_chart_label(row), row.percent, row.paper,
                f'n={row.items}' if row.metric.startswith('pass@') else f'{row.passed}/{row.items}', row.group == 'all')
            for row in rows]
    bar_chart(out_dir / 'report.png', [title, f'policy: {policy}'], bars)
    return summary
