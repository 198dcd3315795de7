"""Every Python package of the workspace is installed the way ROS 2 tools expect to find it."""
import importlib
import pathlib
import xml.etree.ElementTree as ElementTree

import pytest

SRC = pathlib.Path(__file__).resolve().parents[1] / 'ros_ws' / 'src'
PYTHON_PACKAGES = ('cap_ros_common', 'cap_tabletop', 'cap_lmp', 'cap_perception', 'cap_control', 'cap_sim_bridge',
                   'cap_lmp_ros', 'cap_bringup', 'cap_bench')


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
