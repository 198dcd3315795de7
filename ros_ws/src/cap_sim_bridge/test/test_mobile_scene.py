"""The kitchen scene in MuJoCo: the furniture from cap_mobile's layout, the mobile base on its servos, the arm stowed
over it, the head camera."""
from __future__ import annotations

import math

import numpy as np
import pytest
from cap_mobile import layout, robot

from cap_sim_bridge.world import ARM_JOINT_NAMES, World


@pytest.fixture(scope='module')
def world():
    return World('mobile', seed=0)


@pytest.fixture(autouse=True)
def fresh(world):
    world.reset(0)


def test_every_piece_of_furniture_stands_where_the_layout_says(world):
    model = world.model
    for piece in layout.FURNITURE:
        name = piece.name.replace(' ', '_')
        geoms = [model.geom(g).name for g in range(model.ngeom) if model.geom(g).name.startswith(name)]
        assert geoms, f'no geoms for {piece.name}'
        x_min, y_min, x_max, y_max = piece.footprint
        for geom in geoms:
            x, y, _ = world.data.geom(geom).xpos
            assert x_min - 1e-6 <= x <= x_max + 1e-6 and y_min - 1e-6 <= y <= y_max + 1e-6, geom


def test_the_base_starts_at_the_start_pose_with_the_arm_stowed_inside_its_footprint(world):
    assert world.base_pose() == pytest.approx(layout.START_POSE, abs=1e-6)
    assert world.joint_positions() == pytest.approx(robot.STOWED_JOINTS, abs=0.01)
    model, data = world.model, world.data
    arm_bodies = [model.body(b).name for b in range(model.nbody)
                  if model.body(b).name not in ('world',) and model.body_rootid[b] == model.body('base').id]
    for body in arm_bodies:
        x, y, z = data.body(body).xpos
        assert math.hypot(x, y) < layout.BASE_RADIUS, body
        assert z < robot.HEAD_CAMERA_POSITION[2], body


def test_the_base_follows_a_timed_path_to_the_millimetre_and_turns_about_its_centre(world):
    start = world.time
    end = world.follow_base_trajectory([2.0, 4.0], [[0.6, -0.4, 0.0], [0.6, -0.4, math.pi / 2]])
    errors = []
    while world.time < end:
        world.run_for(0.1)
        reference, _ = world.base_reference()
        errors.append(np.abs(world.base_pose() - reference).max())
    world.run_for(0.5)
    assert end == pytest.approx(start + 4.0, abs=0.01)
    assert max(errors) < 0.01
    assert world.base_pose() == pytest.approx([0.6, -0.4, math.pi / 2], abs=0.002)
    assert np.abs(world.base_velocity()).max() < 1e-3
    assert world.joint_positions() == pytest.approx(robot.STOWED_JOINTS, abs=0.01), 'the arm rode along, stowed'


def test_the_base_is_stopped_by_furniture_it_drives_into(world):
    counter = layout.location('countertop')
    _, y_min, _, _ = counter.footprint
    # Straight at the counter's front (a cabinet down to the floor), as if the map did not have it.
    world.follow_base_trajectory([8.0], [[counter.centre[0], counter.centre[1], 0.0]])
    world.run_for(9.0)
    _, y, _ = world.base_pose()
    assert 2.0 < y + layout.BASE_RADIUS < y_min + 0.05, 'the base drove into the counter'


def test_a_held_base_comes_to_rest_within_half_a_second(world):
    world.follow_base_trajectory([4.0], [[2.0, 0.0, 0.0]])
    world.run_for(1.5)
    assert world.base_velocity()[0] > 0.3
    world.hold_base()
    world.run_for(0.5)
    halted = world.base_pose()
    assert np.abs(world.base_velocity()).max() < 0.01
    world.run_for(0.5)
    assert np.abs(world.base_pose() - halted).max() < 0.001


def test_the_head_camera_sees_the_room(world):
    assert robot.HEAD_CAMERA in world.camera_names
    rgb, depth = world.render(robot.HEAD_CAMERA, 160, 120)
    assert rgb.shape == (120, 160, 3) and rgb.std() > 10
    assert np.nanmax(depth) < 12.0 and np.nanmin(depth) > 0.05


def test_the_arm_joints_are_the_arms_and_the_base_joints_are_published_as_the_scenes(world):
    assert set(robot.BASE_JOINT_NAMES) <= set(world.scene_joint_names())
    assert not set(ARM_JOINT_NAMES) & set(world.scene_joint_names())


def test_objects_stand_on_the_furniture_and_the_head_camera_sees_only_what_is_in_front_of_it(world):
    from cap_mobile import objects
    states = world.object_states()
    assert [s.name for s in states] == objects.default_objects(0)
    for state in states:
        surface = objects.surface_of(*state.position[:2])
        assert surface in objects.SURFACES, state.name
        assert state.bbox_min[2] == pytest.approx(layout.location(surface).top, abs=0.005), f'{state.name} rests'
    # Turned away from everything (facing the wall behind the start), the camera sees nothing; facing each object
    # from a metre and a half away in the open, it sees that one.
    world.follow_base_trajectory([3.0], [[0.0, 0.0, math.pi]])
    world.run_for(3.5)
    assert not any(s.visible for s in world.object_states() if s.position[0] > 0.5)
    seen_table = [s for s in states if objects.surface_of(*s.position[:2]) == 'table']
    approach = layout.location('table').approach()
    world.follow_base_trajectory([8.0], [list(approach[:2]) + [world.base_pose()[2] - math.pi / 2]])
    world.run_for(8.5)
    assert world.base_pose()[:2] == pytest.approx(approach[:2], abs=0.01)
    now = {s.name: s.visible for s in world.object_states()}
    assert all(now[s.name] for s in seen_table), now


def test_the_view_from_a_base_pose_is_the_view_after_driving_there_and_asking_it_moves_nothing(world):
    names = [s.name for s in world.object_states()]
    approach = layout.location('table').approach()
    poses = [layout.START_POSE, approach, (0.0, 0.0, math.pi)]
    before, time = world.base_pose(), world.time
    views = [world.visible_with_base_at(pose, names) for pose in poses]
    assert world.base_pose() == pytest.approx(before) and world.time == time
    assert views[0] == [s.visible for s in world.object_states()]
    assert any(views[1]) and not any(views[2])
    world.follow_base_trajectory([8.0], [list(approach[:2]) + [approach[2]]])
    world.run_for(8.5)
    assert views[1] == [s.visible for s in world.object_states()]
