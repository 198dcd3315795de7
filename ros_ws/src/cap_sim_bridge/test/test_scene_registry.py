"""A domain's own scene: offered by another package through an entry point, without editing this one, then simulated
with the arm the world drives."""
import numpy as np
import pytest

from cap_sim_bridge import scenes
from cap_sim_bridge.world import World

# A small table with one fixed box on it, one camera, and the robot.
TOY_MJCF = """
<mujoco model="toy">
  <compiler angle="radian" autolimits="true"/>
  <option timestep="0.002" integrator="implicitfast" cone="elliptic"/>
  <include file="ur5e_gripper.xml"/>
  <worldbody>
    <geom name="table" type="box" size="0.2 0.2 0.02" pos="0 -0.5 -0.02" contype="1" conaffinity="3"/>
    <geom name="fixed box" type="box" size="0.03 0.03 0.03" pos="0.1 -0.5 0.03" contype="1" conaffinity="3"/>
    <camera name="overhead" pos="0 -0.5 1.0"/>
  </worldbody>
</mujoco>
"""


TOY_MODULE = f'''
from cap_sim_bridge import scenes
from cap_sim_bridge.objects import ObjectSpec

SCENE = scenes.SceneSpec(
    'toy', build=scenes.mjcf_builder({TOY_MJCF!r}),
    default_objects=lambda seed: [ObjectSpec('red block', 'block', 'red', position=(-0.1, -0.5))],
    camera_names=('overhead',))
MISNAMED = scenes.SceneSpec('not toy', build=SCENE.build)
EMPTY = scenes.SceneSpec('empty', build=lambda objects: scenes.spec_from_mjcf(
    '<mujoco><worldbody><geom name="table" type="plane" size="1 1 0.1"/></worldbody></mujoco>'))
'''


@pytest.fixture
def toy_scene(install_plugin):
    install_plugin({'toy_scene': TOY_MODULE}, {scenes.ENTRY_POINT_GROUP: {
        'toy': 'toy_scene:SCENE', 'misnamed': 'toy_scene:MISNAMED', 'empty': 'toy_scene:EMPTY',
        'not a scene': 'toy_scene:scenes'}})
    return scenes.get_scene('toy')


def test_the_table_top_is_a_built_in_scene():
    assert {'tabletop', 'whiteboard', 'mobile', 'controllers'} <= set(scenes.scene_names())
    assert scenes.get_scene(scenes.DEFAULT_SCENE).camera_names == ('front', 'top')


def test_an_unknown_scene_is_refused_naming_the_known_ones():
    with pytest.raises(ValueError, match='known scenes: .*tabletop'):
        World('no such scene')


def test_a_registered_scene_is_simulated_with_the_arm(toy_scene):
    assert 'toy' in scenes.scene_names()
    with pytest.raises(ValueError, match="offered as 'misnamed' calls itself 'not toy'"):
        scenes.get_scene('misnamed')
    with pytest.raises(ValueError, match="'not a scene'.*is not a scene"):
        scenes.get_scene('not a scene')
    world = World('toy', seed=0)
    assert world.camera_names == ('overhead',)
    [block] = world.object_states()
    assert block.name == 'red block'
    assert np.allclose(block.position[:2], (-0.1, -0.5), atol=0.003)
    assert abs(block.position[2] - 0.02) < 0.002  # resting on the toy table
    goal = np.array([0.6, -2.0, 1.5, -1.0, -1.5708, -0.7])
    world.follow_trajectory([1.0], [goal])
    world.run_for(2.0)
    assert np.allclose(world.joint_positions(), goal, atol=0.01)
    world.command_gripper(opening=0.0, max_force=20.0)
    world.run_for(1.5)
    assert world.gripper_state().opening < 0.005  # nothing between the fingers: they close
    rgb, depth = world.render('overhead', 64, 48)
    assert rgb.shape == (48, 64, 3) and depth.shape == (48, 64)


def test_a_scene_without_the_robot_is_refused(toy_scene):
    with pytest.raises(ValueError, match='lacks part of the UR5e'):
        World('empty')


def test_the_table_top_cameras_are_the_table_top_facts():
    from cap_tabletop.cameras import CAMERAS, optical_orientation_xyzw
    from scipy.spatial.transform import Rotation

    world = World(seed=0, objects=['red block'])
    for name, camera in CAMERAS.items():
        pose = world.camera_pose(name)
        assert np.allclose(pose[:3, 3], camera.position, atol=1e-6)
        assert np.allclose(pose[:3, :3], Rotation.from_quat(optical_orientation_xyzw(camera)).as_matrix(), atol=1e-4)
        assert world.model.camera(name).fovy[0] == camera.fovy
