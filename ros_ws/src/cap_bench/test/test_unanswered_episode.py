"""A benchmark graph that stops answering costs its episode, not the rest of the run
(cap_bench.tabletop.runner.run_episodes).

The graphs here are stand-ins that answer or time out as told: what is tested is the runner's bookkeeping, which
the graph tests cannot make happen on demand.
"""
from cap_bench.tabletop.episodes import episode_key
from cap_bench.tabletop.options import TabletopOptions
from cap_bench.tabletop.runner import run_episodes


class _Graph:
    """Answers every episode, except those in `silent`, where it stops answering (as TabletopRunner raises)."""

    def __init__(self, silent: set[str], log: list[str]) -> None:
        self.silent, self.log = silent, log
        self.closed = False
        log.append('built')

    def run(self, episode) -> dict:
        key = episode_key(episode.group, episode.template, episode.seed)
        if key in self.silent:
            raise TimeoutError('no answer from lmp_node (reset session) within 60 s')
        return {'key': key, 'success': True, 'reason': ''}

    def close(self) -> None:
        self.closed = True
        self.log.append('closed')


def test_a_graph_that_stops_answering_fails_its_episode_and_the_rest_run_on_a_new_graph():
    keys = ['SA-SI/pick_place/0', 'SA-SI/pick_place/1', 'SA-SI/stack/2']
    log: list[str] = []
    graphs: list[_Graph] = []

    def make() -> _Graph:
        graphs.append(_Graph({'SA-SI/pick_place/1'} if not graphs else set(), log))
        return graphs[-1]

    records: list[dict] = []
    built = run_episodes(keys, TabletopOptions(policy='llm'), make, records.append)

    assert [r['key'] for r in records] == keys
    assert [r['success'] for r in records] == [True, False, True]
    reason = records[1]['reason']
    assert reason.startswith('the graph stopped answering (no answer from lmp_node (reset session) within 60 s)')
    assert records[1]['instruction'] and records[1]['policy'] == 'llm'
    # the silent graph is closed before the next one is built, and the last one at the end
    assert built == 2 and log == ['built', 'closed', 'built', 'closed']
    assert all(graph.closed for graph in graphs)
