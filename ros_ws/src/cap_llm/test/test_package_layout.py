"""The package is installed in the workspace the way ROS 2 tools expect to find it."""
import importlib
import pathlib
import xml.etree.ElementTree as ElementTree

PACKAGE = 'cap_llm'
PACKAGE_DIR = pathlib.Path(__file__).resolve().parents[1]


def test_package_is_importable_from_the_built_workspace():
    module = importlib.import_module(PACKAGE)
    assert pathlib.Path(module.__file__).resolve().parent == PACKAGE_DIR / PACKAGE


def test_manifest_is_format_3_ament_python():
    manifest = ElementTree.parse(PACKAGE_DIR / 'package.xml').getroot()
    assert manifest.get('format') == '3'
    assert manifest.findtext('name') == PACKAGE
    assert manifest.find('export/build_type').text == 'ament_python'
    assert (PACKAGE_DIR / 'resource' / PACKAGE).is_file()
