"""Another package plugs a domain and a scene in through entry points, found in any process that asks for them.

The test writes a tiny installed distribution (a module plus its dist-info with entry_points.txt,
cap_ros_common.testing.write_distribution) into a folder, puts the folder on PYTHONPATH of a fresh interpreter, and
asks the registries there: nothing of the project is edited or imported by the plug-in's name.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

from cap_ros_common.testing import write_distribution

PLUGIN = textwrap.dedent('''
    """A domain and a scene offered by another package."""
    from pathlib import Path

    from cap_lmp_ros.domains.registry import Domain
    from cap_lmp_ros.testing import toy_domain
    from cap_sim_bridge import scenes

    DOMAIN = Domain(name='greenhouse', build_engine=toy_domain.build_engine, robot_functions=('ring_bell',),
                    robot_api=toy_domain.RosToyApi, scene='greenhouse', cassette=Path('greenhouse.yaml'))
    SCENE = scenes.SceneSpec('greenhouse', build=scenes.mjcf_builder(
        '<mujoco><include file="ur5e_gripper.xml"/><worldbody>'
        '<geom name="table" type="box" size="0.3 0.3 0.02" pos="0 -0.5 -0.02"/></worldbody></mujoco>'))
''')
ENTRY_POINTS = {'cap_ros.domains': {'greenhouse': 'greenhouse_plugin:DOMAIN'},
                'cap_ros.scenes': {'greenhouse': 'greenhouse_plugin:SCENE'}}
PROBE = textwrap.dedent('''
    import json
    from cap_lmp_ros.domains.registry import domain_names, get_domain
    from cap_sim_bridge.scenes import get_scene, scene_names
    domain = get_domain('greenhouse')
    print(json.dumps({'domains': domain_names(), 'scenes': scene_names(), 'scene_of_domain': domain.scene,
                      'scene_found': get_scene(domain.scene).name}))
''')


def test_a_domain_and_a_scene_of_another_package_are_found_through_entry_points(tmp_path):
    write_distribution(tmp_path, 'greenhouse-plugin', {'greenhouse_plugin': PLUGIN}, ENTRY_POINTS)
    environment = dict(os.environ, PYTHONPATH=os.pathsep.join([str(tmp_path)] + sys.path))
    answer = subprocess.run([sys.executable, '-c', PROBE], env=environment, capture_output=True, text=True,
                            timeout=120, cwd=tmp_path)
    assert answer.returncode == 0, answer.stderr
    found = json.loads(answer.stdout.strip().splitlines()[-1])
    assert {'greenhouse', 'tabletop'} <= set(found['domains'])
    assert {'greenhouse', 'tabletop'} <= set(found['scenes'])
    assert found['scene_of_domain'] == found['scene_found'] == 'greenhouse'
