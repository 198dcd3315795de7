from setuptools import find_packages, setup

package_name = 'cap_bench'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    package_data={'cap_bench.codegen': ['prompts/*.txt'], 'cap_bench.humaneval': ['prompts/*.txt'],
                  'cap_bench.reasoning': ['prompts/*.txt']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='cap-ros maintainers',
    maintainer_email='maintainers@cap-ros.dev',
    description='The Code as Policies benchmarks: the simulated table top, robot code generation, HumanEval, '
                'spatial reasoning.',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
        ],
        # `cap bench tabletop` (cap_bringup's command line finds benchmarks through this group).
        'cap_ros.benchmarks': [
            'tabletop = cap_bench.runner:main',
            'whiteboard = cap_bench.whiteboard.bench:main',
            'mobile = cap_bench.mobile.bench:main',
            'codegen = cap_bench.codegen.bench:main',
            'humaneval = cap_bench.humaneval.bench:main',
            'reasoning = cap_bench.reasoning.bench:main',
            'devset = cap_bench.devset.bench:main',
            'controllers = cap_bench.controllers.bench:main',
        ],
    },
)
