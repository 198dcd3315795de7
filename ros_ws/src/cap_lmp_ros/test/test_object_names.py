"""What a program passes as an object's name, and what the robot API takes it to mean."""
import pytest

from cap_lmp_ros.domains.tabletop.lmps import object_name_candidate


@pytest.mark.parametrize('passed, meant', [
    ('red block', 'red block'),
    ('the red block', 'red block'),
    ('  The  Red   Block ', 'red block'),
    (['blue bowl'], 'blue bowl'),
    (('the green block',), 'green block'),
    ('theatre block', 'theatre block'),  # only the word "the" goes
])
def test_a_name_is_what_the_program_most_likely_meant(passed, meant):
    assert object_name_candidate(passed) == meant


@pytest.mark.parametrize('passed', [['red block', 'blue block'], [], 3, None, {'name': 'red block'}, [['red block']]])
def test_anything_else_is_not_a_name(passed):
    assert object_name_candidate(passed) is None
