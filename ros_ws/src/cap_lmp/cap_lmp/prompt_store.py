"""The local model's prompt cache, kept on disk from one start of the server to the next.

Reading a domain's fixed prompts (about 7,000 tokens) costs minutes on one core, and every start of the llama.cpp
server began with an empty cache. The server can write a slot's KV cache to a file and read it back
(`--slot-save-path`, POST /slots/0?action=save|restore): a fraction of a second per prompt. A `PromptStore` names
those files, one per prompt, by everything the KV cache depends on: the model file, the server binary that computed
it, the context size and the prompt's text. A changed prompt, model or build therefore misses and is read afresh; a
file is never served for anything but what made it.

Plain Python, no server calls: `local_server.warm_up` does the saving and restoring.
"""
from __future__ import annotations

import hashlib
import os
import pathlib
import re
import time
from dataclasses import dataclass

KEY_VERSION = 1  # part of every key: a change of the file layout here misses every older file
MAX_FILES = 48  # the newest kept (about 80 MB for a 2,800-token prompt of the default model); older ones pruned
SUFFIX = '.kv'


def _file_identity(path: pathlib.Path) -> str:
    """Where a file is, how big and when it was last written: what tells one model (or build) from another without
    reading a gigabyte."""
    resolved = path.resolve()
    stat = resolved.stat()
    return f'{resolved}:{stat.st_size}:{stat.st_mtime_ns}'


@dataclass(frozen=True)
class PromptStore:
    """The folder of a server's saved prompts, and the part of their keys that is the server's own."""

    directory: pathlib.Path
    identity: str

    @classmethod
    def for_server(cls, directory: pathlib.Path, model: pathlib.Path, binary: pathlib.Path,
                   context_size: int) -> 'PromptStore':
        identity = '|'.join((str(KEY_VERSION), _file_identity(model), _file_identity(binary), str(context_size)))
        return cls(pathlib.Path(directory), identity)

    def file_name(self, lmp: str, prompt: str) -> str:
        """The name of `prompt`'s file (llama.cpp takes a bare name inside --slot-save-path: no separators)."""
        digest = hashlib.sha256(f'{self.identity}\n{prompt}'.encode()).hexdigest()[:32]
        return f"{re.sub(r'[^A-Za-z0-9_]', '_', lmp)[:40]}-{digest}{SUFFIX}"

    def has(self, name: str) -> bool:
        return (self.directory / name).is_file()

    def used(self, name: str) -> None:
        """Mark a file as just used: pruning drops the least recently used ones first."""
        try:
            os.utime(self.directory / name)
        except OSError:
            pass

    def temporary_name(self, name: str) -> str:
        """Where the server writes a file before it is moved into place, so that another server that restores it
        never reads it half-written."""
        return f'{name}.{os.getpid()}.tmp'

    def commit(self, temporary: str, name: str) -> None:
        os.replace(self.directory / temporary, self.directory / name)

    def discard(self, name: str) -> None:
        """A file the server could not read back (another build's, or damaged) is removed."""
        try:
            (self.directory / name).unlink()
        except FileNotFoundError:
            pass

    def prune(self, keep: int = MAX_FILES) -> int:
        """Remove all but the `keep` most recently used files, and what a server that died while writing left
        behind; returns how many went."""
        files = sorted(self.directory.glob(f'*{SUFFIX}'), key=lambda path: path.stat().st_mtime_ns, reverse=True)
        stale = files[keep:]
        stale += [path for path in self.directory.glob('*.tmp') if time.time() - path.stat().st_mtime > 3600]
        for path in stale:
            path.unlink(missing_ok=True)
        return len(stale)


__all__ = ['KEY_VERSION', 'MAX_FILES', 'PromptStore']
