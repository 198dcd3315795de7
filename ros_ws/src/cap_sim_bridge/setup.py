from glob import glob
from pathlib import Path

from setuptools import find_packages, setup

package_name = 'cap_sim_bridge'
# Every module of scenes/ is a domain's scene: offered by its file name, so none is forgotten in a list.
SCENES = sorted(path.stem for path in Path(package_name, 'scenes').glob('*.py') if not path.stem.startswith('_'))

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    # The MJCF models are loaded relative to the module, so they travel with the Python package.
    package_data={package_name: ['models/*.xml']},
    include_package_data=True,
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', glob('config/*.yaml')),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='cap-ros maintainers',
    maintainer_email='maintainers@cap-ros.dev',
    description='MuJoCo simulation of the cap-ros robots (a scene per domain) and its ROS 2 bridge node.',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'sim_bridge = cap_sim_bridge.bridge_node:main',
            'robot_state = cap_sim_bridge.robot_state_node:main',
            'cap_sim_render = cap_sim_bridge.render_cli:main',
        ],
        # The scenes the bridge's `scene` parameter names (cap_sim_bridge.scenes).
        'cap_ros.scenes': [f'{name} = {package_name}.scenes.{name}:SCENE' for name in SCENES],
    },
)
