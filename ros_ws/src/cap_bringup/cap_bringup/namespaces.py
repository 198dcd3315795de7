"""Graph namespaces as the `cap` command, the one-process graph and the launch file spell them."""
from __future__ import annotations


def normalise_namespace(namespace: str) -> str:
    """'' (none) or '/name': a leading slash added, a trailing one removed; a bad name is a one-line ValueError."""
    namespace = namespace.strip().strip('/')
    if not namespace:
        return ''
    for part in namespace.split('/'):
        if not part or not (part[0].isalpha() or part[0] == '_') or not all(c.isalnum() or c == '_' for c in part):
            raise ValueError(f'namespace {namespace!r}: each part must start with a letter or _ and hold only '
                             'letters, digits and _')
    return '/' + namespace
