from glob import glob

from setuptools import find_packages, setup

package_name = 'cap_llm'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    # Prompts, reference cassettes and the guard helpers' source are read at run time from the package folder.
    package_data={package_name: ['prompts/*.txt', 'cassettes/*.yaml']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', glob('config/*.yaml')),
    ],
    install_requires=['setuptools'],
    zip_safe=False,
    maintainer='cap-ros maintainers',
    maintainer_email='maintainers@cap-ros.dev',
    description='Language model programs: prompts, hierarchical code generation, sandboxed execution, LLM clients, lmp_node.',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'lmp_node = cap_llm.lmp_node:main',
            'cap = cap_llm.cli:main',
        ],
    },
)
