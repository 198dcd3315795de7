"""For tests: a package installed into a folder, as pip would, so that its entry points (a domain, a scene, a
detector, a demo) are found through the one registration path every plug-in takes (cap_ros_common.plugins)."""
from __future__ import annotations

import pathlib
import re
from typing import Mapping


def write_distribution(folder: pathlib.Path, name: str, modules: Mapping[str, str],
                       entry_points: Mapping[str, Mapping[str, str]]) -> pathlib.Path:
    """Write the modules (module name -> source) and a `<name>.dist-info` with their entry points (group ->
    {entry name: 'module:attribute'}) into `folder`, which a process then puts on sys.path. Returns the folder."""
    folder.mkdir(parents=True, exist_ok=True)
    for module, source in modules.items():
        (folder / f'{module}.py').write_text(source, encoding='utf-8')
    distribution = re.sub(r'[^A-Za-z0-9.]+', '_', name)
    info = folder / f'{distribution}-0.1.dist-info'
    info.mkdir(exist_ok=True)
    (info / 'METADATA').write_text(f'Metadata-Version: 2.1\nName: {name}\nVersion: 0.1\n', encoding='utf-8')
    (info / 'entry_points.txt').write_text(''.join(
        f'[{group}]\n' + ''.join(f'{entry} = {target}\n' for entry, target in entries.items()) + '\n'
        for group, entries in entry_points.items()), encoding='utf-8')
    return folder


__all__ = ['write_distribution']
