from glob import glob
from pathlib import Path

from setuptools import find_packages, setup

package_name = 'cap_perception'
# Every module of detectors/ is a domain's detector: offered by its file name, so none is forgotten in a list.
DETECTORS = sorted(path.stem for path in Path(package_name, 'detectors').glob('*.py') if not path.stem.startswith('_'))

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', glob('config/*.yaml')),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='cap-ros maintainers',
    maintainer_email='maintainers@cap-ros.dev',
    description=('Object perception for cap-ros: simulator ground truth, RGB-D colour detectors per domain, '
                 'YAML stub, perception node.'),
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'perception_node = cap_perception.perception_node:main',
        ],
        # The detectors the `detector` parameter names (cap_perception.detectors).
        'cap_ros.detectors': [f'{name} = {package_name}.detectors.{name}:DETECTOR' for name in DETECTORS],
    },
)
