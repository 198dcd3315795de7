"""Few-shot prompts of the LMPs are text files, one per LMP, kept by each domain in a folder of its own."""
from __future__ import annotations

from functools import lru_cache
from pathlib import Path


@lru_cache(maxsize=None)
def load_prompt(directory: Path | str, name: str) -> str:
    """The text of `<directory>/<name>.txt`."""
    path = Path(directory) / f'{name}.txt'
    if not path.is_file():
        raise FileNotFoundError(f'no prompt named {name!r} in {directory}')
    return path.read_text(encoding='utf-8')


def prompt_names(directory: Path | str) -> list[str]:
    """The names of the prompts in `directory`."""
    return sorted(path.stem for path in Path(directory).glob('*.txt'))
