"""`cap bench results`: the results page (docs/results.md) written from the kept runs' report.json files.

A run is kept by `cap bench results --add RUN_FOLDER`: its report.json, report.md, report.png and settings (run.json of
the language-side benchmarks, options.json of the graph benchmarks) are copied to `results/<folder's name>/` in the
repository, so the page can be written again from what is committed. The page holds, per benchmark, the paper's
figure beside the oracle's and each model's, split by protocol (the paper's: one answer, no feedback; closed loop:
lmp_node's feedback rounds), with items, wall time, tokens, the failure kinds, the command and the run's folder.

Every report.json written now has a `run` block (cap_bench/run_facts.py). A run written before that gets it at
`--add` from its own records (items.jsonl or episodes*.jsonl), and the command must then be given (`--command`).
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import pathlib
import shutil
import sys
from typing import Any, Iterable, Mapping, Sequence

from cap_bench.charts import Bar, bar_chart
from cap_bench.run_facts import run_facts

NOTE_FILE = 'note.md'
KEPT_FILES = ('report.json', 'report.md', 'report.png', 'run.json', 'options.json')
RECORD_PATTERNS = ('items.jsonl', 'episodes*.jsonl')
# The paper's order of its tables; a benchmark not listed comes after them, by name.
ORDER = ('tabletop', 'codegen', 'humaneval', 'reasoning', 'whiteboard', 'mobile', 'controllers')
PAPER_MODEL = 'code-davinci-002'


@dataclasses.dataclass(frozen=True)
class Line:
    """One figure of a run: a label (variant, group or template), items, passed, %, the paper's %."""

    label: str
    items: int
    passed: int
    percent: float | None
    paper: float | None = None
    headline: bool = False  # a total the summary table shows


@dataclasses.dataclass(frozen=True)
class Run:
    name: str  # the folder's name under results/
    benchmark: str
    policy: str  # report.json's policy line
    protocol: str  # 'paper protocol' or 'closed loop (N feedback rounds)'
    lines: tuple[Line, ...]
    facts: Mapping[str, Any]  # the run block: command, wall_s, items, passed, tokens, failure kinds
    title: str

    note: str = ''  # what the person who kept the run wrote about it (note.md)

    @property
    def who(self) -> str:
        """'oracle', or the model's file or name with the protocol it was asked over: 'qwen2.5-... (chat)'."""
        if self.policy.startswith('oracle'):
            return 'oracle'
        model = self.policy.split(' at ')[0].removeprefix('model ').removesuffix('.gguf')
        api = next((word for word in ('chat', 'completions') if f'{word} API' in self.policy), '')
        if 'own system prompt' in self.policy:
            api += ", model's system prompt"
        return f'{model} ({api})' if api else model


# -- reading a run -------------------------------------------------------------------------------------------------
def _lines(report: Mapping[str, Any]) -> list[Line]:
    """The figures of any of the benchmarks' report shapes."""
    if 'groups' in report:  # the table top: templates in groups, the groups, overall
        lines = [Line(f"{row['group']} {row['template']}", row['trials'], row['successes'], row['percent'],
                      row.get('paper')) for row in report['rows']]
        lines += [Line(group, row['trials'], row['successes'], row['percent'], row.get('paper'), True)
                  for group, row in report['groups'].items()]
        overall = report['overall']
        return lines + [Line('all', overall['trials'], overall['successes'], overall['percent'], None, True)]
    if 'templates' in report:  # the controllers
        lines = [Line(row['template'], row['total'], row['passed'], row['percent'], row.get('paper_percent'))
                 for row in report['templates']]
        return lines + [Line('all', report['total'], report['passed'], report['percent'], None, True)]
    if 'overall' in report:  # per template: the whiteboard, the mobile kitchen
        lines = [Line(row['template'], row['trials'], row['successes'], row['percent']) for row in report['rows']]
        overall = report['overall']
        return lines + [Line('all', overall['trials'], overall['successes'], overall['percent'], None, True)]
    # the language side: variant x group
    return [Line(f"{row['variant']}, {row['group']}" + (f" ({row['metric']})" if row['metric'] not in
                                                         ('pass', 'greedy') else ''),
                 row['items'], row['passed'], row['percent'], row.get('paper'), row['group'] == 'all')
            for row in report['rows']]


def _settings(folder: pathlib.Path) -> dict[str, Any]:
    for name in ('run.json', 'options.json'):
        if (folder / name).is_file():
            return json.loads((folder / name).read_text(encoding='utf-8'))
    return {}


def _benchmark(report: Mapping[str, Any], settings: Mapping[str, Any]) -> str:
    words = str(report.get('run', {}).get('command', '')).split()
    if 'bench' in words[:-1]:
        name = words[words.index('bench') + 1]
        # a domain's development set (`--set dev`) is a table of its own
        return f'{name} development set' if '--set dev' in ' '.join(words) else name
    return str(settings.get('benchmark', '')) or 'unknown'


def _protocol(facts: Mapping[str, Any], settings: Mapping[str, Any]) -> str:
    # the records say it (run block); a run kept before they did, its settings (options.json)
    rounds = max(int(facts.get('feedback_rounds', 0) or 0), int(settings.get('feedback_rounds', 0) or 0))
    return f'closed loop ({rounds} feedback round{"s" if rounds > 1 else ""})' if rounds else 'paper protocol'


def read_run(folder: pathlib.Path) -> Run:
    report = json.loads((folder / 'report.json').read_text(encoding='utf-8'))
    if 'run' not in report:
        raise ValueError(f'{folder}/report.json has no run block: keep it with `cap bench results --add` '
                         '(and --command)')
    settings = _settings(folder)
    note = (folder / NOTE_FILE).read_text(encoding='utf-8').strip() if (folder / NOTE_FILE).is_file() else ''
    return Run(folder.name, _benchmark(report, settings), str(report.get('policy', '')),
               _protocol(report['run'], settings),
               tuple(_lines(report)), report['run'], str(report.get('title', '')), note)


def read_runs(root: pathlib.Path) -> list[Run]:
    folders = sorted(path.parent for path in root.glob('*/report.json'))
    return [read_run(folder) for folder in folders]


# -- keeping a run -------------------------------------------------------------------------------------------------
def _records(folder: pathlib.Path) -> list[dict[str, Any]]:
    records: list[dict[str, Any]] = []
    for pattern in RECORD_PATTERNS:
        for path in sorted(folder.glob(pattern)):
            records += [json.loads(line) for line in path.read_text(encoding='utf-8').splitlines() if line.strip()]
    return records


def keep_run(folder: pathlib.Path, root: pathlib.Path, command: str = '', note: str = '') -> pathlib.Path:
    """Copy a run's report and settings to root/<its name>; a report without a run block gets one from its
    records, with `command` (required then: the page names the command of every figure); `note`: words on the run
    for the page (note.md)."""
    report = json.loads((folder / 'report.json').read_text(encoding='utf-8'))
    if 'run' not in report:
        if not command:
            raise ValueError(f'{folder}/report.json predates the run block: give the command that ran it (--command)')
        records = _records(folder)
        if not records:
            raise ValueError(f'{folder} holds no records (items.jsonl, episodes*.jsonl) to count the run from')
        wall = report.get('wall_s', report.get('wall_seconds', 0.0))
        report['run'] = run_facts(records, float(wall), command)
    target = root / folder.resolve().name
    target.mkdir(parents=True, exist_ok=True)
    if note:
        (target / NOTE_FILE).write_text(note.strip() + '\n', encoding='utf-8')
    for kept in KEPT_FILES:
        if (folder / kept).is_file() and kept != 'report.json':
            shutil.copyfile(folder / kept, target / kept)
    (target / 'report.json').write_text(json.dumps(report, indent=2), encoding='utf-8')
    return target


# -- the page ------------------------------------------------------------------------------------------------------
def _percent(value: float | None) -> str:
    return '—' if value is None else f'{value:.1f}'


def _figure(line: Line) -> str:
    return f'{_percent(line.percent)} ({line.passed}/{line.items})'


def _tokens(run: Run) -> str:
    """A model's tokens; none for the oracle (its server's counts are not a model's)."""
    prompt, completion = int(run.facts.get('prompt_tokens', 0)), int(run.facts.get('completion_tokens', 0))
    return f'{prompt:,} + {completion:,}' if (prompt or completion) and run.who != 'oracle' else '—'


def _minutes(seconds: float) -> str:
    return f'{seconds / 60:.1f} min' if seconds >= 60 else f'{seconds:.0f} s'


def _by_benchmark(runs: Iterable[Run]) -> dict[str, list[Run]]:
    grouped: dict[str, list[Run]] = {}
    for run in sorted(runs, key=lambda run: (run.who != 'oracle', run.name)):  # the oracle first
        grouped.setdefault(run.benchmark, []).append(run)
    order = {name: index for index, name in enumerate(ORDER)}
    return dict(sorted(grouped.items(), key=lambda item: (order.get(item[0], len(ORDER)), item[0])))


def _chart(path: pathlib.Path, benchmark: str, runs: Sequence[Run]) -> None:
    """Headline figures of every run of a benchmark, the paper's beside them."""
    bars = [Bar(f'{run.name}: {line.label}'[:44], line.percent, line.paper,  # the run's folder names it
                f'{line.passed}/{line.items}', line.label == 'all' or line.label.endswith(', all'))
            for run in runs for line in run.lines if line.headline]
    bar_chart(path, [f'cap bench {benchmark}: every kept run', 'blue: the run; gray: the paper'], bars)


def page(runs: Sequence[Run], image_dir: pathlib.Path, page_dir: pathlib.Path) -> str:
    """docs/results.md's text; draws one chart per benchmark into image_dir."""
    out = ['# Results', '',
           'Written by `cap bench results` from the runs kept in `results/` (each folder: report.json, report.md, '
           'report.png and the run\'s settings); do not edit by hand. A run is kept with '
           '`cap bench results --add RUN_FOLDER`. Figures are success %, with passed / items; the paper\'s are '
           f'Code as Policies\' own ({PAPER_MODEL}). All runs on one 2-core machine without GPU. "Paper protocol": '
           'one greedy answer per command, no feedback; "closed loop": lmp_node\'s feedback rounds.', '',
           '## Summary', '',
           '| benchmark | headline | paper | run by | protocol | figure | wall | tokens (prompt + completion) | '
           'run |', '|---|---|---|---|---|---|---|---|---|']
    grouped = _by_benchmark(runs)
    for benchmark, mine in grouped.items():
        for run in mine:
            for line in run.lines:
                if line.headline:
                    out.append(f'| {benchmark} | {line.label} | {_percent(line.paper)} | {run.who} | '
                               f'{run.protocol} | {_figure(line)} | {_minutes(float(run.facts["wall_s"]))} | '
                               f'{_tokens(run)} | [{run.name}](../results/{run.name}/report.md) |')
    for benchmark, mine in grouped.items():
        image = image_dir / f"results-{benchmark.replace(' ', '-')}.png"
        _chart(image, benchmark, mine)
        out += ['', f'## {benchmark}', '', f'![{benchmark}]({image.relative_to(page_dir).as_posix()})', '']
        labels = list(dict.fromkeys(line.label for run in mine for line in run.lines))
        out += ['| | paper | ' + ' | '.join(f'{run.who}, {run.protocol} ([{run.name}])' for run in mine) + ' |',
                '|---|---|' + '---|' * len(mine)]
        for label in labels:
            cells = []
            paper = None
            for run in mine:
                line = next((item for item in run.lines if item.label == label), None)
                cells.append('' if line is None else _figure(line))
                paper = paper if line is None or line.paper is None else line.paper
            name = f'**{label}**' if label == 'all' or label.endswith(', all') else label
            out.append(f'| {name} | {_percent(paper)} | ' + ' | '.join(cells) + ' |')
        out.append('')
        for run in mine:
            facts = run.facts
            failures = ', '.join(f'{kind} ({count})' for kind, count in list(facts['failure_kinds'].items())[:6])
            out += [f'[{run.name}]: ../results/{run.name}/report.md',
                    f'- **{run.name}** ({run.title}): `{facts["command"]}`; {facts["items"]} items, '
                    f'{_minutes(float(facts["wall_s"]))}, tokens {_tokens(run)}'
                    + (f'; failures: {failures}' if failures else '') + '.' + (f' {run.note}' if run.note else '')]
    return '\n'.join(out) + '\n'


def write_page(root: pathlib.Path, page_path: pathlib.Path) -> int:
    runs = read_runs(root)
    if not runs:
        raise ValueError(f'no runs kept in {root}: keep one with `cap bench results --add RUN_FOLDER`')
    image_dir = page_path.parent / 'images'
    image_dir.mkdir(parents=True, exist_ok=True)
    page_path.write_text(page(runs, image_dir, page_path.parent), encoding='utf-8')
    return len(runs)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog='cap bench results',
                                     description='Write the results page (docs/results.md) from the kept runs.')
    parser.add_argument('--add', type=pathlib.Path, action='append', default=[],
                        help='keep this run folder first (repeatable): copied to RESULTS/<its name>')
    parser.add_argument('--command', default='', help='with one --add of a report without a run block: the '
                        'command that ran it')
    parser.add_argument('--note', default='', help='with one --add: words on the run, shown with it on the page')
    parser.add_argument('--results', type=pathlib.Path, default=pathlib.Path('results'),
                        help='the kept runs [results]')
    parser.add_argument('--page', type=pathlib.Path, default=pathlib.Path('docs/results.md'),
                        help='the page to write [docs/results.md]')
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        if (args.command or args.note) and len(args.add) != 1:
            raise ValueError('--command and --note go with one --add')
        for folder in args.add:
            print(f'kept {folder} as {keep_run(folder, args.results, args.command, args.note)}')
        count = write_page(args.results, args.page)
    except (OSError, ValueError, KeyError, json.JSONDecodeError) as error:
        print(f'cap bench results: error: {error}', file=sys.stderr)
        return 1
    print(f'{args.page}: {count} run(s) from {args.results}/')
    return 0


if __name__ == '__main__':
    sys.exit(main())
