from setuptools import find_packages, setup

package_name = 'cap_mobile'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    package_data={},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
    ],
    install_requires=['setuptools'],
    zip_safe=False,
    maintainer='cap-ros maintainers',
    maintainer_email='maintainers@cap-ros.dev',
    description=('Facts of the mobile kitchen domain (pure Python): the room, its furniture, named locations and '
                 'bins, and the mobile base.'),
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
        ],
    },
)
