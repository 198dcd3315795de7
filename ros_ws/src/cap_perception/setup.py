from glob import glob

from setuptools import find_packages, setup

package_name = 'cap_perception'

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
    description=('Object perception for cap-ros: simulator ground truth, RGB-D colour detectors (table top, kitchen), '
                 'YAML stub, perception node.'),
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'perception_node = cap_perception.perception_node:main',
        ],
    },
)
