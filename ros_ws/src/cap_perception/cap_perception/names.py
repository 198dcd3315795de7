"""Object names as people type them, mapped to the canonical "<colour> <category>" form."""
from __future__ import annotations

import difflib
import re
from typing import Iterable

_ARTICLES = {'the', 'a', 'an'}
_SPELLINGS = {'grey': 'gray', 'blocks': 'block', 'bowls': 'bowl', 'cube': 'block', 'cubes': 'block'}


class UnknownObjectError(LookupError):
    """Raised when a name matches no known object; the message lists the names that exist."""


def canonical_name(text: str) -> str:
    """'The Red_Block' -> 'red block': lower case, underscores and dashes as spaces, no article, common spellings."""
    words = re.split(r'[\s_\-]+', text.strip().lower())
    words = [_SPELLINGS.get(word, word) for word in words if word and word not in _ARTICLES]
    return ' '.join(words)


def resolve_name(text: str, known: Iterable[str]) -> str:
    """The known canonical name that `text` refers to, or UnknownObjectError naming the known ones."""
    known = sorted(known)
    wanted = canonical_name(text)
    if wanted in known:
        return wanted
    close = difflib.get_close_matches(wanted, known, n=1, cutoff=0.85)
    hint = f' Did you mean {close[0]!r}?' if close else ''
    listing = ', '.join(known) if known else 'none'
    raise UnknownObjectError(f'There is no object called {text!r}.{hint} Known objects: {listing}.')
