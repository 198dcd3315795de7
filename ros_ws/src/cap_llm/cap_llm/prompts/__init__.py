"""Few-shot prompts of the LMPs, written for this project, stored as text next to this module."""
from __future__ import annotations

from functools import lru_cache
from pathlib import Path

PROMPTS_DIR = Path(__file__).resolve().parent


@lru_cache(maxsize=None)
def load_prompt(name: str) -> str:
    """The text of prompts/<name>.txt."""
    path = PROMPTS_DIR / f'{name}.txt'
    if not path.is_file():
        raise FileNotFoundError(f'no prompt named {name!r} in {PROMPTS_DIR}')
    return path.read_text(encoding='utf-8')


def prompt_names() -> list[str]:
    return sorted(path.stem for path in PROMPTS_DIR.glob('*.txt'))
