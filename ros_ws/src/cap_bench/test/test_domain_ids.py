"""Which ROS_DOMAIN_ID each parallel graph of a benchmark run uses."""
import pytest

from cap_bench.ros_domains import domain_ids


def test_jobs_use_consecutive_ids_from_the_environments_domain():
    assert domain_ids(1, environ={'ROS_DOMAIN_ID': '0'}) == [0]
    assert domain_ids(3, environ={'ROS_DOMAIN_ID': '20'}) == [20, 21, 22]


def test_an_explicit_first_id_wins_over_the_environment():
    assert domain_ids(2, first=7, environ={'ROS_DOMAIN_ID': '20'}) == [7, 8]


def test_without_a_domain_in_the_environment_the_ids_stay_below_the_ephemeral_ports():
    ids = domain_ids(4, environ={})
    assert len(ids) == 4 and 1 <= ids[0] and ids[-1] <= 101


@pytest.mark.parametrize('value, words', [('231', "4 job(s) need ROS_DOMAIN_IDs 231..234"),
                                          ('abc', "ROS_DOMAIN_ID='abc' is not a domain id")])
def test_ids_out_of_range_or_malformed_are_refused_with_the_reason(value, words):
    with pytest.raises(ValueError, match=words.replace('(', r'\(').replace(')', r'\)')):
        domain_ids(4, environ={'ROS_DOMAIN_ID': value})
