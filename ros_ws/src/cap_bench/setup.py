from pathlib import Path

from setuptools import find_packages, setup

package_name = 'cap_bench'
FOLDERS = sorted(path for path in Path(package_name).iterdir() if (path / '__init__.py').is_file())
# Every folder with a bench.py is a benchmark, offered by the folder's name, so none is forgotten in a list.
BENCHMARKS = [folder.name for folder in FOLDERS if (folder / 'bench.py').is_file()]
# What a folder holds besides Python (e.g. prompts/*.txt) is loaded relative to its modules: it travels with them.
DATA = {f'{package_name}.{folder.name}': sorted({(path.parent.relative_to(folder) / f'*{path.suffix}').as_posix()
                                                 for path in folder.rglob('*') if path.is_file()
                                                 and path.suffix not in ('.py', '.pyc')}) for folder in FOLDERS}

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    package_data={module: patterns for module, patterns in DATA.items() if patterns},
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
        # `cap bench NAME` (cap_bringup's command line finds benchmarks through this group).
        # `cap bench results` writes the results page from the kept runs of all of them (cap_bench/results.py).
        'cap_ros.benchmarks': [f'{name} = {package_name}.{name}.bench:main' for name in BENCHMARKS]
        + [f'results = {package_name}.results:main'],
    },
)
