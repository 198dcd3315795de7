"""A domain's own scene: registered without editing the package, then simulated with the arm the world drives."""
import numpy as np
import pytest

from cap_sim_bridge import scenes
from cap_sim_bridge.scene import ObjectSpec
from cap_sim_bridge.world import TabletopWorld

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


@pytest.fixture
def toy_scene():
    spec = scenes.register_scene(scenes.SceneSpec(
        'toy', build=scenes.mjcf_builder(TOY_MJCF),
        default_objects=lambda seed: [ObjectSpec('red block', 'block', 'red', position=(-0.1, -0.5))],
        camera_names=('overhead',)))
    yield spec
    scenes.unregister_scene('toy')


def test_the_table_top_is_a_built_in_scene():
    assert 'tabletop' in scenes.scene_names()
    assert scenes.get_scene(scenes.DEFAULT_SCENE).camera_names == ('front', 'top')


def test_an_unknown_scene_is_refused_naming_the_known_ones():
    with pytest.raises(ValueError, match='known scenes: .*tabletop'):
        TabletopWorld('no such scene')


def test_a_registered_scene_is_simulated_with_the_arm(toy_scene):
    assert 'toy' in scenes.scene_names()
    with pytest.raises(ValueError, match='already registered'):
        scenes.register_scene(scenes.SceneSpec('toy', build=scenes.mjcf_builder(TOY_MJCF)))
    world = TabletopWorld('toy', seed=0)
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


def test_a_scene_without_the_robot_is_refused():
    scenes.register_scene(scenes.SceneSpec('empty', build=lambda objects: scenes.spec_from_mjcf(
        '<mujoco><worldbody><geom name="table" type="plane" size="1 1 0.1"/></worldbody></mujoco>')))
    try:
        with pytest.raises(ValueError, match='lacks part of the UR5e'):
            TabletopWorld('empty')
    finally:
        scenes.unregister_scene('empty')


def test_the_table_top_cameras_are_the_table_top_facts():
    from cap_tabletop.cameras import CAMERAS, optical_orientation_xyzw
    from scipy.spatial.transform import Rotation

    world = TabletopWorld(seed=0, objects=['red block'])
    for name, camera in CAMERAS.items():
        pose = world.camera_pose(name)
        assert np.allclose(pose[:3, 3], camera.position, atol=1e-6)
        assert np.allclose(pose[:3, :3], Rotation.from_quat(optical_orientation_xyzw(camera)).as_matrix(), atol=1e-4)
        assert world.model.camera(name).fovy[0] == camera.fovy
