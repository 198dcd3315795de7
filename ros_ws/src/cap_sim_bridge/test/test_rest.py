"""RestWatch: when the bridge may idle (no goal, nothing moving, for idle_after of simulated time)."""
from cap_sim_bridge.rest import REST_SPEED, RestWatch


def test_idle_only_after_a_whole_period_of_stillness():
    watch = RestWatch(after=1.0)
    assert not watch.update(0.0, busy=False, max_speed=0.0)
    assert not watch.update(0.99, busy=False, max_speed=0.0)
    assert watch.update(1.0, busy=False, max_speed=0.0)


def test_a_goal_or_motion_ends_idling_at_once_and_restarts_the_wait():
    watch = RestWatch(after=1.0)
    watch.update(0.0, busy=False, max_speed=0.0)
    assert watch.update(2.0, busy=False, max_speed=0.0)
    assert not watch.update(2.1, busy=True, max_speed=0.0)
    assert not watch.update(2.5, busy=False, max_speed=0.0)  # still since 2.5 only
    assert watch.update(3.5, busy=False, max_speed=0.0)
    assert not watch.update(3.6, busy=False, max_speed=10 * REST_SPEED)  # something moves
    assert not watch.update(4.0, busy=False, max_speed=0.0)


def test_wake_and_a_scene_reset_restart_the_wait():
    watch = RestWatch(after=1.0)
    watch.update(0.0, busy=False, max_speed=0.0)
    assert watch.update(5.0, busy=False, max_speed=0.0)
    watch.wake()
    assert not watch.update(5.5, busy=False, max_speed=0.0)
    assert not watch.update(0.2, busy=False, max_speed=0.0)  # simulated time went back (a reset)
    assert watch.update(1.2, busy=False, max_speed=0.0)


def test_idling_switched_off_and_a_broken_speed_never_idle():
    assert not RestWatch(after=0.0).update(100.0, busy=False, max_speed=0.0)
    watch = RestWatch(after=1.0)
    watch.update(0.0, busy=False, max_speed=0.0)
    assert not watch.update(2.0, busy=False, max_speed=float('nan'))
