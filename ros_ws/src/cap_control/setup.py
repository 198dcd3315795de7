from glob import glob
from pathlib import Path

from setuptools import find_packages, setup

package_name = 'cap_control'
# Every skill folder with a node.py is an executable of that folder's name, so none is forgotten in a list.
SKILLS = sorted(path.parent.name for path in Path(package_name).glob('*/node.py'))

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
    description=('Control for cap-ros: UR5e kinematics, trajectory timing, pick-and-place, path following, navigation '
                 'of a mobile base.'),
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [f'{name} = {package_name}.{name}.node:main' for name in SKILLS],
    },
)
