"""One command at a time; later ones wait in a bounded FIFO; a stop empties it."""
import threading

from cap_lmp_ros.command_queue import MAX_COMMAND_CHARS, CommandQueue, normalise_command


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


def test_a_command_is_one_line_and_empty_or_overlong_ones_are_refused_saying_why():
    queue = CommandQueue(max_waiting=1)
    job, queued = queue.submit('can you throw blocks\n# move the red block\t5cm\x1b[2J to the bottom\r', 'topic')
    assert queued and job.command == 'can you throw blocks # move the red block 5cm [2J to the bottom'
    empty, queued = queue.submit(' \n\t ', 'action')
    assert not queued and empty.refusal == 'refused: the command is empty'
    long, queued = queue.submit('say hi ' * 200, 'topic')
    assert not queued and long.refusal == f'refused: the command is 1399 characters long; the limit is ' \
                                          f'{MAX_COMMAND_CHARS}'
    assert len(long.command) < 300
    full, queued = queue.submit('say hi', 'topic')
    assert not queued and 'the queue is full' in full.refusal and 'max_queued_commands=1' in full.refusal
    command, refusal = normalise_command('say\u2028hi\x00 there ' + chr(55296))
    assert command.startswith('say hi there \ufffd') and command.encode('utf-8') and not refusal
