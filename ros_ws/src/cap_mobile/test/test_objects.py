"""The kitchen's objects: kinds, groups, and where an episode puts them (on the furniture tops, apart)."""
import math

import pytest

from cap_mobile import layout, objects


def test_every_object_has_a_group_and_the_snacks_drinks_and_fruit_are_told_apart():
    assert set(objects.GROUPS) == set(objects.OBJECT_NAMES)
    assert {objects.GROUPS[name] for name in objects.OBJECT_NAMES} == {
        objects.GROUP_DRINK, objects.GROUP_SNACK, objects.GROUP_FRUIT}
    assert objects.KINDS['coke can'].resting_height == pytest.approx(0.061)


@pytest.mark.parametrize('seed', range(20))
def test_an_episode_puts_its_objects_on_the_furniture_tops_apart(seed):
    names = objects.default_objects(seed)
    assert len(set(names)) == len(names) and 6 <= len(names) <= 7
    placed = objects.spawn_positions(len(names), seed)
    for x, y, height in placed:
        surface = objects.surface_of(x, y)
        assert surface in objects.SURFACES
        assert height == pytest.approx(layout.location(surface).top)
    assert all(math.dist(a[:2], b[:2]) >= objects.SPAWN_SEPARATION for i, a in enumerate(placed)
               for b in placed[i + 1:])


def test_a_given_position_is_kept_on_whatever_is_under_it():
    table = layout.location('table').centre
    placed = objects.spawn_positions(2, 0, [table, (0.0, 0.0)])
    assert placed[0] == (table[0], table[1], layout.location('table').top)
    assert placed[1] == (0.0, 0.0, 0.0)  # the floor
    assert objects.surface_of(0.0, 0.0) is None
