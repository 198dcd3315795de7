from glob import glob
from pathlib import Path

from setuptools import find_packages, setup

package_name = 'cap_lmp_ros'
# Every sub-package of domains/ with a domain.py is a domain: offered by its folder's name, so none is forgotten in a
# list, with its prompts and cassettes as package data.
DOMAINS = sorted(path.parent.name for path in Path(package_name, 'domains').glob('*/domain.py'))

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    package_data={f'{package_name}.domains.{name}': ['prompts/*.txt', 'cassettes/*.yaml'] for name in DOMAINS},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', glob('config/*.yaml')),
    ],
    install_requires=['setuptools'],
    zip_safe=False,
    maintainer='cap-ros maintainers',
    maintainer_email='maintainers@cap-ros.dev',
    description=('The ROS binding of the LMP engine: lmp_node, its command queue, and the domains (prompts, LMPs, '
                 'robot APIs) as plug-ins.'),
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'lmp_node = cap_lmp_ros.lmp_node:main',
        ],
        # The domains lmp_node's `domain` parameter names (cap_lmp_ros.domains.registry).
        'cap_ros.domains': [f'{name} = {package_name}.domains.{name}.domain:DOMAIN' for name in DOMAINS],
    },
)
