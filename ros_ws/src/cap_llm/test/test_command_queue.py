"""One command at a time; later ones wait in a bounded FIFO; a stop empties it."""
import threading

from cap_llm.command_queue import CommandQueue


def test_commands_run_in_arrival_order_and_a_full_queue_refuses():
    queue = CommandQueue(max_waiting=2)
    first, ok1 = queue.submit('stack the blocks', 'topic')
    second, ok2 = queue.submit('say hello', 'action')
    third, ok3 = queue.submit('one too many', 'topic')
    assert (ok1, ok2, ok3) == (True, True, False)
    assert queue.next_job() is first and queue.running is first
    queue.finish(first)
    assert first.finished.is_set() and queue.running is None
    assert queue.next_job() is second
    assert len({first.command_id, second.command_id, third.command_id}) == 3


def test_withdraw_and_drain_only_touch_waiting_jobs():
    queue = CommandQueue()
    running, _ = queue.submit('a', 'topic')
    waiting, _ = queue.submit('b', 'topic')
    later, _ = queue.submit('c', 'topic')
    queue.next_job()
    assert not queue.withdraw(running)
    assert queue.withdraw(waiting)
    assert queue.drain() == [later]
    assert queue.waiting() == 0


def test_close_wakes_the_worker():
    queue = CommandQueue()
    got = []
    worker = threading.Thread(target=lambda: got.append(queue.next_job()))
    worker.start()
    queue.close()
    worker.join(5)
    assert got == [None]
