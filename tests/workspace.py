"""The workspace's packages as their package.xml files describe them: the one place the tests learn which packages
exist, how each is built and in which layer it sits, so that a package added tomorrow is covered without editing a
list. Imported by the tests beside it (tests/ is put on sys.path by them)."""
from __future__ import annotations

import pathlib
import xml.etree.ElementTree as ElementTree
from dataclasses import dataclass, field

ROOT = pathlib.Path(__file__).resolve().parents[1]
SRC = ROOT / 'ros_ws' / 'src'
# The layers, lowest first (a package.xml names its own in <export><cap_ros layer="..."/></export>): interfaces;
# shared helpers and domain facts; the pure LMP engine, perception, control and the simulator; the LMP node;
# bringup; benchmarks.
LAYERS = ('interfaces', 'foundation', 'parts', 'lmp_node', 'bringup', 'benchmarks')


@dataclass
class Package:
    name: str
    root: pathlib.Path
    build_type: str = ''
    layer: str = ''
    exec_depends: set[str] = field(default_factory=set)
    test_depends: set[str] = field(default_factory=set)

    @property
    def level(self) -> int:
        """The layer's rank (-1 for a package that names no known layer)."""
        return LAYERS.index(self.layer) if self.layer in LAYERS else -1


def read_packages(src: pathlib.Path = SRC) -> dict[str, Package]:
    """Every package under `src` (a folder holding a package.xml), by name."""
    packages = {}
    for manifest in sorted(src.glob('*/package.xml')):
        root = ElementTree.parse(manifest).getroot()
        package = Package(root.findtext('name'), manifest.parent, root.findtext('export/build_type') or '',
                          (root.find('export/cap_ros') if root.find('export/cap_ros') is not None
                           else ElementTree.Element('cap_ros')).get('layer', ''))
        for tag in ('depend', 'exec_depend', 'build_depend'):
            package.exec_depends |= {element.text.strip() for element in root.findall(tag)}
        package.test_depends = {element.text.strip() for element in root.findall('test_depend')}
        packages[package.name] = package
    return packages
