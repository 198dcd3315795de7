from glob import glob

from setuptools import find_packages, setup

package_name = 'cap_hardware'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    # The shipped profiles travel with the Python package (cap_hardware.profiles.shipped_profile finds them) and
    # are installed into share/ for users to copy.
    package_data={package_name: ['profiles/*.yaml']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/profiles', glob(package_name + '/profiles/*.yaml')),
    ],
    install_requires=['setuptools'],
    zip_safe=False,
    maintainer='cap-ros maintainers',
    maintainer_email='maintainers@cap-ros.dev',
    description=('Hardware profiles of cap-ros (pure Python): the interfaces, frames, calibration and limits of a '
                 'real robot, and what a preflight checks.'),
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
        ],
    },
)
