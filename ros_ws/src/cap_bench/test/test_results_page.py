"""The results page: every benchmark's report shape read, a run kept with its facts, the page naming the command and
the folder of every figure."""
import json
import pathlib

import pytest

from cap_bench.results import keep_run, main, read_runs
from cap_bench.run_facts import failure_kind, invocation, run_facts


def _language_run(folder: pathlib.Path, *, with_run_block: bool) -> pathlib.Path:
    folder.mkdir(parents=True)
    records = [{'key': 'flat/a/0', 'passed': True, 'reason': '', 'prompt_tokens': 100, 'completion_tokens': 20},
               {'key': 'flat/b/0', 'passed': False, 'prompt_tokens': 90, 'completion_tokens': 30,
                'reason': "the test failed: AssertionError:  (line 7: `assert candidate('x') == 2`)"}]
    (folder / 'items.jsonl').write_text(''.join(json.dumps(record) + '\n' for record in records))
    report = {'title': 'HumanEval (2 problems), greedy (temperature 0)',
              'policy': 'model tiny.gguf at http://127.0.0.1:1/v1, chat API', 'notes': [], 'wall_s': 12.5,
              'rows': [{'variant': 'flat', 'group': 'all', 'items': 2, 'passed': 1, 'paper': 45.7,
                        'metric': 'greedy', 'value': None, 'percent': 50.0}]}
    if with_run_block:
        report['run'] = run_facts(records, 12.5, 'cap bench humaneval --policy llm --api chat')
    (folder / 'report.json').write_text(json.dumps(report))
    (folder / 'run.json').write_text(json.dumps({'benchmark': 'humaneval'}))
    return folder


def _tabletop_run(folder: pathlib.Path, feedback_rounds: int) -> pathlib.Path:
    folder.mkdir(parents=True)
    records = [{'key': 'UA-UI/line/0', 'success': False, 'reason': 'the model deadline of 120 s passed'},
               {'key': 'SA-SI/stack/0', 'success': True, 'reason': ''}]
    report = {'title': 'Table-top benchmark', 'policy': 'oracle: the reference program',
              'rows': [{'group': 'SA-SI', 'template': 'stack', 'trials': 1, 'successes': 1, 'percent': 100.0,
                        'paper': 94},
                       {'group': 'UA-UI', 'template': 'line', 'trials': 1, 'successes': 0, 'percent': 0.0,
                        'paper': 90}],
              'groups': {'SA-SI': {'trials': 1, 'successes': 1, 'percent': 100.0, 'paper': 94.3},
                         'UA-UI': {'trials': 1, 'successes': 0, 'percent': 0.0, 'paper': 71.0}},
              'overall': {'trials': 2, 'successes': 1, 'percent': 50.0},
              'run': run_facts(records, 61.0, 'cap bench tabletop --trials 1')}
    (folder / 'report.json').write_text(json.dumps(report))
    (folder / 'options.json').write_text(json.dumps({'feedback_rounds': feedback_rounds}))
    return folder


def test_the_run_block_counts_failures_by_kind_without_their_particulars():
    assert failure_kind("the test failed: AssertionError:  (line 7: `assert f('x') == 2`)") == \
        'the test failed: AssertionError'
    assert failure_kind('the model deadline of 120 s for one command passed') == \
        'the model deadline of N s for one command passed'
    assert failure_kind("there is no 'coke can' on the table") == 'there is no … on the table'
    facts = run_facts([{'passed': False, 'reason': 'x: ValueError: y'}, {'success': True, 'prompt_tokens': 3}], 2.04,
                      'cap bench x')
    assert facts == {'command': 'cap bench x', 'wall_s': 2.0, 'items': 2, 'passed': 1, 'prompt_tokens': 3,
                     'completion_tokens': 0, 'failure_kinds': {'x: ValueError': 1}, 'feedback_rounds': 0}
    assert invocation(['/some/bin/cap', 'bench', 'codegen', '--out', 'a b']) == "cap bench codegen --out 'a b'"


def test_a_report_without_a_run_block_is_kept_only_with_its_command(tmp_path):
    old = _language_run(tmp_path / 'runs' / 'he-old', with_run_block=False)
    with pytest.raises(ValueError, match='--command'):
        keep_run(old, tmp_path / 'results')
    kept = keep_run(old, tmp_path / 'results', 'cap bench humaneval --policy llm', 'the first chat run')
    report = json.loads((kept / 'report.json').read_text())
    assert report['run']['command'] == 'cap bench humaneval --policy llm' and report['run']['prompt_tokens'] == 190
    assert (kept / 'note.md').read_text().strip() == 'the first chat run' and not (kept / 'items.jsonl').exists()


def test_the_page_shows_each_run_beside_the_paper_with_its_command_and_folder(tmp_path, capsys):
    runs = tmp_path / 'runs'
    _language_run(runs / 'he-chat', with_run_block=True)
    _tabletop_run(runs / 'tt-oracle', 0)
    _tabletop_run(runs / 'tt-closed', 2)
    page = tmp_path / 'docs' / 'results.md'
    argv = ['--results', str(tmp_path / 'results'), '--page', str(page)]
    assert main(argv) == 1 and 'no runs kept' in capsys.readouterr().err
    assert main(['--add', str(runs / 'he-chat'), '--add', str(runs / 'tt-oracle'), '--add', str(runs / 'tt-closed'),
                 *argv]) == 0
    text = page.read_text()
    assert '| humaneval | flat, all | 45.7 | tiny (chat) | paper protocol | 50.0 (1/2) | 12 s | 190 + 50 |' in text
    assert '| tabletop | UA-UI | 71.0 | oracle | closed loop (2 feedback rounds) | 0.0 (0/1) | 1.0 min |' in text
    assert '`cap bench tabletop --trials 1`' in text and '[tt-closed](../results/tt-closed/report.md)' in text
    assert 'the test failed: AssertionError (1)' in text
    assert text.index('## tabletop') < text.index('## humaneval')  # the paper's order
    assert (page.parent / 'images' / 'results-tabletop.png').stat().st_size > 0
    assert [run.name for run in read_runs(tmp_path / 'results')] == ['he-chat', 'tt-closed', 'tt-oracle']
