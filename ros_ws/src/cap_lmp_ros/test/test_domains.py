"""The domain registry: the table-top domain is found by its folder, an unknown domain is a one-line error, and a
domain another package offers (the toy domain, installed by the test) runs through lmp_node over DDS, its robot API
really called."""
from __future__ import annotations

import dataclasses
import subprocess
import sys

import pytest
import yaml
from rclpy.parameter import Parameter
from std_msgs.msg import String

from cap_interfaces.action import ExecuteCommand
from cap_interfaces.msg import StatusEvent
from cap_lmp_ros.domains.registry import ENTRY_POINT_GROUP, domain_names, get_domain
from cap_lmp_ros.lmp_node import LmpNode
from cap_lmp_ros.testing.lmp_graph import LmpGraph, wait_for
from cap_lmp_ros.testing.toy_domain import BELL_TOPIC, toy_domain
from cap_lmp.cassette import FORMAT as CASSETTE_FORMAT

TOY_PROGRAMS = {'ring the bell twice': 'ring_bell(2)', 'open a file': "import os\nos.listdir('/')",
                'ring the bell a hundred times': 'ring_bell(100)'}


def test_the_table_top_domain_is_found_by_its_folder():
    assert 'tabletop' in domain_names()
    tabletop = get_domain('tabletop')
    assert tabletop.scene == 'tabletop' and tabletop.cassette.is_file()
    assert 'put_first_on_second' in tabletop.robot_functions
    assert tabletop.build_engine.__module__ == 'cap_lmp_ros.domains.tabletop.lmps'


def test_an_unknown_domain_is_a_one_line_error_naming_the_known_ones(ros_context):
    with pytest.raises(ValueError) as error:
        get_domain('spaceship')
    assert "unknown domain 'spaceship'" in str(error.value) and 'tabletop' in str(error.value)
    assert '\n' not in str(error.value)
    with pytest.raises(ValueError, match="unknown domain 'spaceship'.*tabletop"):
        LmpNode(context=ros_context, parameter_overrides=[Parameter('domain', value='spaceship')])


def test_what_the_sandbox_process_imports_has_no_rclpy():
    code = ('import sys\nimport cap_lmp_ros.domains.tabletop.lmps, cap_lmp_ros.domains.registry, '
            'cap_lmp_ros.domains.tabletop.domain, cap_lmp_ros.testing.toy_domain, cap_lmp_ros.config\n'
            'assert "rclpy" not in sys.modules, "rclpy was imported"')
    completed = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True)
    assert completed.returncode == 0, completed.stderr


def test_a_domain_builder_must_be_found_by_name_in_the_sandbox_process(tmp_path):
    toy = toy_domain(tmp_path / 'toy.yaml')
    with pytest.raises(ValueError, match='top level of a module'):
        dataclasses.replace(toy, build_engine=lambda api, client, limits, **options: None)


def _toy_module(cassette, name: str = 'toy') -> str:
    """A module of another package that defines the toy domain as DOMAIN."""
    return ('from pathlib import Path\nfrom cap_lmp_ros.testing.toy_domain import toy_domain\n'
            f'DOMAIN = toy_domain(Path({str(cassette)!r}), name={name!r})\n')


def test_a_second_domain_of_the_same_name_is_refused(install_plugin, tmp_path):
    install_plugin({'toy_a': _toy_module(tmp_path / 'a.yaml', 'toy_twice')},
                   {ENTRY_POINT_GROUP: {'toy_twice': 'toy_a:DOMAIN'}}, name='toy-a')
    assert get_domain('toy_twice').cassette == tmp_path / 'a.yaml'
    install_plugin({'toy_b': _toy_module(tmp_path / 'b.yaml', 'toy_twice')},
                   {ENTRY_POINT_GROUP: {'toy_twice': 'toy_b:DOMAIN'}}, name='toy-b')
    with pytest.raises(ValueError, match="domain 'toy_twice' is offered twice, by toy_a:DOMAIN .* and toy_b:DOMAIN"):
        get_domain('toy_twice')


@pytest.fixture
def toy_graph(ros_context, tmp_path, install_plugin):
    cassette = tmp_path / 'toy.yaml'
    entries = [{'lmp': 'toy_ui', 'query': query, 'context': '*', 'completion': code, 'source': 'written by hand'}
               for query, code in TOY_PROGRAMS.items()]
    cassette.write_text(yaml.safe_dump({'format': CASSETTE_FORMAT, 'entries': entries}))
    # Its cassette is the default: no parameter names it.
    install_plugin({'toy_plugin': _toy_module(cassette)}, {ENTRY_POINT_GROUP: {'toy': 'toy_plugin:DOMAIN'}})
    graph = LmpGraph(ros_context, tmp_path, [Parameter('domain', value='toy'), Parameter('time_limit_s', value=30.0)])
    bells: list[str] = []
    graph.user.create_subscription(String, BELL_TOPIC, lambda message: bells.append(message.data), 10)
    graph.bells = bells
    assert wait_for(lambda: graph.user.count_publishers(BELL_TOPIC) == 1)
    yield graph
    graph.close()


def test_a_registered_toy_domain_runs_through_lmp_node(toy_graph):
    wrapped = toy_graph.run('ring the bell twice')
    result = wrapped.result
    assert result.success and result.outcome == ExecuteCommand.Result.OUTCOME_DONE, result.message
    assert result.code == 'ring_bell(2)'
    assert wait_for(lambda: toy_graph.bells == ['ring x2'])
    assert wait_for(lambda: toy_graph.final(result.command_id) is not None)
    assert toy_graph.final(result.command_id).stage == StatusEvent.STAGE_DONE


def test_the_toy_domain_results_carry_typed_outcomes(toy_graph):
    refused = toy_graph.run('open a file').result
    assert not refused.success and refused.outcome == ExecuteCommand.Result.OUTCOME_REFUSED, refused.message
    failed = toy_graph.run('ring the bell a hundred times').result
    assert failed.outcome == ExecuteCommand.Result.OUTCOME_ERROR and 'from 1 to 10' in failed.message
    empty = toy_graph.run('   ').result  # refused before it ran
    assert empty.outcome == ExecuteCommand.Result.OUTCOME_REFUSED
    unknown = toy_graph.run('sing a song').result  # the cassette has no answer: the model's failure
    assert unknown.outcome == ExecuteCommand.Result.OUTCOME_MODEL_ERROR, unknown.message
    assert toy_graph.bells == []
