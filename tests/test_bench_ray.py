"""`cap bench tabletop --executor ray`: the same episodes as the local executor, on a Ray instance of the run's own
(started on 127.0.0.1, stopped at the end), with the same records, report and --resume."""
import json

from cap_bench.tabletop.bench import load_records, run_benchmark
from cap_bench.tabletop.options import TabletopOptions

# Four episodes for two jobs taking them from one queue: every task brings up a graph and streams records back.
TASKS = ('pick_place', 'stack')


def _run(out, executor: str, domain_id: int, resume: bool = False) -> dict:
    return run_benchmark(TabletopOptions(groups=('SA-SI',), tasks=TASKS, trials=2, jobs=2, out=str(out),
                                         executor=executor, resume=resume, first_domain_id=domain_id),
                         show_progress=False)


def _outcomes(out) -> dict:
    """What a user compares: each episode's key, instruction, success and outcome."""
    return {r['key']: (r['instruction'], r['success'], r.get('outcome'), bool(r['reason']))
            for r in load_records(out)}


def _reasons(*outs) -> str:
    """Why episodes failed, for an assertion's message."""
    return '; '.join(f"{out.name} {r['key']}: {r['reason']}" for out in outs for r in load_records(out)
                     if not r['success']) or 'no episode failed'


def _lines(out) -> dict:
    return {path.name: path.read_text().splitlines() for path in sorted(out.glob('episodes*.jsonl'))}


def test_the_ray_executor_runs_the_local_executors_episodes_and_resumes(ros_isolation, tmp_path):
    local, ray = tmp_path / 'local', tmp_path / 'ray'
    local_summary = _run(local, 'local', int(ros_isolation))
    ray_summary = _run(ray, 'ray', int(ros_isolation))

    assert len(_outcomes(ray)) == 4 == ray_summary['episodes']
    assert _outcomes(ray) == _outcomes(local), _reasons(local, ray)
    assert all(success for _, success, _, _ in _outcomes(ray).values()), _reasons(ray)
    assert sorted(_lines(ray)) == sorted(_lines(local)) == ['episodes-0.jsonl', 'episodes-1.jsonl']
    assert ray_summary['overall'] == local_summary['overall']
    assert json.loads((ray / 'options.json').read_text())['executor'] == 'ray'
    assert (ray / 'report.md').read_text().count('| SA-SI |') == 2
    assert (ray / 'report.png').stat().st_size > 1000

    # A run stopped before a job's last episode: --resume runs that one alone (job 0), through Ray again.
    lines = _lines(ray)
    stopped = max(lines, key=lambda name: len(lines[name]))  # which job ran more depends on who was free first
    lost = json.loads(lines[stopped][-1])
    (ray / stopped).write_text(''.join(line + '\n' for line in lines[stopped][:-1]))
    kept = {name: lines[name][:-1] if name == stopped else lines[name] for name in lines}
    _run(ray, 'ray', int(ros_isolation), resume=True)
    resumed = _lines(ray)
    assert resumed['episodes-0.jsonl'][:-1] == kept['episodes-0.jsonl']
    assert resumed['episodes-1.jsonl'] == kept['episodes-1.jsonl']
    assert json.loads(resumed['episodes-0.jsonl'][-1])['key'] == lost['key']
    assert _outcomes(ray) == _outcomes(local)

    # Nothing left to run: a second --resume adds nothing and reports the same.
    again = _run(ray, 'ray', int(ros_isolation), resume=True)
    assert _lines(ray) == resumed
    assert again['episodes'] == 4 and again['overall'] == local_summary['overall']


def test_the_runs_own_ray_instance_is_on_loopback():
    from cap_bench.tabletop import ray_executor

    ray = ray_executor.start('', jobs=2)
    try:
        nodes = ray.nodes()
        assert [node['NodeManagerAddress'] for node in nodes] == ['127.0.0.1']
        assert ray.cluster_resources()['CPU'] == 2
    finally:
        ray.shutdown()
