from glob import glob
from pathlib import Path

from setuptools import find_packages, setup

package_name = 'cap_bringup'
# Every module of demos/ is a domain's demo (`cap demo NAME`), offered by its file name, so none is forgotten in a
# list; modules whose name starts with an underscore (_support.py) are what the demos share.
DEMOS = sorted(path.stem for path in Path(package_name, 'demos').glob('*.py') if not path.stem.startswith('_'))

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    package_data={package_name: ['cassettes/*.yaml', 'console/static/*']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/launch', glob('launch/*.launch.py')),
        ('share/' + package_name + '/config', glob('config/*.yaml')),
    ],
    install_requires=['setuptools'],
    zip_safe=False,
    maintainer='cap-ros maintainers',
    maintainer_email='maintainers@cap-ros.dev',
    description='Bringup of the cap-ros graph: the one-process graph, the cap command, the demos, the web console, '
                'RViz markers and launch files.',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'cap = cap_bringup.cli:main',
            'console = cap_bringup.console.node:main',
            'calibration = cap_bringup.calibration_node:main',
            'visualization_node = cap_bringup.visualization_node:main',
        ],
        # The demos `cap demo NAME` runs (cap_bringup.demos): name = the domain's name, value = the demo's main.
        'cap_ros.demos': [f'{name} = {package_name}.demos.{name}:main' for name in DEMOS],
    },
)
