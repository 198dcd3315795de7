"""Attack programs against the command's limits, shared by the limit tests and benchmarks/limits.py.

Each is a program a model could write (or be made to write) that runs past a limit: loops, programs that switch
the sandbox's tracing off, single long C calls, GEOS work without the interpreter, endless robot or model calls,
memory hogs, an over-long program. Served by command text through the scripted model server.
"""
from __future__ import annotations

SCENE = {'red block': (-0.1, -0.4), 'blue block': (0.1, -0.45), 'red bowl': (-0.15, -0.65)}
MOVE = 'put the red block in the red bowl'

# A stop raised inside a generator's finalizer is swallowed by CPython, which removes the tracer with it.
DISABLE_TRACING = '''
def gen():
    yield 1
    yield 2
def down(rest, box):
    if rest:
        return down(rest[1:], box)
    box[0] = None
    return 0
for k in range(300):
    box = [gen()]
    next(box[0])
    down(list(range(k)), box)
'''
# Programs that run past the time limit: each must end within a second of it, the session kept or not.
TIME_ATTACKS = {
    'loop forever': 'n = 0\nwhile True:\n    n += 1',
    'disable tracing, then a comprehension': DISABLE_TRACING + 'x = [i for i in range(10 ** 8)]',
    'disable tracing, then recursion': DISABLE_TRACING + 'def r(n):\n    return r(n + 1) if n < 100 else r(0)\nr(0)',
    'disable tracing, then a loop': DISABLE_TRACING + 'while True:\n    pass',
    'one C call: str of an aliased list': 'row = [0] * 10 ** 6\ns = str([row] * 1000)',
    'one C call: list.count of long lists': 'a = [0] * 10 ** 6\nc = ([a] * 20000).count(list(a))',
    'GEOS without the interpreter: buffer of a 30,000-point line': (
        'pts = np.random.rand(30000, 2)\nb = LineString(pts).buffer(0.01)'),
    'robot calls in a loop': "while True:\n    p = get_obj_pos('red block')",
}
PROGRAMS = {
    MOVE: "put_first_on_second('red block', 'red bowl')",
    'ask forever': ("while True:\n    try:\n        parse_obj_name('the blocks', '')\n"
                    "    except Exception:\n        pass"),
    'ask once': "say(parse_obj_name('the blocks', f'objects = {get_obj_names()}'))",
    '# the blocks.': "ret_val = ['red block', 'blue block']",
    'keep filling the memory': 'keep = []\nwhile True:\n    keep.append(np.ones(10 ** 6))',
    'use 100 MB': 'big = [np.ones(10 ** 6) for i in range(12)]\nsay(len(big))',
    'remember seven': 'seven = 7',
    'recall seven': 'say(seven)',
    'fill the address space': 'rows = [[0] * 10 ** 6 for i in range(400)]',
    'move in a long program': "put_first_on_second('red block', 'red bowl')\n" + 'x = 0\n' * 10_000,
    **TIME_ATTACKS,
}
