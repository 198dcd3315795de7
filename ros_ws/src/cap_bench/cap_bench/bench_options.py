"""The options every benchmark that runs its episodes through a graph shares: who writes the programs (the oracle's
reference programs replayed from a cassette, or a model), how many trials, where the results go, how long an
instruction may take. A benchmark with options of its own extends BenchOptions (e.g. cap_bench.tabletop.options)."""
from __future__ import annotations

import dataclasses
import os
from typing import Any


@dataclasses.dataclass
class BenchOptions:
    policy: str = 'oracle'  # or 'llm'
    trials: int = 50
    base_seed: int = 0
    out: str = 'output/bench'
    resume: bool = False
    base_url: str = ''  # for policy=llm; empty: CAP_LLM_BASE_URL
    model: str = ''
    api: str = 'chat'
    episode_timeout_s: float = 900.0
    first_domain_id: int | None = None  # the run's first graph's ROS_DOMAIN_ID; None: see cap_bench.ros_domains
    backend: str = 'http'  # for policy=llm: 'http' (base_url) or 'local' (a llama.cpp server started for the run)
    model_file: str = ''  # for backend=local; empty: the default model of `make model`
    model_threads: int = 1
    feedback_rounds: int = 0  # for policy=llm: lmp_node's feedback_rounds (0: the paper's protocol)
    rehearse: str = 'off'  # lmp_node's rehearse: 'always' rehearses every program on a twin first


def policy_name(options: BenchOptions) -> str:
    """Short: 'oracle programs' or the model's name."""
    if options.policy == 'oracle':
        return 'oracle programs'
    return f"model {options.model or os.environ.get('CAP_LLM_MODEL', '') or '(unnamed)'}"


def policy_description(options: BenchOptions) -> str:
    """Who wrote the programs, for reports."""
    if options.policy == 'oracle':
        return 'oracle: the reference program of each episode, replayed from a cassette (no model)'
    url = options.base_url or os.environ.get('CAP_LLM_BASE_URL', '') or '(CAP_LLM_BASE_URL)'
    return f'{policy_name(options)} at {url}, {options.api} API'


def feedback_rounds(options: BenchOptions) -> int:
    """lmp_node's feedback rounds of the run: a model's, none for the oracle's replayed programs."""
    return options.feedback_rounds if options.policy == 'llm' else 0


def lmp_parameters(options: BenchOptions) -> tuple[str, dict[str, Any]]:
    """(llm backend, lmp_node parameters) of the run's policy: the cassette for the oracle, else the model's."""
    lmp: dict[str, Any] = {'time_limit_s': options.episode_timeout_s}
    backend = 'cassette' if options.policy == 'oracle' else options.backend
    if options.policy == 'llm':
        lmp['feedback_rounds'] = feedback_rounds(options)
    if backend == 'local':  # lmp_node starts and supervises the model server itself
        lmp.update(model_file=options.model_file, model_threads=options.model_threads)
    elif options.policy == 'llm':
        lmp.update(api=options.api)
        if options.base_url:
            lmp['base_url'] = options.base_url
        if options.model:
            lmp['model'] = options.model
    return backend, lmp
