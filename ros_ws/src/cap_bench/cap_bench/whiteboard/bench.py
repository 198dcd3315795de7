"""`cap bench whiteboard`: drawing and erasing on the simulated whiteboard through the real graph, judged on the ink.

Every episode goes the way of a user's commands: the scene is reset through the sim bridge's service (which also
wipes the board), the session is reset, the episode's instructions go to lmp_node's /cap/execute action one after
another, the programs (the reference programs replayed from a cassette, or a model's code from an OpenAI-compatible
endpoint) run in the sandbox and drive follow_path over ROS, and the ink image the bridge serves (GetInk) is judged
against the episode's shapes (cap_bench.whiteboard.ink_check). Episodes: cap_bench.whiteboard.episodes.

    cap bench whiteboard --trials 20 --out output/whiteboard            # the reference programs (oracle)
    cap bench whiteboard --policy llm --backend local --trials 5      # the local model

Results are appended to episodes.jsonl as each episode ends (--resume continues a run); report.json, report.md and
report.png summarise them per template. One graph runs the episodes one after another.
"""
from __future__ import annotations

import pathlib
import time
from typing import Sequence

import cv2
import numpy as np

from cap_bench import episode_runs, template_report
from cap_bench.bench_options import BenchOptions, policy_description
from cap_bench.episode_runs import episode_record, load_records, run_episodes
from cap_bench.graph_cli import TemplateBench
from cap_bench.graph_client import SERVICE_TIMEOUT_S, GraphClient, outcome_name, prediction_fields
from cap_bench.whiteboard import devset
from cap_bench.whiteboard.episodes import TEMPLATES, Episode, oracle_program, sample_episode
from cap_bench.whiteboard.ink_check import MAX_P95_MM, MIN_COVERAGE, check_drawing, check_erased
from cap_lmp.safe_text import one_line

DEFAULT_OUT = 'output/whiteboard'
UI_LMP = 'whiteboard_ui'
# The bar the oracle must clear (the paper has no figure for this domain): this share of episodes passing.
TARGET_ORACLE_RATE = 0.99
CRITERIA = {'p95_mm_at_most': MAX_P95_MM, 'coverage_at_least': MIN_COVERAGE, 'oracle_rate_target': TARGET_ORACLE_RATE}
NOTE = (f"A drawing passes with the ink's 95th-percentile distance to the target at most {MAX_P95_MM} mm and at least "
        f"{MIN_COVERAGE:.0%} of the target inked; an erase with the board clean.")
COLUMNS = (('p95 median [mm]', 'p95_mm_median', '.2f'), ('p95 max [mm]', 'p95_mm_max', '.2f'),
           ('least coverage', 'coverage_min', '.3f'))


def plan(templates: Sequence[str], trials: int, base_seed: int = 0) -> list[Episode]:
    """Every episode of the run, trial by trial across the templates."""
    return [sample_episode(template, base_seed + trial) for trial in range(trials) for template in templates]


def write_oracle_cassette(episodes: Sequence[Episode], path: pathlib.Path) -> None:
    """One reference program per distinct instruction (a program depends only on its instruction's words)."""
    episode_runs.write_oracle_cassette(episodes, path, UI_LMP, 'whiteboard', oracle_program)


class WhiteboardRunner(GraphClient):
    """One whiteboard graph in this process, running episodes one after another."""

    def __init__(self, options: BenchOptions, cassette: pathlib.Path | None) -> None:
        from cap_interfaces.msg import GraphNames
        from cap_interfaces.srv import GetInk

        super().__init__(options, cassette, 'cap_bench_whiteboard', domain='whiteboard', camera_rate=0.0)
        self.get_ink = self.node.create_client(GetInk, GraphNames.SIM_GET_INK_SERVICE)
        self.GetInk = GetInk
        self.wait_until_ready('the whiteboard graph', self.get_ink.service_is_ready)

    def ink(self) -> np.ndarray:
        """The board's ink now, as the bridge serves it (a PNG, decoded)."""
        answer = self.call(self.get_ink.call_async(self.GetInk.Request()), SERVICE_TIMEOUT_S, 'the ink service')
        return cv2.imdecode(np.frombuffer(bytes(answer.image.data), np.uint8), cv2.IMREAD_GRAYSCALE)

    def run(self, episode: Episode) -> dict:
        world = self.graph.world
        record = episode_record(episode, self.options)
        wall_started = time.monotonic()
        if not self.start_episode(episode, record):
            return record
        sim_started = world.time
        results = self.run_instructions(episode.instructions, record)
        if results is None:
            return record
        done = self.finished(results)
        ink = self.ink()
        verdict = check_erased(ink) if episode.erase else check_drawing(ink, episode.targets)
        record.update(code='\n# ---\n'.join(r.code for r in results), success=bool(done and verdict.success),
                      outcome=outcome_name(results[-1].outcome) if results else '',
                      sim_seconds=round(world.time - sim_started, 3),
                      wall_seconds=round(time.monotonic() - wall_started, 3), **verdict.figures(),
                      **prediction_fields(results))
        if not done:
            record['reason'] = f'the command ended {record["outcome"]}: {one_line(results[-1].message)}'
        elif not verdict.success:
            record['reason'] = f'the ink is wrong: {verdict.reason}'
        return record


def _ink_figures(records: list[dict]) -> dict:
    """The ink figures of a template's drawings: the median and largest 95th-percentile distance, the least
    coverage (None for erasing)."""
    drawn = [r for r in records if 'p95_mm' in r and r['template'] != 'erase' and r.get('ink_pixels', 0)]
    return {'p95_mm_median': float(np.median([r['p95_mm'] for r in drawn])) if drawn else None,
            'p95_mm_max': float(max(r['p95_mm'] for r in drawn)) if drawn else None,
            'coverage_min': float(min(r['coverage'] for r in drawn)) if drawn else None}


def summarise(records: Sequence[dict], title: str, policy: str, wall_seconds: float) -> dict:
    """Per template and overall: passed / trials; the ink figures of the drawings; each failure's reason."""
    return template_report.summarise(records, TEMPLATES, title, policy, CRITERIA, wall_seconds, _ink_figures)


def write_report(summary: dict, out: pathlib.Path) -> None:
    template_report.write_report(summary, out, COLUMNS, NOTE)
    template_report.draw_chart(summary, out / 'report.png')


def run_benchmark(options: BenchOptions, templates: Sequence[str], resume: bool = False) -> dict:
    episodes = plan(templates, options.trials, options.base_seed)
    seconds = run_episodes(options, episodes, resume, write_oracle_cassette, WhiteboardRunner)
    out = pathlib.Path(options.out)
    summary = summarise(load_records(out), 'Whiteboard: drawing and erasing, judged on the ink',
                        policy_description(options), seconds)
    write_report(summary, out)
    return summary


def write_dev_cassette(episodes: Sequence[Episode], path: pathlib.Path) -> None:
    """The development set's reference programs, one per instruction."""
    episode_runs.write_oracle_cassette(episodes, path, UI_LMP, 'whiteboard', devset.reference_program)


def run_devset(options: BenchOptions, resume: bool = False) -> dict:
    """The development set (cap_bench.whiteboard.devset), `options.trials` times, judged on the ink."""
    seconds = run_episodes(options, devset.episodes(options.trials), resume, write_dev_cassette, WhiteboardRunner)
    out = pathlib.Path(options.out)
    summary = template_report.summarise(load_records(out), list(devset.BY_KEY),
                                        'Whiteboard development set, judged on the ink', policy_description(options),
                                        CRITERIA, seconds, _ink_figures)
    write_report(summary, out)
    return summary


BENCH = TemplateBench(name='whiteboard', description=__doc__.split('\n\n')[0], out=DEFAULT_OUT,
                      templates=tuple(TEMPLATES), run_templates=run_benchmark, run_devset=run_devset)


def main(argv: list[str] | None = None) -> int:
    return BENCH.main(argv)
