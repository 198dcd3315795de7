"""A robot function that takes a function of the program (a controller) calls it through IsolatedEngine.invoke: in
the sandbox process, under the sandbox's rules, with a time budget per call, from another thread of the node."""
from __future__ import annotations

import json
import subprocess
import sys
import threading

import pytest

from cap_lmp.cassette import ANY_CONTEXT, Cassette, CassetteEntry, CassetteClient
from cap_lmp.isolated_engine import CallableHandle, InvokeError, IsolatedEngine
from cap_lmp.sandbox import SandboxLimits
from cap_lmp.testing.minimal_engine import build_engine

PROGRAMS = {
    'square ten times': 'def square(x):\n    return x * x\nresults = drive(square, 10)\nreport(results)',
    'divide by zero': 'def bad(x):\n    y = x / 0\n    return y\nresults = drive(bad, 1)\nreport(results)',
    'spin': 'def slow(x):\n    n = 0\n    while True:\n        n += 1\nresults = drive(slow, 2)\nreport(results)',
    'call the robot inside': 'def nosy(x):\n    report(x)\n    return x\nresults = drive(nosy, 1)\nreport(results)',
    'pass a function elsewhere': 'def f(x):\n    return x\nreport(f)',
}


class Driver:
    """The node's side: `drive(f, n)` calls f(i) n times from another thread, as a controller node's loop would."""

    def __init__(self) -> None:
        self.engine: IsolatedEngine | None = None
        self.reported: list = []
        self.seconds: list[float] = []

    def drive(self, function, times: int):
        assert isinstance(function, CallableHandle)
        outcomes: list = []

        def loop() -> None:
            for i in range(times):
                try:
                    value, seconds = self.engine.invoke(function, [i], budget_s=0.05, timeout_s=2.0)
                    outcomes.append(value)
                    self.seconds.append(seconds)
                except InvokeError as error:
                    outcomes.append(f'{error.kind}: {error}')
                    return

        thread = threading.Thread(target=loop)
        thread.start()
        thread.join()
        return outcomes

    def report(self, value) -> None:
        self.reported.append(value)


@pytest.fixture
def driven(tmp_path):
    cassette = Cassette(tmp_path / 'programs.yaml', [
        CassetteEntry(lmp='main', query=query, context=ANY_CONTEXT, completion=code, source='written for this test')
        for query, code in PROGRAMS.items()])
    cassette.save()
    driver = Driver()
    engine = IsolatedEngine(build_engine, {'drive': driver.drive, 'report': driver.report},
                            CassetteClient(cassette.path),
                            SandboxLimits(time_limit_s=20.0), function_arguments=('drive',), jail='best_effort')
    driver.engine = engine
    try:
        yield driver, engine
    finally:
        engine.close()


def test_the_program_function_is_called_in_the_sandbox_process_from_another_thread(driven):
    driver, engine = driven
    result = engine.run('square ten times')
    assert result.success, result.message
    assert driver.reported == [[i * i for i in range(10)]]
    assert len(driver.seconds) == 10 and all(0 <= s < 0.05 for s in driver.seconds)


def test_an_exception_of_the_function_names_its_line(driven):
    driver, engine = driven
    assert engine.run('divide by zero').success
    [[outcome]] = driver.reported
    assert outcome.startswith('ZeroDivisionError: ') and 'line 2' in outcome and 'x / 0' in outcome


def test_a_call_past_its_budget_is_stopped_and_the_program_goes_on(driven):
    driver, engine = driven
    result = engine.run('spin')
    assert result.success, result.message  # the stop ended with the call: the program reported and finished
    [[outcome]] = driver.reported
    assert outcome.startswith('ControllerOverrun: ') and 'time budget of 50 ms' in outcome
    assert engine.run('square ten times').success  # the session is intact


def test_the_function_cannot_call_the_robot(driven):
    driver, engine = driven
    assert engine.run('call the robot inside').success
    [[outcome]] = driver.reported
    assert 'cannot call the robot' in outcome


def test_only_declared_robot_functions_take_functions(driven):
    _, engine = driven
    result = engine.run('pass a function elsewhere')
    assert not result.success and 'cannot be passed to the robot' in result.message


def test_invoke_without_a_waiting_program_is_refused(driven):
    _, engine = driven
    with pytest.raises(InvokeError) as raised:
        engine.invoke(CallableHandle(1, 'f'), [0], budget_s=0.01, timeout_s=0.1)
    assert raised.value.kind == 'NotRunning'


def test_a_garbage_collection_in_the_sandbox_process_walks_only_what_programs_made():
    # A full collection over the engine's own objects (5-7 ms) inside a controller's call stopped a correct
    # controller at its 5 ms budget; the sandbox process freezes them once the engine is built.
    script = (
        'import gc, json\n'
        'from cap_lmp.engine_process import freeze_setup_heap\n'
        'from cap_lmp.testing.minimal_engine import build_engine\n'
        'engine = build_engine({}, None)\n'
        'before = len(gc.get_objects())\n'
        'freeze_setup_heap()\n'
        'made = [[i] for i in range(100)]\n'
        'print(json.dumps([before, len(gc.get_objects())]))\n')
    before, after = json.loads(subprocess.run([sys.executable, '-c', script], check=True, capture_output=True,
                                              text=True).stdout)
    assert before > 10_000 and 100 <= after < 1_000
