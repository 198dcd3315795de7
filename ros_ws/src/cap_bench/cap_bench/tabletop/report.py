"""Benchmark report: per-row success rates beside the paper's, as Markdown, JSON and a bar chart (PNG)."""
from __future__ import annotations

import json
import pathlib
from typing import Iterable, Mapping

from cap_bench.charts import Bar, bar_chart
from cap_bench.run_facts import run_facts
from cap_bench.tabletop.templates import GROUPS

# The Code as Policies paper's simulated table-top results (code-davinci-002), % success per row.
PAPER: dict[str, dict[str, float]] = {
    'SA-SI': {'pick_place': 100, 'stack': 94, 'blocks_on_corner': 92, 'blocks_in_bowl': 100, 'matching_bowls': 100,
              'block_by_direction': 72, 'block_by_distance': 98, 'nth_block': 98},
    'UA-SI': {'pick_place': 100, 'stack': 100, 'blocks_on_corner': 100, 'blocks_in_bowl': 96,
              'matching_bowls': 92, 'block_by_direction': 60, 'block_by_distance': 100, 'nth_block': 60},
    'UA-UI': {'different_corners': 98, 'mismatched_bowls': 60, 'stack_on_corner': 82, 'place_by_magnitude': 38,
              'corner_by_distance': 58, 'line': 90},
}
PAPER_TOTALS = {'SA-SI': 94.3, 'UA-SI': 88.5, 'UA-UI': 71.0}


def summarise(records: Iterable[Mapping]) -> dict:
    """Rows (group, template) -> {'trials', 'successes', 'percent', 'paper'}; plus group and overall totals."""
    rows: dict[tuple[str, str], list[bool]] = {}
    for record in records:
        rows.setdefault((record['group'], record['template']), []).append(bool(record['success']))
    table = []
    for group, (_, templates) in GROUPS.items():
        for template in templates:
            outcomes = rows.get((group, template), [])
            table.append({'group': group, 'template': template, 'trials': len(outcomes),
                          'successes': sum(outcomes),
                          'percent': 100.0 * sum(outcomes) / len(outcomes) if outcomes else None,
                          'paper': PAPER[group][template]})
    groups = {}
    for group in GROUPS:
        done = [r for r in table if r['group'] == group and r['trials']]
        trials = sum(r['trials'] for r in done)
        groups[group] = {'trials': trials, 'successes': sum(r['successes'] for r in done),
                         'percent': 100.0 * sum(r['successes'] for r in done) / trials if trials else None,
                         'paper': PAPER_TOTALS[group]}
    trials = sum(r['trials'] for r in table)
    successes = sum(r['successes'] for r in table)
    return {'rows': table, 'groups': groups, 'overall': {
        'trials': trials, 'successes': successes, 'percent': 100.0 * successes / trials if trials else None}}


def _percent(value: float | None) -> str:
    return '—' if value is None else f'{value:.1f}'


def markdown(summary: Mapping, title: str, policy: str = '') -> str:
    lines = [f'# {title}', ''] + ([f'Policy: {policy}', ''] if policy else [])
    lines += ['| group | task | trials | this run % | paper (CaP) % |', '|---|---|---|---|---|']
    for row in (r for r in summary['rows'] if r['trials']):
        lines.append(f"| {row['group']} | {row['template']} | {row['trials']} | {_percent(row['percent'])} | "
                     f"{row['paper']:.0f} |")
    for group, totals in ((g, t) for g, t in summary['groups'].items() if t['trials']):
        lines.append(f"| **{group}** | total | {totals['trials']} | **{_percent(totals['percent'])}** | "
                     f"{totals['paper']:.1f} |")
    overall = summary['overall']
    lines.append(f"| **all** | | {overall['trials']} | **{_percent(overall['percent'])}** | |")
    return '\n'.join(lines) + '\n'


def chart(summary: Mapping, path: pathlib.Path, title_lines: list[str]) -> None:
    """Bars per row, then the group totals and the overall figure, with the run's title and policy on top."""
    rows = [r for r in summary['rows'] if r['trials']] or summary['rows']
    bars = [Bar(f"{row['group']} {row['template']}", row['percent'], row['paper'],
                f"{row['successes']}/{row['trials']}") for row in rows]
    bars += [Bar(f'{group} total', totals['percent'], totals['paper'], f"{totals['successes']}/{totals['trials']}",
                 bold=True) for group, totals in summary['groups'].items() if totals['trials']]
    overall = summary['overall']
    bars.append(Bar('all', overall['percent'], None, f"{overall['successes']}/{overall['trials']}", bold=True))
    bar_chart(path, title_lines, bars)


def write_report(records: list[Mapping], out_dir: pathlib.Path, title: str, policy: str = '',
                 wall_s: float = 0.0) -> dict:
    """report.json, report.md and report.png; `policy` names who wrote the programs (oracle or which model),
    `wall_s` the run's wall time."""
    summary = summarise(records)
    summary.update(title=title, policy=policy, run=run_facts(records, wall_s))
    (out_dir / 'report.json').write_text(json.dumps(summary, indent=2))
    (out_dir / 'report.md').write_text(markdown(summary, title, policy))
    chart(summary, out_dir / 'report.png', [title] + ([f'policy: {policy}'] if policy else []))
    return summary
