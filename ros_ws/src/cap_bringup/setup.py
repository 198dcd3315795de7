from glob import glob

from setuptools import find_packages, setup

package_name = 'cap_bringup'

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
    description='Bringup of the cap-ros graph: the one-process graph, the cap command, the demo, the web console, '
                'RViz markers and launch files.',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'cap = cap_bringup.cli:main',
            'console = cap_bringup.console.node:main',
            'visualization_node = cap_bringup.visualization_node:main',
        ],
    },
)
