"""Every Python package of the workspace is installed the way ROS 2 tools expect to find it, and every package's
tests are collected: the packages are read from their package.xml files, never listed here."""
import importlib
import pathlib
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ElementTree

import pytest

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))  # workspace.py beside this file
from workspace import LAYERS, ROOT, SRC, read_packages  # noqa: E402

PYTHON_PACKAGES = sorted(name for name, package in read_packages().items() if package.build_type == 'ament_python')


def test_every_package_names_its_build_type_and_layer():
    packages = read_packages()
    assert {package.build_type for package in packages.values()} <= {'ament_python', 'ament_cmake'}
    assert [name for name, package in packages.items() if package.layer not in LAYERS] == []
    assert len(PYTHON_PACKAGES) >= 12 and 'cap_mobile' in PYTHON_PACKAGES


@pytest.mark.parametrize('package', PYTHON_PACKAGES)
def test_package_is_importable_from_the_built_workspace(package):
    module = importlib.import_module(package)
    assert pathlib.Path(module.__file__).resolve().parent == SRC / package / package


@pytest.mark.parametrize('package', PYTHON_PACKAGES)
def test_manifest_is_format_3_ament_python_with_a_resource_marker(package):
    manifest = ElementTree.parse(SRC / package / 'package.xml').getroot()
    assert manifest.get('format') == '3'
    assert manifest.findtext('name') == package
    assert manifest.find('export/build_type').text == 'ament_python'
    assert (SRC / package / 'resource' / package).is_file()


def test_the_interface_package_is_ament_cmake():
    manifest = ElementTree.parse(SRC / 'cap_interfaces' / 'package.xml').getroot()
    assert manifest.find('export/build_type').text == 'ament_cmake'
    assert manifest.findtext('member_of_group') == 'rosidl_interface_packages'


THROWAWAY_MANIFEST = '''<?xml version="1.0"?>
<package format="3">
  <name>cap_throwaway</name>
  <version>0.0.1</version>
  <description>A package made by a test.</description>
  <maintainer email="maintainers@cap-ros.dev">cap-ros maintainers</maintainer>
  <license>Apache-2.0</license>
  <export>
    <build_type>ament_python</build_type>
    <cap_ros layer="parts"/>
  </export>
</package>
'''


def test_a_package_added_to_the_workspace_is_covered_the_day_it_is_added(tmp_path):
    """A new package in a copy of the workspace's layout: its tests are collected, it is in the layout test's
    packages and in its layer, with nothing else edited."""
    shutil.copy(ROOT / 'pytest.ini', tmp_path / 'pytest.ini')
    package = tmp_path / 'ros_ws' / 'src' / 'cap_throwaway'
    (package / 'cap_throwaway').mkdir(parents=True)
    (package / 'cap_throwaway' / '__init__.py').write_text('')
    (package / 'test').mkdir()
    (package / 'test' / 'test_throwaway.py').write_text('def test_it_is_collected():\n    pass\n')
    (package / 'package.xml').write_text(THROWAWAY_MANIFEST)
    (tmp_path / 'tests').mkdir()
    collected = subprocess.run([sys.executable, '-m', 'pytest', '--collect-only', '-q', '-p', 'no:cacheprovider'],
                               cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert 'ros_ws/src/cap_throwaway/test/test_throwaway.py::test_it_is_collected' in collected.stdout, \
        collected.stdout + collected.stderr
    found = read_packages(tmp_path / 'ros_ws' / 'src')
    assert found['cap_throwaway'].build_type == 'ament_python' and found['cap_throwaway'].layer == 'parts'
