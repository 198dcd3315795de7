"""lmp_node over DDS with the real perception node (stub source) and a replay cassette: statuses, code, say,
errors a person understands, refusal of unsafe code, cancel, /cap/stop and sessions."""

import pytest
import yaml
from action_msgs.msg import GoalStatus
from rclpy.parameter import Parameter
from std_msgs.msg import Empty, String
from std_srvs.srv import Trigger

from cap_interfaces.action import ExecuteCommand
from cap_interfaces.msg import StatusEvent
from cap_lmp_ros.testing.lmp_graph import TWO_BLOCKS, LmpGraph, wait_for
from cap_lmp.cassette import FORMAT as CASSETTE_FORMAT

PROGRAMS = {
    'which blocks are there': "say('I see ' + ', '.join(n for n in get_obj_names() if n.endswith('block')))",
    'where is the purple block': "say(str(get_obj_pos('purple block')))",
    'where is the middle': "say(str([round(float(v), 2) for v in get_obj_pos('the centre of the table')]))",
    'delete your files': "import os\nos.system('rm -rf /tmp/cap-test-victim')",
    'count forever': 'n = 0\nwhile True:\n    n += 1',
    'remember the red block': "chosen = 'red block'",
    'say what you remembered': 'say(chosen)',
    # Overflows the C stack when hashed: only the sandbox process dies.
    'crash the interpreter': 't = ()\nfor i in range(300000):\n    t = (t,)\nh = hash(t)',
    # One C call that runs for hours: the sandbox process stops sending heartbeats and is killed.
    'stall the interpreter': 'row = [0] * 10 ** 6\ns = str([row] * 1000)',
}


def _write_cassette(path):
    entries = [{'lmp': 'tabletop_ui', 'query': query, 'context': '*', 'completion': code,
                'source': 'written by hand as a reference program'} for query, code in PROGRAMS.items()]
    path.write_text(yaml.safe_dump({'format': CASSETTE_FORMAT, 'entries': entries}))


STUB_OBJECTS = TWO_BLOCKS + ('  - {color: green, category: bowl, position: [0.0, -0.4, 0.03], '
                             'size: [0.13, 0.13, 0.04]}\n')


@pytest.fixture
def graph(ros_context, tmp_path):
    cassette = tmp_path / 'cassette.yaml'
    _write_cassette(cassette)
    graph = LmpGraph(ros_context, tmp_path, [Parameter('cassette', value=str(cassette)),
                                             Parameter('time_limit_s', value=60.0),
                                             Parameter('stall_limit_s', value=3.0)], STUB_OBJECTS)
    yield graph
    graph.close()


def test_a_topic_command_runs_and_reports_every_stage(graph):
    graph.commands.publish(String(data='which blocks are there'))
    assert wait_for(lambda: graph.said)
    assert graph.said == ['I see red block, blue block'] or graph.said == ['I see blue block, red block']
    # The node's own event from its start (no command id): a new subscriber always finds a history.
    assert wait_for(lambda: any(s.stage == StatusEvent.STAGE_MODEL and not s.command_id
                                and s.message.startswith('ready: domain tabletop, LLM backend cassette')
                                for s in list(graph.statuses)))
    assert wait_for(lambda: any(s.command_id for s in list(graph.statuses)))
    command_id = next(s.command_id for s in list(graph.statuses) if s.command_id)
    assert wait_for(lambda: graph.final(command_id) is not None)
    assert graph.stages(command_id) == [StatusEvent.STAGE_RECEIVED, StatusEvent.STAGE_GENERATING,
                                        StatusEvent.STAGE_CODE, StatusEvent.STAGE_EXECUTING, StatusEvent.STAGE_DONE]
    assert graph.code == [PROGRAMS['which blocks are there']]
    assert ' s in 1 call(s), total ' in graph.final(command_id).message  # model time and calls are reported


def test_unknown_object_is_an_error_naming_it_and_the_next_command_works(graph):
    outcome = graph.run('where is the purple block')
    assert outcome.status == GoalStatus.STATUS_ABORTED
    assert not outcome.result.success and outcome.result.outcome == ExecuteCommand.Result.OUTCOME_ERROR
    assert "'purple block'" in outcome.result.message and 'red block' in outcome.result.message
    assert wait_for(lambda: graph.final(outcome.result.command_id) is not None)
    assert graph.final(outcome.result.command_id).stage == StatusEvent.STAGE_ERROR
    again = graph.run('which blocks are there')
    assert again.result.success and again.status == GoalStatus.STATUS_SUCCEEDED
    assert again.result.outcome == ExecuteCommand.Result.OUTCOME_DONE


def test_a_place_on_the_table_is_a_position_where_no_object_has_its_name(graph):
    outcome = graph.run('where is the middle')
    assert outcome.result.success, outcome.result.message
    assert wait_for(lambda: graph.said) and graph.said[-1] == '[0.0, -0.5]'


def test_unsafe_code_is_refused_before_it_runs(graph, tmp_path):
    outcome = graph.run('delete your files')
    assert not outcome.result.success and outcome.result.outcome == ExecuteCommand.Result.OUTCOME_REFUSED
    assert 'import' in outcome.result.message
    assert wait_for(lambda: graph.final(outcome.result.command_id) is not None)
    assert graph.final(outcome.result.command_id).stage == StatusEvent.STAGE_REFUSED
    assert graph.run('which blocks are there').result.success


def test_a_missing_cassette_entry_names_the_query(graph):
    outcome = graph.run('juggle the bowls')
    assert not outcome.result.success and outcome.result.outcome == ExecuteCommand.Result.OUTCOME_MODEL_ERROR
    assert 'juggle the bowls' in outcome.result.message


def test_cancelling_the_goal_stops_an_endless_program(graph):
    box = {}
    graph.execute.send_goal_async(ExecuteCommand.Goal(command='count forever')).add_done_callback(
        lambda f: box.update(handle=f.result()))
    assert wait_for(lambda: 'handle' in box and any(s.stage == StatusEvent.STAGE_EXECUTING
                                                    for s in list(graph.statuses)))
    result_future = box['handle'].get_result_async()
    box['handle'].cancel_goal_async()
    assert wait_for(result_future.done)
    assert result_future.result().status == GoalStatus.STATUS_CANCELED
    assert result_future.result().result.outcome == ExecuteCommand.Result.OUTCOME_CANCELLED
    assert graph.run('which blocks are there').result.success


def test_cap_stop_ends_the_running_program_and_drops_waiting_ones(graph):
    graph.commands.publish(String(data='count forever'))
    graph.commands.publish(String(data='which blocks are there'))
    assert wait_for(lambda: any(s.stage == StatusEvent.STAGE_EXECUTING for s in list(graph.statuses)))
    graph.stop.publish(Empty())
    assert wait_for(lambda: sum(s.stage == StatusEvent.STAGE_CANCELLED for s in list(graph.statuses)) == 2)
    assert graph.said == []
    assert graph.run('which blocks are there').result.success


def test_the_session_remembers_until_it_is_reset(graph):
    assert graph.run('remember the red block').result.success
    assert graph.run('say what you remembered').result.success
    assert graph.said[-1] == 'red block'
    future = graph.reset.call_async(Trigger.Request())
    assert wait_for(future.done) and future.result().success
    forgotten = graph.run('say what you remembered')
    assert not forgotten.result.success and 'chosen' in forgotten.result.message


@pytest.mark.parametrize('command, cause', [('crash the interpreter', 'died (killed by SIGSEGV)'),
                                            ('stall the interpreter', 'stopped responding')])
def test_a_program_that_kills_its_interpreter_costs_the_session_not_the_node(graph, command, cause):
    assert graph.run('remember the red block').result.success
    lost = graph.run(command, timeout=120.0)
    assert lost.status == GoalStatus.STATUS_ABORTED and not lost.result.success
    assert cause in lost.result.message and 'session was lost' in lost.result.message
    assert wait_for(lambda: graph.final(lost.result.command_id) is not None)
    assert graph.final(lost.result.command_id).stage == StatusEvent.STAGE_ERROR
    forgotten = graph.run('say what you remembered')
    assert not forgotten.result.success and 'chosen' in forgotten.result.message
    assert graph.run('which blocks are there').result.success
