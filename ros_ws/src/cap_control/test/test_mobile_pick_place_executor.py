"""MobilePickPlaceExecutor over fake ports: what it refuses before anything moves, and where it sends the base."""
from __future__ import annotations

from concurrent.futures import Future

import numpy as np
import pytest
from cap_mobile import layout, robot

from cap_control.mobile_pick_place.executor import (
    TASK_PICK, TASK_PLACE_AT_OBJECT, TASK_PLACE_AT_POSITION, MobilePickPlaceExecutor, MobileRequest, Navigator,
)
from cap_control.mobile_pick_place.plan import Held, MobileErrorCode
from cap_control.navigation.plan import OccupancyGrid
from cap_control.navigation.executor import NavigationConfig
from cap_control.pick_place.plan import ObjectInfo
from cap_control.ports import Arm, Ending, Gripper, Interruption, ObjectReport, PendingGoal, Perception


def done(value=None) -> Future:
    future: Future = Future()
    future.set_result(value)
    return future


class Goal(PendingGoal):
    def __init__(self, result):
        self._result = done(result)

    @property
    def accepted(self) -> Future:
        return done(True)

    @property
    def result(self) -> Future:
        return self._result

    def cancel(self) -> Future:
        return done()


class Robot(Arm, Gripper, Perception, Navigator):
    """Every port at once: objects by name, a navigator that records its goals and fails when told to."""

    def __init__(self, objects: dict[str, tuple[float, float, float]], navigation_code: int = 0,
                 out_of_view: tuple[str, ...] = (), grid: OccupancyGrid | None = None):
        self.objects = objects
        self.grid = grid if grid is not None else NavigationConfig().grid()  # the navigation node's map
        self.out_of_view = out_of_view  # remembered by perception, not seen now
        self.navigation_code = navigation_code
        self.goals: list[tuple[float, float, float]] = []

    # perception
    def state_service_ready(self) -> Future:
        return done()

    def names_available(self) -> bool:
        return True

    def object_names(self, visible_only: bool = True) -> Future:
        return done([name for name in self.objects if not (visible_only and name in self.out_of_view)])

    def object_state(self, name: str) -> Future:
        if name not in self.objects:
            return done(ObjectReport(False, f'no object named {name!r}'))
        x, y, z = self.objects[name]
        info = ObjectInfo(name, (x, y, z), (0.066, 0.066, 0.122))
        return done(ObjectReport(True, '', info, (x, y, z), name not in self.out_of_view, 0.0))

    # navigation
    def server_ready(self) -> Future:
        return done()

    def map(self) -> OccupancyGrid:
        return self.grid

    def go(self, pose) -> PendingGoal:
        self.goals.append(pose)
        return Goal((self.navigation_code, 'no free path leads there' if self.navigation_code else ''))

    def pose(self) -> Future:
        return done(np.array(self.goals[-1] if self.goals else layout.START_POSE))

    # arm and gripper (no motion is expected in these tests)
    def joints(self) -> Future:
        return done(np.array(robot.STOWED_JOINTS))

    def opening(self) -> float | None:
        return 0.085

    def state_time(self) -> float | None:
        return None

    def follow(self, trajectory, contact_tolerance, goal_tolerance=None) -> PendingGoal:
        raise AssertionError('the arm should not move')

    def command(self, position, max_effort) -> PendingGoal:
        raise AssertionError('the gripper should not move')


def executor(robot_: Robot) -> MobilePickPlaceExecutor:
    return MobilePickPlaceExecutor(robot_, robot_, robot_, robot_)


TABLE = layout.location('table')
ON_TABLE = (TABLE.centre[0], TABLE.footprint[1] + 0.15, TABLE.top + 0.061)


def test_a_pick_of_an_unknown_object_or_one_on_the_floor_is_refused_before_the_base_moves():
    robot_ = Robot({'coke can': (0.5, 0.5, 0.061)})
    outcome = executor(robot_).run(MobileRequest(TASK_PICK, 'apple'), Interruption())
    assert outcome.code == MobileErrorCode.OBJECT_NOT_FOUND
    outcome = executor(robot_).run(MobileRequest(TASK_PICK, 'coke can'), Interruption())
    assert outcome.code == MobileErrorCode.OUTSIDE_WORKSPACE and 'floor' in outcome.message
    assert robot_.goals == []


def test_with_the_hands_full_a_pick_is_refused_and_with_nothing_held_a_place():
    robot_ = Robot({'coke can': ON_TABLE})
    run = executor(robot_)
    outcome = run.run(MobileRequest(TASK_PLACE_AT_POSITION, target_xy=TABLE.centre), Interruption())
    assert outcome.code == MobileErrorCode.NOTHING_HELD
    run.held = Held('apple', (0.07, 0.07, 0.06), 0.03, 0.07)
    outcome = run.run(MobileRequest(TASK_PICK, 'coke can'), Interruption())
    assert outcome.code == MobileErrorCode.HANDS_FULL and 'apple' in outcome.message
    outcome = run.run(MobileRequest(TASK_PLACE_AT_OBJECT, 'apple'), Interruption())
    assert outcome.code == MobileErrorCode.TARGET_NOT_FOUND
    assert robot_.goals == []


def test_a_point_another_object_stands_on_is_refused_before_the_base_moves():
    robot_ = Robot({'coke can': ON_TABLE})
    run = executor(robot_)
    run.held = Held('water bottle', (0.065, 0.065, 0.21), 0.05, 0.065)
    outcome = run.run(MobileRequest(TASK_PLACE_AT_POSITION, target_xy=(ON_TABLE[0] + 0.03, ON_TABLE[1])),
                      Interruption())
    assert outcome.code == MobileErrorCode.OUTSIDE_WORKSPACE, outcome.message
    assert 'the coke can at' in outcome.message and 'is in the way' in outcome.message
    assert robot_.goals == [] and run.held is not None  # nothing moved; the bottle is still held


def test_the_base_is_sent_to_face_the_table_from_the_near_side_and_a_failed_drive_is_unreachable():
    robot_ = Robot({'coke can': ON_TABLE}, navigation_code=9101)
    outcome = executor(robot_).run(MobileRequest(TASK_PICK, 'coke can'), Interruption())
    assert outcome.ending == Ending.FAILED and outcome.code == MobileErrorCode.UNREACHABLE
    assert 'no free path' in outcome.message
    x, y, yaw = robot_.goals[0]
    assert x == pytest.approx(ON_TABLE[0]) and y < TABLE.footprint[1] - layout.BASE_RADIUS
    assert yaw == pytest.approx(np.pi / 2)


def test_the_base_stands_aside_of_an_object_in_the_arms_way_even_one_out_of_the_cameras_view():
    """A bottle in front of the can, remembered by perception but not seen from where the robot is: straight across
    from the can, the arm moving out would knock it over, so the base stands further along the table's side."""
    can = (TABLE.centre[0], TABLE.footprint[1] + 0.3, TABLE.top + 0.061)
    bottle = (TABLE.centre[0] - 0.065, TABLE.footprint[1] + 0.13, TABLE.top + 0.105)
    robot_ = Robot({'coke can': can, 'water bottle': bottle}, navigation_code=9101, out_of_view=('water bottle',))
    executor(robot_).run(MobileRequest(TASK_PICK, 'coke can'), Interruption())
    x, y, yaw = robot_.goals[0]
    assert x - can[0] >= 0.1 and y < TABLE.footprint[1] and yaw == pytest.approx(np.pi / 2), 'away from the bottle'
    seen_only = Robot({'coke can': can, 'water bottle': bottle}, navigation_code=9101)
    executor(seen_only).run(MobileRequest(TASK_PICK, 'coke can'), Interruption())
    assert seen_only.goals == robot_.goals, 'the same spot whether the bottle is seen now or remembered'
    alone = Robot({'coke can': can}, navigation_code=9101)
    executor(alone).run(MobileRequest(TASK_PICK, 'coke can'), Interruption())
    assert alone.goals[0][0] == pytest.approx(can[0]), 'straight across when nothing is in the way'


def test_where_the_base_may_stand_is_the_navigation_nodes_own_map():
    """A navigation node told to keep 5 cm more clearance leaves no spot within the arm's reach of a can 15 cm into
    the table: the pick is refused before the base moves, instead of a goal the node would refuse."""
    usual = Robot({'coke can': ON_TABLE}, navigation_code=9101)
    executor(usual).run(MobileRequest(TASK_PICK, 'coke can'), Interruption())
    cautious_map = NavigationConfig(margin=layout.NAVIGATION_MARGIN + 0.05).grid()
    cautious = Robot({'coke can': ON_TABLE}, grid=cautious_map)
    outcome = executor(cautious).run(MobileRequest(TASK_PICK, 'coke can'), Interruption())
    assert not cautious_map.is_free(usual.goals[0][:2])
    assert outcome.code == MobileErrorCode.OUTSIDE_WORKSPACE and 'out of the arm\'s reach' in outcome.message
    assert cautious.goals == []
