"""Pick-and-place plans: the right stages in the right order, safe heights, workspace limits, clear failures."""
import math
import re

import numpy as np
import pytest
from cap_interfaces.action import PickPlace
from cap_tabletop import objects
from cap_tabletop.cameras import TOP

from cap_control.kinematics import HOME_JOINTS, forward_kinematics, inverse_kinematics, top_down_pose
from cap_control.pick_place.plan import (
    GripperStep, LiftCheck, ObjectInfo, Observation, PickPlaceConfig, PickPlaceError,
    PickPlaceErrorCode, PlacedCheck, StageName, TrajectoryStep, Workspace, allowed_target_range,
    check_place_on_table, clear_of_bowl_rims, footprint_half_extents, plan_pick_place, target_taken_by,
    yaw_of_quaternion,
)
from cap_control.trajectory import UR5E_LIMITS, trajectory_tcp_positions

BLOCK_SIZE = (objects.BLOCK_SIZE,) * 3
STAGE_ORDER = ['approach', 'descend', 'grasp', 'verify', 'lift', 'move', 'place', 'release', 'retreat']


def block(name: str, x: float, y: float, yaw: float = 0.0, z: float = 0.02) -> ObjectInfo:
    return ObjectInfo(name, (x, y, z), BLOCK_SIZE, objects.CATEGORY_BLOCK, yaw)


def bowl(name: str, x: float, y: float) -> ObjectInfo:
    return ObjectInfo(name, (x, y, 0.03), (0.14, 0.14, 0.06), objects.CATEGORY_BOWL)


def trajectory_steps(plan):
    return [(stage.name, step) for stage in plan.stages for step in stage.steps if isinstance(step, TrajectoryStep)]


def stage(plan, name: StageName):
    return next(s for s in plan.stages if s.name == name)


def test_error_codes_and_stage_names_are_those_of_the_action():
    for code in PickPlaceErrorCode:
        assert getattr(PickPlace.Result, code.name) == code.value
    for name in StageName:
        assert getattr(PickPlace.Feedback, 'STAGE_' + name.name) == name.value


def test_block_into_bowl_plan_runs_the_stages_in_order_and_chains_its_motions():
    red, blue_bowl = block('red block', 0.1, -0.6, yaw=0.3), bowl('blue bowl', -0.2, -0.4)
    plan = plan_pick_place(red, blue_bowl, HOME_JOINTS)
    assert [s.name.value for s in plan.stages] == STAGE_ORDER
    assert [s.progress for s in plan.stages] == sorted(s.progress for s in plan.stages)
    assert plan.stages[-1].progress == 1.0
    joints = HOME_JOINTS
    for _, step in trajectory_steps(plan):
        np.testing.assert_allclose(step.trajectory.start, joints, atol=1e-12)
        assert np.all(np.abs(step.trajectory.velocities) <= UR5E_LIMITS.velocity * (1 + 1e-6))
        joints = step.trajectory.end
    # Gripper: open on the way, closed with force to grasp, open to release.
    assert isinstance(stage(plan, StageName.APPROACH).steps[0], GripperStep)
    opening = stage(plan, StageName.APPROACH).steps[0]
    # Fully open, while the arm travels (not before), and no gripper motion when the fingers are open already.
    assert opening.position == PickPlaceConfig().gripper_open_width and not opening.wait
    assert opening.unless_open_at_least < opening.position
    close = stage(plan, StageName.GRASP).steps[0]
    # Inside the block's width: the fingers stop on it and squeeze with the full force.
    assert close.position < 0.04 and close.max_effort > 0
    assert 0.05 <= stage(plan, StageName.RELEASE).steps[0].position <= 0.07, 'opens enough, not against a bowl wall'


def test_grasp_holds_the_block_at_its_middle_square_to_its_faces():
    red = block('red block', -0.15, -0.7, yaw=0.4)
    plan = plan_pick_place(red, (0.2, -0.3), HOME_JOINTS)
    grasp_pose = forward_kinematics(stage(plan, StageName.DESCEND).steps[-1].trajectory.end)
    np.testing.assert_allclose(grasp_pose[:3, 3], red.position, atol=1e-6)
    np.testing.assert_allclose(grasp_pose[:3, 2], [0, 0, -1], atol=1e-6)
    yaw = math.atan2(grasp_pose[1, 0], grasp_pose[0, 0])
    assert math.remainder(yaw - 0.4, math.pi / 2) == pytest.approx(0.0, abs=1e-6)
    descent = trajectory_tcp_positions(stage(plan, StageName.DESCEND).steps[-1].trajectory)
    np.testing.assert_allclose(descent[:, :2], [red.position[:2]] * len(descent), atol=1e-6)
    assert not stage(plan, StageName.DESCEND).steps[-1].stop_on_contact


@pytest.mark.parametrize('target_kind', ['block', 'bowl', 'table'])
def test_place_height_stacks_on_blocks_drops_into_bowls_and_sets_down_on_the_table(target_kind):
    red = block('red block', 0.15, -0.45)
    target = {'block': block('green block', -0.1, -0.65, yaw=0.2), 'bowl': bowl('blue bowl', -0.1, -0.65),
              'table': (-0.1, -0.65)}[target_kind]
    plan = plan_pick_place(red, target, HOME_JOINTS)
    descent, place_step = stage(plan, StageName.PLACE).steps
    assert place_step.stop_on_contact and place_step.contact_tolerance > 0
    # Fast down to just above the contact (no touch-down read there: the servos lag at full acceleration), then
    # slowly at the touch-down limits.
    assert not descent.stop_on_contact
    descent_end = forward_kinematics(descent.trajectory.end)[2, 3]
    assert descent_end == pytest.approx(plan.place_z + plan.config.touchdown_height, abs=1e-6)
    assert place_step.limits == plan.config.touchdown_limits
    place_pose = forward_kinematics(place_step.trajectory.end)
    np.testing.assert_allclose(place_pose[:2, 3], [-0.1, -0.65], atol=1e-6)
    held_bottom = place_pose[2, 3] - (plan.grasp_z - red.bottom)
    if target_kind == 'block':
        assert 0.0 < held_bottom - target.top <= 0.01, 'released just above the block below'
        yaw = math.atan2(place_pose[1, 0], place_pose[0, 0])
        assert math.remainder(yaw - 0.2, math.pi / 2) == pytest.approx(0.0, abs=1e-6), 'square with the block'
    elif target_kind == 'bowl':
        assert target.bottom < held_bottom < target.top - 0.02, 'released inside the bowl, below its rim'
    else:
        assert 0.0 < held_bottom <= 0.01, 'released just above the table'


def test_set_down_by_a_bowl_the_descent_slows_above_its_rim():
    """The held block's footprint reaches over the bowl's rim: the fast descent ends above the rim (which the block
    meets first), and the slow touch-down goes on from there to the table."""
    red = block('red block', 0.15, -0.45)
    blue = bowl('blue bowl', -0.1, -0.65)
    # (With rim_shift the point would move clear of the rim: see the test below.)
    plan = plan_pick_place(red, (-0.1, -0.565), HOME_JOINTS, PickPlaceConfig(rim_shift=0.0), neighbours=[blue])
    descent, place_step = stage(plan, StageName.PLACE).steps
    held_below_tcp = plan.grasp_z - red.bottom
    descent_end = forward_kinematics(descent.trajectory.end)[2, 3]
    assert descent_end == pytest.approx(blue.top + held_below_tcp + plan.config.touchdown_height, abs=1e-6)
    assert place_step.stop_on_contact
    assert forward_kinematics(place_step.trajectory.end)[2, 3] == pytest.approx(plan.place_z, abs=1e-6)
    # Away from the bowl, the descent ends just above the table as usual.
    clear = plan_pick_place(red, (0.1, -0.55), HOME_JOINTS, PickPlaceConfig(rim_shift=0.0), neighbours=[blue])
    clear_end = forward_kinematics(stage(clear, StageName.PLACE).steps[0].trajectory.end)[2, 3]
    assert clear_end == pytest.approx(clear.place_z + clear.config.touchdown_height, abs=1e-6)


def rim_gap(obj: ObjectInfo, xy, bowl_info: ObjectInfo) -> float:
    half_x, half_y = footprint_half_extents(obj)
    dx = max(abs(xy[0] - bowl_info.position[0]) - half_x, 0.0)
    dy = max(abs(xy[1] - bowl_info.position[1]) - half_y, 0.0)
    return math.hypot(dx, dy) - footprint_half_extents(bowl_info)[0]


def test_a_point_whose_block_would_come_down_on_a_bowls_rim_moves_just_clear_of_it():
    """Set down reaching over a rim, a block slides off it: the place moves (at most rim_shift) to the nearest point
    where the block's footprint clears the rim, the check after placing still judges it against the point asked
    for, and the log says where it went."""
    red = block('red block', 0.15, -0.45)
    blue = bowl('blue bowl', -0.1, -0.65)
    asked = (-0.1, -0.565)
    assert rim_gap(red, asked, blue) < 0
    plan = plan_pick_place(red, asked, HOME_JOINTS, neighbours=[blue])
    placed = forward_kinematics(stage(plan, StageName.PLACE).steps[-1].trajectory.end)[:2, 3]
    shift = math.dist(placed, asked)
    assert 0 < shift <= plan.config.rim_shift
    assert rim_gap(red, placed, blue) >= 0.0049
    assert 'clear of the blue bowl\'s rim' in plan.target_description
    placed_check = stage(plan, StageName.RETREAT).checks[0]
    assert tuple(placed_check.target_xy) == asked
    # Clear of the rim, the descent is fast down to the table.
    descent_end = forward_kinematics(stage(plan, StageName.PLACE).steps[0].trajectory.end)[2, 3]
    assert descent_end == pytest.approx(plan.place_z + plan.config.touchdown_height, abs=1e-6)


def test_a_point_inside_a_bowl_or_without_a_clear_point_near_it_stays():
    red = block('red block', 0.15, -0.45)
    blue = bowl('blue bowl', -0.1, -0.65)
    config = PickPlaceConfig()
    inside = (-0.1, -0.63)  # all of the block within the rim: into the bowl
    assert clear_of_bowl_rims(red, inside, [blue], config) == (inside, None)
    # Between two bowls 15 cm apart there is no point within 2 cm clear of both rims.
    green = bowl('green bowl', -0.1, -0.5)
    between = (-0.1, -0.575)
    assert clear_of_bowl_rims(red, between, [blue, green], config) == (between, None)
    # Near a table edge the moved point stays where the whole block is on the table.
    edge_bowl = bowl('edge bowl', -0.15, -0.3)
    asked = (-0.08, -0.24)
    moved, rim_of = clear_of_bowl_rims(red, asked, [edge_bowl], config)
    (x_low, x_high), (y_low, y_high) = allowed_target_range(red, config)
    assert rim_of is edge_bowl and y_low <= moved[1] <= y_high and x_low <= moved[0] <= x_high


def test_a_block_goes_into_a_bowl_squarely_on_top_of_the_blocks_already_there():
    red = block('red block', 0.15, -0.45)
    blue_bowl = bowl('blue bowl', -0.1, -0.65)
    inside = [block('green block', -0.09, -0.655, yaw=0.3, z=0.026), block('yellow block', -0.092, -0.652, yaw=0.31,
                                                                         z=0.066)]
    outside = block('pink block', 0.1, -0.3, z=0.1)  # taller, but not in the bowl
    plan = plan_pick_place(red, blue_bowl, HOME_JOINTS, neighbours=inside + [outside, red])
    place_pose = forward_kinematics(stage(plan, StageName.PLACE).steps[-1].trajectory.end)
    np.testing.assert_allclose(place_pose[:2, 3], [-0.092, -0.652], atol=1e-6)
    held_bottom = place_pose[2, 3] - (plan.grasp_z - red.bottom)
    assert 0.0 < held_bottom - inside[1].top <= 0.01, 'released just above the top block'
    yaw = math.atan2(place_pose[1, 0], place_pose[0, 0])
    assert math.remainder(yaw - 0.31, math.pi / 2) == pytest.approx(0.0, abs=1e-6), 'square with the top block'
    # An empty bowl: dropped at its centre, near its floor.
    plan = plan_pick_place(red, blue_bowl, HOME_JOINTS, neighbours=[outside])
    np.testing.assert_allclose(forward_kinematics(stage(plan, StageName.PLACE).steps[0].trajectory.end)[:2, 3],
                               [-0.1, -0.65], atol=1e-6)


@pytest.mark.parametrize('neighbour_xy', [(0.07, 0.0), (0.0, 0.07), (-0.065, 0.0), (0.0, -0.065)])
def test_the_fingers_close_across_the_side_with_room_when_a_neighbour_stands_close(neighbour_xy):
    red = block('red block', 0.15, -0.45)
    spot = (-0.05, -0.55)
    neighbour = block('blue block', spot[0] + neighbour_xy[0], spot[1] + neighbour_xy[1])
    plan = plan_pick_place(red, spot, HOME_JOINTS, neighbours=[neighbour])
    place_pose = forward_kinematics(stage(plan, StageName.PLACE).steps[-1].trajectory.end)
    finger_axis = place_pose[:2, 1]  # the fingers close along the TCP y axis
    towards = np.array(neighbour_xy) / np.linalg.norm(neighbour_xy)
    assert abs(float(finger_axis @ towards)) < 0.75, 'the fingers do not point at the neighbour'
    # Alone, the place yaw is the grasp yaw (no wrist turn needed).
    alone = plan_pick_place(red, spot, HOME_JOINTS)
    assert math.remainder(alone.place_yaw - alone.grasp_yaw, math.pi / 2) == pytest.approx(0.0, abs=1e-6)
    # The open fingers come down beside the block to pick, not onto its neighbour.
    beside = block('green block', red.position[0] + neighbour_xy[0], red.position[1] + neighbour_xy[1])
    plan = plan_pick_place(red, spot, HOME_JOINTS, neighbours=[beside])
    grasp_pose = forward_kinematics(stage(plan, StageName.DESCEND).steps[0].trajectory.end)
    assert abs(float(grasp_pose[:2, 1] @ towards)) < 0.75


@pytest.mark.parametrize('spot', [(0.0, -0.5), (-0.27, -0.77), (0.27, -0.23), (0.25, -0.5)])
def test_with_a_camera_to_clear_the_tool_ends_out_of_its_line_of_sight_to_the_placed_block(spot):
    camera = TOP.position
    red = block('red block', 0.15, -0.45)
    config = PickPlaceConfig(clear_view_from=camera)
    plan = plan_pick_place(red, spot, HOME_JOINTS, config)
    steps = stage(plan, StageName.RETREAT).steps
    assert len(steps) == 2
    tcp = forward_kinematics(steps[-1].trajectory.end)[:3, 3]
    assert tcp[2] == pytest.approx(plan.travel_z, abs=1e-3)
    # The line of sight from the camera to the block, at the tool's height, passes well beside the tool.
    top = objects.BLOCK_SIZE  # the block rests on the table
    block_top = np.array([spot[0], spot[1], top])
    at_tool_height = block_top + (np.array(camera) - block_top) * (tcp[2] - top) / (camera[2] - top)
    assert np.linalg.norm(at_tool_height[:2] - tcp[:2]) > 0.1
    # Without a camera to clear, the tool waits above the block.
    assert len(stage(plan_pick_place(red, spot, HOME_JOINTS), StageName.RETREAT).steps) == 1


def test_the_held_block_passes_high_over_everything_while_moving():
    red = block('red block', 0.2, -0.75)
    tall_stack_top = 0.12
    plan = plan_pick_place(red, block('blue block', -0.2, -0.25, z=tall_stack_top - 0.02), HOME_JOINTS,
                           obstacle_height=tall_stack_top)
    held_below_tcp = plan.grasp_z - red.bottom
    for name in (StageName.MOVE,):
        tcp = trajectory_tcp_positions(stage(plan, name).steps[0].trajectory)
        assert tcp[:, 2].min() - held_below_tcp >= tall_stack_top + 0.01


def test_no_motion_goes_below_the_table_safety_height():
    config = PickPlaceConfig()
    rng = np.random.default_rng(3)
    for _ in range(8):
        obj = block('red block', rng.uniform(-0.2, 0.2), rng.uniform(-0.7, -0.3), rng.uniform(-1, 1))
        plan = plan_pick_place(obj, (rng.uniform(-0.25, 0.25), rng.uniform(-0.75, -0.25)), HOME_JOINTS)
        for _, step in trajectory_steps(plan):
            tcp = trajectory_tcp_positions(step.trajectory)
            assert tcp[:, 2].min() >= config.workspace.table_z + config.workspace.min_tcp_height - 1e-9


@pytest.mark.parametrize('corner', [(-0.25, -0.25), (0.25, -0.25), (-0.25, -0.75), (0.25, -0.75), (0.0, -0.5)])
def test_blocks_can_be_placed_on_every_corner(corner):
    plan = plan_pick_place(block('red block', 0.05, -0.5, 0.7), corner, HOME_JOINTS)
    np.testing.assert_allclose(plan.target_xy, corner)


@pytest.mark.parametrize('obj, target, words', [
    (block('red block', 0.45, -0.5), (0.0, -0.5), 'the red block at (0.450, -0.500) is outside the workspace'),
    (block('red block', 0.0, -0.5), (0.0, -0.95), 'the target point (0.000, -0.950) is outside the workspace'),
    (block('red block', 0.0, -0.5), bowl('blue bowl', 0.0, -0.1), 'the target blue bowl at (0.000, -0.100)'),
    (block('red block', 0.0, -0.5), (-0.31, -0.5), 'outside the workspace'),
])
def test_objects_and_targets_outside_the_workspace_are_refused(obj, target, words):
    with pytest.raises(PickPlaceError, match=re.escape(words)) as raised:
        plan_pick_place(obj, target, HOME_JOINTS)
    assert raised.value.code == PickPlaceErrorCode.OUTSIDE_WORKSPACE


def test_the_allowed_range_keeps_the_whole_block_on_the_table_with_a_margin():
    config = PickPlaceConfig()  # table x in [-0.3, 0.3], y in [-0.8, -0.2]; 1 cm margin
    (x_low, x_high), (y_low, y_high) = allowed_target_range(block('cyan block', 0.0, -0.5), config)
    assert (x_low, x_high, y_low, y_high) == pytest.approx((-0.27, 0.27, -0.77, -0.23))
    # Turned by 45 degrees, a 4 cm cube reaches 2.83 cm out along x and y.
    (x_low, _), (_, y_high) = allowed_target_range(block('cyan block', 0.0, -0.5, yaw=math.pi / 4), config)
    assert x_low == pytest.approx(-0.3 + 0.02 * math.sqrt(2) + 0.01)
    assert y_high == pytest.approx(-0.2 - 0.02 * math.sqrt(2) - 0.01)
    wider = PickPlaceConfig(edge_margin=0.02)
    assert allowed_target_range(block('cyan block', 0.0, -0.5), wider)[0] == pytest.approx((-0.26, 0.26))


@pytest.mark.parametrize('target', [(-0.3, -0.2), (0.3, -0.8), (0.275, -0.5), (0.0, -0.225), (0.0, -0.95)])
def test_a_target_that_would_leave_the_block_overhanging_is_refused_with_the_allowed_range(target):
    with pytest.raises(PickPlaceError) as raised:
        plan_pick_place(block('cyan block', 0.0, -0.5), target, HOME_JOINTS)
    assert raised.value.code == PickPlaceErrorCode.OUTSIDE_WORKSPACE
    message = raised.value.message
    assert f'({target[0]:.3f}, {target[1]:.3f})' in message
    assert 'x in [-0.270, 0.270], y in [-0.770, -0.230]' in message
    assert 'wholly on the table' in message


@pytest.mark.parametrize('xy', [(-0.27, -0.23), (0.27, -0.77), (0.0, -0.5)])
def test_targets_just_inside_the_allowed_range_are_accepted(xy):
    check_place_on_table(block('cyan block', 0.0, -0.5), xy, PickPlaceConfig())


def test_stacking_onto_a_block_that_overhangs_the_edge_is_refused():
    near_edge = block('green block', 0.285, -0.5)  # 5 mm of it beyond the table's right edge
    with pytest.raises(PickPlaceError, match='the green block at \\(0.285, -0.500\\) is too close') as raised:
        plan_pick_place(block('red block', 0.0, -0.5), near_edge, HOME_JOINTS)
    assert raised.value.code == PickPlaceErrorCode.OUTSIDE_WORKSPACE


def test_stacking_onto_a_block_within_the_edge_margin_is_accepted():
    """A block set down at the margin's limit may end a few millimetres beyond it; one stacked on it rests on
    that block, so only the block being wholly on the table counts."""
    past_margin = block('green block', -0.2, -0.225)  # 5 mm past the margin, 5 mm from being over the edge
    plan = plan_pick_place(block('red block', 0.0, -0.5), past_margin, HOME_JOINTS)
    assert plan.target_description == 'the green block'
    with pytest.raises(PickPlaceError, match='the target point \\(-0.200, -0.225\\) is too close'):
        plan_pick_place(block('red block', 0.0, -0.5), (-0.2, -0.225), HOME_JOINTS)  # on the table: the margin


def test_a_point_target_on_another_block_is_refused_naming_it_and_one_in_a_bowl_is_not():
    red, orange = block('red block', 0.0, -0.4), block('orange block', 0.0, -0.55)
    config = PickPlaceConfig()
    assert target_taken_by(red, (0.0, -0.52), [orange], config) is orange
    assert target_taken_by(red, (0.0, -0.5), [orange], config) is None  # 5 cm apart: 1 cm between them
    with pytest.raises(PickPlaceError, match='the orange block at \\(0.000, -0.550\\) is in the way') as raised:
        plan_pick_place(red, (0.0, -0.52), HOME_JOINTS, neighbours=[orange])
    assert raised.value.code == PickPlaceErrorCode.OUTSIDE_WORKSPACE
    assert 'put it on the orange block by name' in raised.value.message
    blue = bowl('blue bowl', 0.1, -0.6)
    assert target_taken_by(red, (0.11, -0.6), [blue, orange], config) is None  # into the bowl


def test_a_point_target_at_a_blocks_own_position_stacks_on_that_block():
    red, orange = block('red block', 0.0, -0.4), block('orange block', 0.0, -0.55)
    at_orange = plan_pick_place(red, (0.005, -0.545), HOME_JOINTS, neighbours=[orange])  # get_obj_pos('orange block')
    named = plan_pick_place(red, orange, HOME_JOINTS, neighbours=[orange])
    assert at_orange.target_description == 'the orange block'
    assert at_orange.place_z == pytest.approx(named.place_z) and at_orange.target_xy == named.target_xy
    (on_block,) = stage(at_orange, StageName.RETREAT).checks
    assert on_block.failure(Observation(object_position=(0.0, -0.55, 0.06))) is None
    # at a tower's position: on its top block, whichever block perception lists first
    top = block('blue block', 0.002, -0.548, z=orange.position[2] + 0.04)
    for neighbours in ([orange, top], [top, orange]):
        on_tower = plan_pick_place(red, (0.0, -0.55), HOME_JOINTS, neighbours=neighbours)
        assert on_tower.target_description == 'the blue block'
        assert on_tower.place_z == pytest.approx(plan_pick_place(red, top, HOME_JOINTS, neighbours=neighbours).place_z)


def test_after_placing_at_a_point_the_block_must_rest_on_the_table_there():
    plan = plan_pick_place(block('red block', 0.0, -0.5), (0.1, -0.3), HOME_JOINTS)
    (placed,) = stage(plan, StageName.RETREAT).checks
    assert placed.failure(Observation(object_position=(0.1, -0.3, 0.02))) is None
    assert 'fell off the table' in placed.failure(Observation(object_position=(0.12, -0.25, -0.73)))
    assert 'fell off the table' in placed.failure(Observation(object_position=(0.1, -0.18, 0.02)))
    assert 'on top of something' in placed.failure(Observation(object_position=(0.1, -0.3, 0.06)))
    assert 'from the target' in placed.failure(Observation(object_position=(0.1, -0.335, 0.02)))
    # On a block, the object rests on top of it.
    stacked = plan_pick_place(block('red block', 0.0, -0.5), block('blue block', 0.1, -0.3), HOME_JOINTS)
    (on_block,) = stage(stacked, StageName.RETREAT).checks
    assert on_block.failure(Observation(object_position=(0.1, -0.3, 0.06))) is None
    assert 'fell off the table' in on_block.failure(Observation(object_position=(0.1, -0.3, -0.7)))


def test_a_narrower_workspace_is_enforced_whatever_the_target():
    config = PickPlaceConfig(workspace=Workspace(x_min=-0.1, x_max=0.1))
    with pytest.raises(PickPlaceError) as raised:
        plan_pick_place(block('red block', 0.0, -0.5), (0.2, -0.5), HOME_JOINTS, config)
    assert raised.value.code == PickPlaceErrorCode.OUTSIDE_WORKSPACE


def test_an_object_too_wide_for_the_gripper_is_refused():
    big = ObjectInfo('gray box', (0.0, -0.5, 0.05), (0.2, 0.2, 0.1))
    with pytest.raises(PickPlaceError, match='does not fit in the gripper') as raised:
        plan_pick_place(big, (0.1, -0.3), HOME_JOINTS)
    assert raised.value.code == PickPlaceErrorCode.GRASP_MISSED


def test_a_long_object_is_grasped_across_its_narrow_side():
    bar = ObjectInfo('brown bar', (0.0, -0.5, 0.02), (0.12, 0.03, 0.04), yaw=0.25)
    plan = plan_pick_place(bar, (0.1, -0.3), HOME_JOINTS)
    fingers = forward_kinematics(stage(plan, StageName.DESCEND).steps[0].trajectory.end)[:3, 1]
    across_bar = np.array([-math.sin(0.25), math.cos(0.25), 0.0])
    assert abs(fingers @ across_bar) == pytest.approx(1.0, abs=1e-6)
    grasp_check = stage(plan, StageName.VERIFY).checks[0]
    assert grasp_check.min_gap < 0.03 < grasp_check.max_gap


def test_placing_an_object_on_itself_is_refused():
    red = block('red block', 0.0, -0.5)
    with pytest.raises(PickPlaceError) as raised:
        plan_pick_place(red, red, HOME_JOINTS)
    assert raised.value.code == PickPlaceErrorCode.TARGET_NOT_FOUND


def test_grasp_check_tells_a_missed_grasp_from_a_held_block():
    plan = plan_pick_place(block('red block', 0.0, -0.5), (0.1, -0.3), HOME_JOINTS)
    verify = stage(plan, StageName.VERIFY)
    assert verify.failure_code == PickPlaceErrorCode.GRASP_MISSED
    check = verify.checks[0]
    assert check.failure(Observation(gripper_position=0.0395, gripper_stalled=True)) is None
    assert 'closed to 0.0 mm' in check.failure(Observation(gripper_position=0.0, gripper_stalled=False))
    assert 'did not stop' in check.failure(Observation(gripper_position=0.04, gripper_stalled=False))
    assert 'wider' in check.failure(Observation(gripper_position=0.08, gripper_stalled=True))


def test_lift_and_place_checks_notice_a_dropped_or_misplaced_block():
    plan = plan_pick_place(block('red block', 0.0, -0.5), (0.1, -0.3), HOME_JOINTS)
    lift = stage(plan, StageName.LIFT)
    assert lift.failure_code == PickPlaceErrorCode.OBJECT_DROPPED
    (lift_check,) = lift.checks
    assert isinstance(lift_check, LiftCheck) and not lift_check.needs_object_position
    assert lift_check.failure(Observation(gripper_position=0.0395)) is None
    assert 'fingers closed to 0.0 mm' in lift_check.failure(Observation(gripper_position=0.0))
    assert 'cannot tell' in lift_check.failure(Observation())
    (placed_check,) = stage(plan, StageName.RETREAT).checks
    assert isinstance(placed_check, PlacedCheck)
    assert placed_check.failure(Observation(object_position=(0.11, -0.31, 0.02))) is None
    assert 'from the target' in placed_check.failure(Observation(object_position=(0.0, -0.5, 0.02)))
    # Hidden from the camera, the object is not judged on a remembered place.
    assert placed_check.failure(Observation(object_position=(0.0, -0.5, 0.02), object_visible=False)) is None
    assert 'not found' in placed_check.failure(Observation())


def test_after_touching_down_early_the_retreat_starts_from_where_the_arm_stopped():
    red, green = block('red block', 0.1, -0.6), block('green block', -0.1, -0.4)
    plan = plan_pick_place(red, green, HOME_JOINTS)
    place = stage(plan, StageName.PLACE).steps[0].trajectory
    stopped = place.positions[len(place) // 2]  # contact halfway down
    retreat_step = stage(plan, StageName.RETREAT).steps[0]
    retreat = plan.trajectory_for(retreat_step, stopped)
    np.testing.assert_array_equal(retreat.start, stopped)
    np.testing.assert_allclose(forward_kinematics(retreat.end), forward_kinematics(retreat_step.trajectory.end),
                               atol=1e-6)
    tcp = trajectory_tcp_positions(retreat)
    np.testing.assert_allclose(tcp[:, :2], [[-0.1, -0.4]] * len(tcp), atol=1e-6)
    # At the planned start, the planned trajectory is used as is.
    assert plan.trajectory_for(retreat_step, retreat_step.trajectory.start) is retreat_step.trajectory


def test_from_a_low_gripper_the_arm_first_rises_straight_up():
    low = inverse_kinematics(top_down_pose((0.2, -0.3, 0.03), 0.0))
    plan = plan_pick_place(block('red block', -0.2, -0.7), (0.0, -0.5), low)
    first = next(step for step in stage(plan, StageName.APPROACH).steps if isinstance(step, TrajectoryStep))
    tcp = trajectory_tcp_positions(first.trajectory)
    np.testing.assert_allclose(tcp[:, :2], [[0.2, -0.3]] * len(tcp), atol=1e-6)
    assert tcp[-1, 2] == pytest.approx(plan.travel_z)


def test_bounding_box_of_a_turned_block_gives_back_its_sides():
    for yaw in (0.0, 0.3, math.pi / 4, 1.2, -0.5):
        c, s = abs(math.cos(yaw)), abs(math.sin(yaw))
        half = 0.02 * (c + s)
        obj = ObjectInfo.from_bounding_box('red block', (0.1 - half, -0.5 - half, 0.0), (0.1 + half, -0.5 + half, 0.04),
                                           yaw=yaw)
        np.testing.assert_allclose(obj.size, BLOCK_SIZE, atol=1e-9)
        np.testing.assert_allclose(obj.position, (0.1, -0.5, 0.02), atol=1e-12)
    bar = ObjectInfo.from_bounding_box('bar', (-0.06, -0.015, 0.0), (0.06, 0.015, 0.04), yaw=0.0)
    np.testing.assert_allclose(bar.size, (0.12, 0.03, 0.04))


def test_random_episodes_of_the_benchmark_all_plan():
    rng = np.random.default_rng(42)
    joints = HOME_JOINTS
    for _ in range(15):
        obj = block('red block', rng.uniform(-0.2, 0.2), rng.uniform(-0.7, -0.3), rng.uniform(-math.pi, math.pi))
        kind = rng.integers(3)
        where = (rng.uniform(-0.25, 0.25), rng.uniform(-0.75, -0.25))
        target = [block('blue block', *where, yaw=rng.uniform(-1, 1)), bowl('blue bowl', *where), where][kind]
        plan = plan_pick_place(obj, target, joints)
        assert plan.duration < 15.0
        joints = trajectory_steps(plan)[-1][1].trajectory.end  # the next episode starts where this one ended


def test_yaw_of_a_block_is_read_whichever_face_it_rests_on():
    from scipy.spatial.transform import Rotation

    for yaw in (0.0, 0.3, -1.1, 2.0):
        upright = Rotation.from_euler('z', yaw).as_quat()  # x, y, z, w
        assert math.remainder(yaw_of_quaternion(*upright) - yaw, math.pi / 2) == pytest.approx(0.0, abs=1e-9)
        on_its_side = (Rotation.from_euler('z', yaw) * Rotation.from_euler('x', math.pi / 2)).as_quat()
        assert math.remainder(yaw_of_quaternion(*on_its_side) - yaw, math.pi / 2) == pytest.approx(0.0, abs=1e-9)
