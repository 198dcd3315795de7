"""The parameters of lmp_node, each with its default and description: their one home (config/lmp_node.yaml only
overrides). Declared with cap_ros_common.parameters.declare_config."""
from __future__ import annotations

from dataclasses import dataclass

from cap_control.kinematics import JOINT_NAMES
from cap_ros_common.parameters import parameter


@dataclass(frozen=True)
class LmpNodeConfig:
    llm_backend: str = parameter('cassette', 'cassette (replay a recorded cassette, offline), http (an '
                                 'OpenAI-compatible endpoint; CAP_LLM_BASE_URL, CAP_LLM_MODEL, CAP_LLM_API_KEY from '
                                 'the environment unless set below) or local (a llama.cpp server this node starts '
                                 'and supervises, see model_file; installed by `make model`).')
    cassette: str = parameter('', 'Cassette file for llm_backend=cassette, or the file to record into with '
                              "record_cassette=true; empty: the domain's packaged reference cassette.")
    record_cassette: bool = parameter(False, 'With llm_backend=http: also record every answer into `cassette`.')
    base_url: str = parameter('', 'OpenAI-compatible endpoint; empty: CAP_LLM_BASE_URL.')
    model: str = parameter('', 'Model name; empty: CAP_LLM_MODEL.')
    api: str = parameter('', 'chat (chat completions) or completions (legacy completions); empty: CAP_LLM_API, '
                         'else chat.')
    request_timeout_s: float = parameter(0.0, 'Timeout of one HTTP attempt of a model request [s]; 0: '
                                         'CAP_LLM_TIMEOUT_S, else 60.')
    time_limit_s: float = parameter(300.0, 'Wall-clock limit of one generated program, robot motion included [s].')
    service_timeout_s: float = parameter(5.0, 'Timeout of one perception request [s].')
    motion_timeout_s: float = parameter(180.0, 'Timeout of one pick-and-place [s].')
    max_queued_commands: int = parameter(5, 'Commands that may wait while one runs; more are refused.')
    domain: str = parameter('tabletop', 'Robot domain of the prompts, robot API and scene (see '
                            'cap_lmp_ros.domains.registry.domain_names()).')
    sandbox_process: bool = parameter(True, 'Run generated programs in a sandbox process of their own (a crash or a '
                                      'stuck C call then costs the session, not the node); false: in this process '
                                      '(faster to start, for debugging; a single long C call then cannot be '
                                      'stopped, and the node warns at start-up).')
    stall_limit_s: float = parameter(10.0, 'With sandbox_process: kill the sandbox process when one operation holds '
                                     'it this long without a pause [s].')
    jail: str = parameter('required', 'With sandbox_process: the kernel jail of the sandbox process (only the system '
                          'calls and files it needs, read-only; no sockets, exec, new processes or terminal): required '
                          '(the node does not start without it), best_effort (what the kernel offers, the rest logged) '
                          'or off.')
    model_time_limit_s: float = parameter(120.0, 'Overall model time per command [s].')
    regenerations: int = parameter(2, 'How often an answer that cannot be run (a syntax error, a name nothing '
                                   'defines, an object neither on the table nor in the command) is asked for again, '
                                   'sampled, before the command fails; 0: never. Found before the code runs, so a '
                                   'half-done command is never repeated.')
    feedback_rounds: int = parameter(0, 'Execution feedback: how often a program that failed while running (a robot '
                                     "call's error, a Python error) is followed by a new one the model writes from "
                                     'what happened (its program, the error and its line, the robot actions that '
                                     'completed, the scene now), continuing the command; 0: the paper\'s protocol. '
                                     'Not with require_approval (the approved program is all that runs).')
    model_file: str = parameter('', 'With llm_backend=local: the GGUF model file; empty: CAP_MODEL_FILE, else the '
                                'default model `make model` installs.')
    model_threads: int = parameter(1, 'With llm_backend=local: CPU threads of the model server (1 keeps a core for '
                                   'the simulator on a 2-core machine).')
    model_context: int = parameter(8192, 'With llm_backend=local: context size of the model server [tokens].')
    prompt_cache_dir: str = parameter('', 'With llm_backend=local: folder where the prompts read into the model '
                                      "server's cache are kept for the next start (empty: CAP_CACHE's prompt-kv/, "
                                      "by default ~/.cache/cap-ros/prompt-kv; 'off': read them at every start).")
    model_port: int = parameter(0, 'With llm_backend=local: loopback port of the model server; 0: a free one.')
    require_approval: bool = parameter(False, 'Hold each generated program until a person approves it: its code and '
                                       'the robot actions a plan-only run of it found are shown on /cap/status '
                                       '(STAGE_AWAITING_APPROVAL); approve or reject it with /cap/approve.')
    approval_timeout_s: float = parameter(300.0, 'With require_approval: a program not approved within this time '
                                          'is dropped (refused) [s].')

    rehearse: str = parameter('off', 'Rehearse each program on a twin before the robot moves (cap_lmp.rehearsal): '
                              'always, on_approval (with require_approval only) or off. The graph starts the twin '
                              '(its simulator, perception and control nodes under the namespace twin) when this is '
                              'not off; hardware mode defaults to always.')
    twin_joint_states_topic: str = parameter('joint_states', 'With rehearse: the real arm\'s joint states, where the '
                                             'twin starts its arm.')
    twin_arm_joints: tuple[str, ...] = parameter(JOINT_NAMES, 'With rehearse: the real arm\'s joint names in the '
                                                 "twin's order (shoulder pan to wrist 3).")


# Parameters whose change at run time takes effect from the next command; any other change is rejected.
RUNTIME_PARAMETERS = ('max_queued_commands', 'service_timeout_s', 'motion_timeout_s', 'require_approval',
                      'approval_timeout_s')
