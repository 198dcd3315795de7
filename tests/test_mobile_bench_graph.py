"""`cap bench mobile` through the real graph: one oracle episode of each template, judged on the simulator."""
from cap_bench.mobile.bench import run_benchmark
from cap_bench.mobile.episodes import TEMPLATES
from cap_bench.bench_options import BenchOptions


def test_one_oracle_episode_per_template_passes_with_a_report(ros_isolation, tmp_path):
    summary = run_benchmark(BenchOptions(trials=1, out=str(tmp_path), first_domain_id=int(ros_isolation)),
                            TEMPLATES)
    assert summary['overall']['trials'] == len(TEMPLATES)
    assert summary['failures'] == {}
    assert (tmp_path / 'report.md').exists() and (tmp_path / 'episodes.jsonl').exists()
