"""A sandbox process that misbehaves on purpose, for IsolatedEngine's tests: what escaped code could do.

    python -m cap_lmp.testing.hostile_child <mode> <data fd> <control fd>

It speaks the framing of engine_process (multiprocessing Connection) and, after the run message, does what `mode`
says: send half a message, flood heartbeats, call the robot without reading replies, send malformed messages, die of
a real-time signal, fork a grandchild that keeps the socket, send malformed model requests, behave but
answer a stop late, or (breaks_approval) make robot calls before and after asking for approval, as each command
(a JSON object: 'before', 'plan', 'after') says.
"""
from __future__ import annotations

import json
import os
import signal
import struct
import sys
import time
from multiprocessing.connection import Connection

RESULT = {'command': 'cmd', 'command_id': 1, 'success': False, 'code': '', 'message': 'stopped',
          'outcome': 'cancelled', 'error_type': 'StoppedError', 'error_line': None, 'error_source': None,
          'stop_reason': '',
          'model_calls': 0, 'prompt_tokens': 0, 'completion_tokens': 0, 'timings': {}, 'generated_functions': []}


def main() -> None:
    mode = sys.argv[1]
    data = Connection(int(sys.argv[2]))
    _control = Connection(int(sys.argv[3]))  # kept open: closing it would look like a clean exit

    def send(message: dict) -> None:
        data.send_bytes(json.dumps(message).encode())

    def half_a_message() -> None:
        os.write(data.fileno(), struct.pack('!i', 100) + b'{"op"')
        time.sleep(60)

    data.recv_bytes()  # setup
    if mode == 'never_ready':
        half_a_message()
    send({'op': 'ready', 'default_lmp': 'toy_ui'})
    run_message = data.recv_bytes()
    if mode == 'half_message':
        half_a_message()
    elif mode == 'flood':
        while True:
            send({'op': 'alive'})
            time.sleep(0.002)
    elif mode == 'calls_without_reading':
        for call_id in range(10 ** 7):
            send({'op': 'call', 'id': call_id, 'name': 'where', 'args': [], 'kwargs': {}})
    elif mode == 'huge_integer':
        data.send_bytes(b'{"op": "alive", "n": ' + b'7' * 5000 + b'}')
    elif mode == 'result_of_wrong_shape':
        send({'op': 'result', 'result': [1]})
    elif mode == 'result_of_wrong_types':
        send({'op': 'result', 'result': {**RESULT, 'success': 'no'}})
    elif mode == 'unknown_outcome':
        send({'op': 'result', 'result': {**RESULT, 'outcome': 'victory'}})
    elif mode == 'outcome_against_success':
        send({'op': 'result', 'result': {**RESULT, 'outcome': 'done'}})
    elif mode == 'empty_event':
        send({'op': 'event'})
    elif mode == 'realtime_signal':
        os.kill(os.getpid(), signal.SIGRTMIN + 6)
    elif mode == 'grandchild_keeps_the_socket':
        if os.fork() == 0:
            while True:
                send({'op': 'alive'})
                time.sleep(0.01)
        os._exit(1)
    elif mode == 'asks_the_model_badly':  # malformed model requests, then one asking for a day of model time
        replies = []
        for request in ({'lmp': 'x', 'prompt': 7}, {'lmp': 'x', 'prompt': 'p' * (2 * 10 ** 6)}, 'not a request',
                        {'lmp': 'toy_ui', 'prompt': '# the blocks.\n', 'query': 'the blocks',
                         'time_budget_s': 86400.0}):
            send({'op': 'complete', 'id': len(replies) + 1, 'request': request})
            replies.append(json.loads(data.recv_bytes()))
        send({'op': 'result', 'result': {**RESULT, 'message': json.dumps(replies)[:5000]}})
    elif mode == 'breaks_approval':  # for every command, makes the calls its text names, then asks for approval
        run = json.loads(run_message)
        while True:
            approve_plan = json.loads(run['command']) if run['command'].startswith('{') else {}
            ordered = approve_plan.get('before', []), approve_plan.get('after', [])
            replies = []
            for call in ordered[0]:
                send({'op': 'call', 'id': len(replies) + 1, **call})
                replies.append(json.loads(data.recv_bytes()))
            send({'op': 'approve', 'id': len(replies) + 1, 'code': run['command'],
                  'plan': approve_plan.get('plan', [])})
            replies.append(json.loads(data.recv_bytes()))
            for call in ordered[1] if 'error' not in replies[-1] else []:
                send({'op': 'call', 'id': len(replies) + 1, **call})
                replies.append(json.loads(data.recv_bytes()))
            send({'op': 'result', 'result': {**RESULT, 'command': run['command'], 'outcome': 'error',
                                             'message': json.dumps(replies)[:5000]}})
            run = json.loads(data.recv_bytes())
    elif mode == 'slow_robot_then_result':
        send({'op': 'call', 'id': 1, 'name': 'slow', 'args': [], 'kwargs': {}})
        data.recv_bytes()
        time.sleep(0.1)  # raising the stop and building the result takes a moment
        send({'op': 'result', 'result': RESULT})
    time.sleep(60)


if __name__ == '__main__':
    main()
