"""Benchmark report: per-row success rates beside the paper's, as Markdown, JSON and a bar chart (PNG)."""
from __future__ import annotations

import json
import pathlib
from typing import Iterable, Mapping

import cv2
import numpy as np

from cap_bench.templates import GROUPS

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


def markdown(summary: Mapping, title: str) -> str:
    lines = [f'# {title}', '', '| group | task | trials | this run % | paper (CaP) % |', '|---|---|---|---|---|']
    for row in (r for r in summary['rows'] if r['trials']):
        lines.append(f"| {row['group']} | {row['template']} | {row['trials']} | {_percent(row['percent'])} | "
                     f"{row['paper']:.0f} |")
    for group, totals in ((g, t) for g, t in summary['groups'].items() if t['trials']):
        lines.append(f"| **{group}** | total | {totals['trials']} | **{_percent(totals['percent'])}** | "
                     f"{totals['paper']:.1f} |")
    overall = summary['overall']
    lines.append(f"| **all** | | {overall['trials']} | **{_percent(overall['percent'])}** | |")
    return '\n'.join(lines) + '\n'


def chart(summary: Mapping, path: pathlib.Path) -> None:
    """Horizontal bars per row: this run (blue) above the paper (gray)."""
    rows = [r for r in summary['rows'] if r['trials']] or summary['rows']
    row_height, left, width = 26, 260, 460
    image = np.full((row_height * len(rows) + 60, left + width + 60, 3), 255, np.uint8)
    cv2.putText(image, 'success % (blue: this run, gray: paper)', (10, 22), cv2.FONT_HERSHEY_SIMPLEX, 0.55,
                (0, 0, 0), 1, cv2.LINE_AA)
    for i, row in enumerate(rows):
        y = 40 + i * row_height
        cv2.putText(image, f"{row['group']} {row['template']}", (10, y + 16), cv2.FONT_HERSHEY_SIMPLEX, 0.45,
                    (0, 0, 0), 1, cv2.LINE_AA)
        paper = int(width * row['paper'] / 100)
        cv2.rectangle(image, (left, y + 12), (left + paper, y + 20), (170, 170, 170), -1)
        if row['percent'] is not None:
            ours = int(width * row['percent'] / 100)
            cv2.rectangle(image, (left, y + 2), (left + ours, y + 11), (167, 121, 78), -1)
            cv2.putText(image, f"{row['percent']:.0f}", (left + ours + 4, y + 11), cv2.FONT_HERSHEY_SIMPLEX, 0.35,
                        (0, 0, 0), 1, cv2.LINE_AA)
    cv2.imwrite(str(path), image)


def write_report(records: list[Mapping], out_dir: pathlib.Path, title: str) -> dict:
    summary = summarise(records)
    (out_dir / 'report.json').write_text(json.dumps(summary, indent=2))
    (out_dir / 'report.md').write_text(markdown(summary, title))
    chart(summary, out_dir / 'report.png')
    return summary
