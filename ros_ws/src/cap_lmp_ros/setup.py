from glob import glob

from setuptools import find_packages, setup

package_name = 'cap_lmp_ros'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    package_data={'cap_lmp_ros.domains.tabletop': ['prompts/*.txt', 'cassettes/*.yaml'],
                  'cap_lmp_ros.domains.whiteboard': ['prompts/*.txt', 'cassettes/*.yaml'],
                  'cap_lmp_ros.domains.controllers': ['prompts/*.txt', 'cassettes/*.yaml']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', glob('config/*.yaml')),
    ],
    install_requires=['setuptools'],
    zip_safe=False,
    maintainer='cap-ros maintainers',
    maintainer_email='maintainers@cap-ros.dev',
    description=('The ROS binding of the LMP engine: lmp_node, its command queue, and the domain registry with the '
                 'table-top and whiteboard domains (prompts, LMPs, robot APIs).'),
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'lmp_node = cap_lmp_ros.lmp_node:main',
        ],
    },
)
