"""Cassettes: completions stored in a YAML file of the repository, replayed offline or recorded from a backend.

File format (YAML, one list of entries; multi-line completions are written as literal blocks):

    format: cap-llm-cassette/1
    entries:
    - lmp: tabletop_ui
      query: put the blocks in the bowls with matching colors
      context: objects = ['blue block', 'red block', 'blue bowl', 'red bowl']    # or '*' for any context
      source: written by hand as a reference program        # or: recorded from <model> [at <base url>]
      completion: |
        for block in ...

The key is (LMP name, normalised query, normalised context line), not a hash of the prompt: editing an LMP's
few-shot examples, hints, stop sequences or the session history leaves every entry valid, while a different command
or a different scene (the `objects = [...]` line) is a different entry. Normalising lower-cases the query, folds runs
of white space and drops a trailing period; the context only has its white space folded. An entry whose context is
'*' answers the query in any scene (a reference program that reads the scene itself); an exact context wins over '*'.
The price of this key: after an edit that should change the model's answer, re-record the affected entries.
"""
from __future__ import annotations

import os
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from cap_lmp.errors import CassetteMissError, LLMError
from cap_lmp.llm import Completion, CompletionRequest, LLMClient, OpenAICompatibleClient

FORMAT = 'cap-llm-cassette/1'
ANY_CONTEXT = '*'
HAND_WRITTEN = 'written by hand as a reference program'


def normalise_query(query: str) -> str:
    return ' '.join(query.lower().split()).rstrip('.').rstrip()


def normalise_context(context: str) -> str:
    return ' '.join(context.split())


def cassette_key(lmp: str, query: str, context: str) -> tuple[str, str, str]:
    return lmp, normalise_query(query), normalise_context(context)


@dataclass
class CassetteEntry:
    lmp: str
    query: str
    context: str
    completion: str
    source: str

    def as_dict(self) -> dict[str, Any]:
        return {'lmp': self.lmp, 'query': self.query, 'context': self.context, 'source': self.source,
                'completion': self.completion}


class _LiteralDumper(yaml.SafeDumper):
    pass


def _represent_str(dumper: yaml.SafeDumper, text: str) -> Any:
    style = '|' if '\n' in text else None
    return dumper.represent_scalar('tag:yaml.org,2002:str', text, style=style)


_LiteralDumper.add_representer(str, _represent_str)


class Cassette:
    """The entries of one cassette file, indexed by key."""

    def __init__(self, path: str | os.PathLike[str], entries: list[CassetteEntry] | None = None) -> None:
        self.path = Path(path)
        self._entries: dict[tuple[str, str, str], CassetteEntry] = {}
        for entry in entries or []:
            self.add(entry)

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> 'Cassette':
        """Read a cassette; a file that does not exist yet is an empty cassette."""
        path = Path(path)
        if not path.exists():
            return cls(path)
        data = yaml.safe_load(path.read_text(encoding='utf-8')) or {}
        if data.get('format') != FORMAT:
            raise LLMError(f'{path} is not a cassette of format {FORMAT}')
        entries = []
        for raw in data.get('entries') or []:
            missing = {'lmp', 'query', 'completion', 'source'} - set(raw)
            if missing:
                raise LLMError(f'{path}: an entry lacks {", ".join(sorted(missing))}: {raw}')
            entries.append(CassetteEntry(lmp=raw['lmp'], query=raw['query'], context=raw.get('context') or '',
                                         completion=raw['completion'], source=raw['source']))
        return cls(path, entries)

    def add(self, entry: CassetteEntry) -> None:
        self._entries[cassette_key(entry.lmp, entry.query, entry.context)] = entry

    def find(self, lmp: str, query: str, context: str) -> CassetteEntry | None:
        entry = self._entries.get(cassette_key(lmp, query, context))
        if entry is None:
            entry = self._entries.get(cassette_key(lmp, query, ANY_CONTEXT))
        return entry

    def __len__(self) -> int:
        return len(self._entries)

    def entries(self) -> list[CassetteEntry]:
        return list(self._entries.values())

    def save(self) -> None:
        """Write atomically (a crash never leaves half a cassette)."""
        data = {'format': FORMAT, 'entries': [entry.as_dict() for entry in self._entries.values()]}
        text = yaml.dump(data, Dumper=_LiteralDumper, sort_keys=False, allow_unicode=True, width=120)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        handle, temporary = tempfile.mkstemp(dir=self.path.parent, prefix='.' + self.path.name)
        with os.fdopen(handle, 'w', encoding='utf-8') as stream:
            stream.write(text)
        os.replace(temporary, self.path)


class CassetteClient:
    """An LLMClient answering from a cassette.

    mode 'replay': offline; a missing entry raises CassetteMissError naming the LMP and the query.
    mode 'record': answers from the cassette when it can, otherwise asks `backend` and stores the answer with its
    provenance ('recorded from <model>'); the file is saved after every new entry.
    A request's `time_budget_s` does not apply to replay (answering from the file takes no model time); in record
    mode the backend honours it.
    """

    def __init__(self, path: str | os.PathLike[str], mode: str = 'replay', backend: LLMClient | None = None) -> None:
        if mode not in ('replay', 'record'):
            raise ValueError(f"cassette mode must be 'replay' or 'record', not {mode!r}")
        if mode == 'record' and backend is None:
            raise ValueError('record mode needs a backend to record from')
        self.cassette = Cassette.load(path)
        self.mode = mode
        self.backend = backend
        self._lock = threading.Lock()

    def complete(self, request: CompletionRequest) -> Completion:
        started = time.monotonic()
        with self._lock:
            entry = self.cassette.find(request.lmp, request.query, request.context)
        if entry is not None:
            return Completion(text=entry.completion, model='cassette', latency_s=time.monotonic() - started,
                              source=entry.source)
        if self.mode == 'replay':
            raise CassetteMissError(request.lmp, request.query, str(self.cassette.path))
        assert self.backend is not None
        completion = self.backend.complete(request)
        source = f'recorded from {completion.model or "an unnamed model"}'
        with self._lock:
            self.cassette.add(CassetteEntry(lmp=request.lmp, query=request.query, context=request.context,
                                            completion=completion.text, source=source))
            self.cassette.save()
        return completion


def make_client(cassette: str | os.PathLike[str] | None = None, record: bool = False,
                **http_options: Any) -> LLMClient:
    """The client a front end wants: HTTP from the environment (no cassette), a replay cassette, or a cassette
    recording from the HTTP endpoint. `http_options` override OpenAICompatibleClient.from_env settings."""
    if not cassette:
        return OpenAICompatibleClient.from_env(**http_options)
    if record:
        return CassetteClient(cassette, mode='record', backend=OpenAICompatibleClient.from_env(**http_options))
    return CassetteClient(cassette)
