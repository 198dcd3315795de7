"""The mobile domain in the engine: the paper's navigation commands from the reference cassette, with a robot that
records where it is sent (and is there at once), and the API's checks of what programs pass."""
import math

import numpy as np
import pytest
from cap_mobile import layout

from cap_lmp.cassette import CassetteClient
from cap_lmp.errors import RobotApiError
from cap_lmp_ros.domains.mobile.poses import floor_point, location_name, traj_poses
from cap_lmp_ros.domains.registry import get_domain

SESSION = ('go to the table', 'move in a 3m by 2m rectangle around the office chair',
           'do that again but rotated 45 degrees clockwise', 'follow the convex hull containing the chairs',
           'move back and forth between the table and the countertop 3 times', 'how far are you from the desk',
           'how many snacks are on the table?')
TABLE = np.array(layout.location('table').centre)
# Two snacks and a drink on the table, a snack on the desk (the robot's fake camera sees everything).
OBJECTS = {'chips bag': TABLE + [0.3, 0.1], 'energy bar': TABLE + [-0.4, -0.2], 'coke can': TABLE + [0.0, 0.2],
           'granola bar': np.array(layout.location('desk').centre)}


class Base:
    """The mobile robot's functions, recording each drive and teleporting only this fake's pose."""

    def __init__(self):
        self.pose = np.array(layout.START_POSE, dtype=float)
        self.drives: list[tuple[str, object]] = []
        self.said: list[str] = []

    def functions(self):
        return {'get_obj_names': lambda: list(OBJECTS), 'get_visible_obj_names': lambda: list(OBJECTS),
                'is_obj_visible': lambda name: name in OBJECTS, 'get_obj_pos': lambda name: OBJECTS[name].copy(),
                'get_loc_names': lambda: list(layout.LOCATION_NAMES),
                'get_loc_pos': lambda name: np.array(layout.location(location_name(name)).centre),
                'get_robot_pos_and_angle': lambda: (self.pose[:2].copy(), float(self.pose[2])),
                'goto_pos': self.goto_pos, 'goto_loc': self.goto_loc, 'follow_traj': self.follow_traj,
                'pick_obj': lambda name: self.drives.append(('pick', name)),
                'place_at_pos': lambda pos: self.drives.append(('place', floor_point(pos))),
                'place_at_obj': lambda name: self.drives.append(('place on', name)), 'say': self.said.append}

    def goto_loc(self, name):
        self.pose = np.array(layout.location(location_name(name)).approach())
        self.drives.append(('loc', location_name(name)))

    def goto_pos(self, pos, angle=None):
        point = floor_point(pos)
        self.pose = np.array([*point, self.pose[2] if angle is None else angle])
        self.drives.append(('pos', point))

    def follow_traj(self, pts):
        poses = traj_poses(pts, self.pose)
        self.pose = np.array(poses[-1])
        self.drives.append(('traj', np.array(poses)))


def test_the_reference_session_drives_the_papers_shapes_and_remembers_the_last_one():
    domain = get_domain('mobile')
    robot = Base()
    engine = domain.build_engine(robot.functions(), CassetteClient(domain.cassette))
    for command in SESSION:
        result = engine.run(command)
        assert result.success, (command, result.error)
    kinds = [kind for kind, _ in robot.drives]
    assert kinds == ['loc', 'traj', 'traj', 'traj'] + ['loc'] * 7
    chair = np.array(layout.location('office chair').centre)
    rectangle, rotated = robot.drives[1][1], robot.drives[2][1]
    assert np.ptp(rectangle[:, 0]) == pytest.approx(3.0) and np.ptp(rectangle[:, 1]) == pytest.approx(2.0)
    assert rectangle[:, :2].mean(axis=0) == pytest.approx(chair, abs=0.5)
    # Rotated 45 degrees clockwise about the same centre: each corner's bearing from the centre drops by 45 degrees.
    before = np.degrees(np.arctan2(*(rectangle[0, :2] - chair)[::-1]))
    after = np.degrees(np.arctan2(*(rotated[0, :2] - chair)[::-1]))
    assert (before - after) % 360 == pytest.approx(45, abs=0.5)
    hull = robot.drives[3][1]
    for name in ('office chair', 'chair'):
        centre = layout.location(name).centre
        assert min(math.dist(centre, p[:2]) for p in hull) > 0.3, 'the path goes around the chairs'
    assert [name for _, name in robot.drives[4:10]] == ['table', 'countertop'] * 3
    assert robot.said[0].endswith('meters from the desk')
    assert robot.said[1] == 'There are 2 snacks on the table'



def test_the_session_remembers_which_bin_is_which_and_puts_things_away_there():
    """The paper's "this is the compost bin": the bins are named by colour, the user says what each one takes."""
    domain = get_domain('mobile')
    robot = Base()
    engine = domain.build_engine(robot.functions(), CassetteClient(domain.cassette))
    for command in ('go to the green bin', 'this is the compost bin', 'go to the blue bin', 'this is the recycle bin',
                    'go to the grey bin', 'this is the landfill bin', 'the coke can and the apple are on the table',
                    'put away the coke can and the apple on their corresponding bins'):
        result = engine.run(command)
        assert result.success, (command, result.error)
    handled = [(kind, tuple(np.round(target, 3)) if kind == 'place' else target) for kind, target in robot.drives[3:]]
    assert handled == [('pick', 'coke can'), ('place', layout.location('blue bin').centre),
                       ('pick', 'apple'), ('place', layout.location('green bin').centre)]


def test_every_place_the_reference_session_drives_to_is_free_for_the_base():
    """The kitchen's layout leaves room for the paper's shapes: no corner lies in furniture or near a wall."""
    from cap_control.navigation.executor import NavigationConfig
    grid = NavigationConfig().grid()
    robot = Base()
    domain = get_domain('mobile')
    engine = domain.build_engine(robot.functions(), CassetteClient(domain.cassette))
    for command in SESSION:
        engine.run(command)
    for kind, target in robot.drives:
        points = target[:, :2] if kind == 'traj' else [layout.location(target).approach()[:2]] if kind == 'loc' \
            else [target]
        assert all(grid.is_free(point) for point in points), (kind, target)


@pytest.mark.parametrize('bad, words', [('here', 'must be'), ([1.0], '1 numbers'), ([0.0, math.nan], 'not a number')])
def test_positions_that_are_not_points_are_clear_errors(bad, words):
    with pytest.raises(RobotApiError, match=words):
        floor_point(bad)


def test_trajectories_face_along_each_leg_and_drop_repeated_points():
    poses = traj_poses([[1.0, 0.0], [1.0, 0.0], [1.0, 1.0]], (0.0, 0.0, 0.0))
    assert [p[:2] for p in poses] == [(1.0, 0.0), (1.0, 1.0)]
    assert poses[0][2] == pytest.approx(0.0) and poses[1][2] == pytest.approx(math.pi / 2)
    with pytest.raises(RobotApiError, match='at most'):
        traj_poses(np.zeros((500, 2)), (0.0, 0.0, 0.0))


def test_a_location_is_named_loosely_and_an_unknown_one_lists_the_known_ones():
    assert location_name('The Office_Chair') == 'office chair'
    with pytest.raises(RobotApiError, match='Known locations: countertop'):
        location_name('the garage')
    with pytest.raises(RobotApiError, match='text'):
        location_name(3)


@pytest.mark.parametrize('name', ['mobile_ui', 'parse_obj_name', 'parse_position', 'transform_traj', 'fgen'])
def test_every_prompt_is_code_the_sandbox_accepts_calling_only_what_generated_code_has(name):
    import ast

    from cap_lmp.functions import undefined_calls
    from cap_lmp.prompts import load_prompt
    from cap_lmp.sandbox import check_code
    from cap_lmp_ros.domains.mobile.lmps import PROMPTS_DIR
    body = load_prompt(PROMPTS_DIR, name).split('\n\n', 1)[1]
    check_code(body)
    engine = get_domain('mobile').build_engine(Base().functions(), client=None)
    known = set(engine.scope) | set(engine.scope['__builtins__'])
    fgen = ast.parse(load_prompt(PROMPTS_DIR, 'fgen'))
    known |= {node.name for node in fgen.body if isinstance(node, ast.FunctionDef)}
    assert not {call.name for call in undefined_calls(ast.parse(body), known)}
    # No example of a prompt is one of the paper's commands the reference cassette (and the demo) answers.
    assert not any(command in body for command in SESSION)
