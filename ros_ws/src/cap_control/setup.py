from glob import glob

from setuptools import find_packages, setup

package_name = 'cap_control'

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
        'console_scripts': [
            'pick_place = cap_control.pick_place_node:main',
            'follow_path = cap_control.follow_path_node:main',
            'navigation = cap_control.navigation_node:main',
            'mobile_pick_place = cap_control.mobile_pick_place_node:main',
            'controller_node = cap_control.controller_node:main',
        ],
    },
)
