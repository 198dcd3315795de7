"""The table-top benchmark through the real graph: one episode of every row with the oracle programs, and a few
episodes with the programs coming from an OpenAI-protocol endpoint."""
import json

import pytest

from cap_bench.tabletop.bench import load_records, run_benchmark
from cap_bench.tabletop.options import TabletopOptions
from cap_bench.tabletop.oracle import oracle_program
from cap_bench.tabletop.sampling import sample_episode
from cap_lmp.testing.openai_server import ScriptedOpenAIServer, last_query_line


@pytest.mark.slow
def test_one_oracle_episode_per_task_and_group(ros_isolation, tmp_path):
    summary = run_benchmark(TabletopOptions(trials=1, out=str(tmp_path), first_domain_id=int(ros_isolation)),
                            show_progress=False)
    records = load_records(tmp_path)
    assert len(records) == 22 == summary['episodes']
    failures = [(r['key'], r['reason']) for r in records if not r['success']]
    assert all(reason for _, reason in failures), 'every failure carries a reason'
    assert failures == []
    assert (tmp_path / 'report.md').read_text().count('\n| ') >= 22
    assert (tmp_path / 'report.png').stat().st_size > 1000
    report = json.loads((tmp_path / 'report.json').read_text())
    assert report['overall']['percent'] == 100.0
    assert report['policy'].startswith('oracle') and 'oracle programs' in report['title']
    assert 'Policy: oracle' in (tmp_path / 'report.md').read_text()


@pytest.mark.slow
def test_llm_policy_runs_episodes_end_to_end_against_an_endpoint(ros_isolation, tmp_path):
    tasks = ('pick_place', 'blocks_in_bowl')
    programs = {}
    for task in tasks:
        episode = sample_episode('SA-SI', task, 0)
        programs[episode.instruction.lower()] = oracle_program(episode)

    def responder(request):
        query = last_query_line(request.prompt).lstrip('# ').rstrip('.').lower()
        return programs.get(query)

    with ScriptedOpenAIServer(responder=responder) as server:
        summary = run_benchmark(TabletopOptions(policy='llm', groups=('SA-SI',), tasks=tasks, trials=1,
                                                out=str(tmp_path), base_url=server.base_url, model=server.model,
                                                first_domain_id=int(ros_isolation)), show_progress=False)
        asked = [last_query_line(r.prompt) for r in server.requests]
    records = load_records(tmp_path)
    assert [r['success'] for r in records] == [True, True], [r['reason'] for r in records]
    assert all(r['model_calls'] >= 1 for r in records)
    assert len(asked) == 2
    assert summary['overall']['percent'] == 100.0
