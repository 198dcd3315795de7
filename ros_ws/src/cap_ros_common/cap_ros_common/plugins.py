"""Plug-ins by entry point: the one way a domain, a scene, a detector, a demo or a benchmark becomes known.

Each kind of plug-in is an entry-point group (`cap_ros.domains`, `cap_ros.scenes`, ...). The workspace's own
packages offer theirs the same way as any other package: their setup.py derives the entry points from their
folders, so a module added to such a folder is offered without editing a list. The name of an entry point is the
plug-in's name (for a domain's parts, the domain's name). No ROS here.
"""
from __future__ import annotations

import importlib.metadata
from typing import Any, Callable, Generic, TypeVar

Plugin = TypeVar('Plugin')


class PluginGroup(Generic[Plugin]):
    """The plug-ins of one entry-point group, loaded when asked for.

    `kind` names a plug-in in messages ('domain', 'scene'); `accept` says whether a loaded object is one (a wrong
    object is an error naming its entry point, not a silent skip). Each question reads the entry points again (a few
    milliseconds; asked at start-up, not per message), so a package installed while the process runs is found, and
    one removed is gone; the loaded objects themselves are Python's imported modules' attributes.
    """

    def __init__(self, group: str, kind: str, accept: Callable[[Any], bool] = lambda value: True) -> None:
        self.group, self.kind, self._accept = group, kind, accept

    def _entry_points(self) -> dict[str, list[importlib.metadata.EntryPoint]]:
        """Every name offered, with each entry point that offers it (more than one: a conflict)."""
        found: dict[str, list[importlib.metadata.EntryPoint]] = {}
        for entry in importlib.metadata.entry_points(group=self.group):
            found.setdefault(entry.name, []).append(entry)
        return found

    def _load(self, entry: importlib.metadata.EntryPoint) -> Plugin:
        try:
            value = entry.load()
        except Exception as error:
            raise ValueError(f'{self.kind} {entry.name!r} ({entry.value}, entry point of {self.group}) cannot be '
                             f'loaded: {type(error).__name__}: {error}') from error
        if not self._accept(value):
            raise ValueError(f'{self.kind} {entry.name!r}: {entry.value} (entry point of {self.group}) is not a '
                             f'{self.kind} but {type(value).__name__}')
        return value

    def get(self, name: str) -> Plugin:
        """The plug-in called `name`; ValueError (one line, naming the known ones) if there is none."""
        entries = self._entry_points()
        if name not in entries:
            known = ', '.join(sorted(entries)) or 'none'
            raise ValueError(f'unknown {self.kind} {name!r}; known {self.kind}s: {known}')
        if len(entries[name]) > 1:  # two packages offer one name: neither is chosen behind the user's back
            offers = ' and '.join(f'{entry.value} ({entry.dist.name if entry.dist else "?"})'
                                  for entry in entries[name])
            raise ValueError(f'{self.kind} {name!r} is offered twice, by {offers}: uninstall one')
        return self._load(entries[name][0])

    def names(self) -> list[str]:
        """Every plug-in's name, sorted (read from the entry points, nothing loaded)."""
        return sorted(self._entry_points())

    def all(self) -> dict[str, Plugin]:
        """Every plug-in, loaded, by name."""
        return {name: self.get(name) for name in self.names()}


__all__ = ['PluginGroup']
