"""lmp_node: natural-language commands in, generated and executed policy code out.

Commands arrive on /cap/command (std_msgs/String) or as /cap/execute goals. One runs at a time on a worker thread;
later ones wait in a FIFO of `max_queued_commands` and are refused when it is full (see command_queue.py). A
command is put on one line before it reaches a prompt; an empty or over-long one is refused. Every command gets an
answer on /cap/status, refused ones included (and every /cap/execute goal is accepted and gets a result saying
what happened). Every stage is published on /cap/status; the generated code on /cap/code, what the robot says on
/cap/say. /cap/stop ends the running program and its motion and drops waiting commands. /cap/reset_session forgets
the session.

With `require_approval`, each program waits after its code is generated and checked: a plan-only run lists the
robot actions it would take (cap_lmp.approval; the domain says which functions act and what their calls mean), the
code and that plan are published on /cap/status (STAGE_AWAITING_APPROVAL, with `plan`), and the program runs only
once /cap/approve approves it. A rejection, or no answer within `approval_timeout_s`, ends the command as refused
(nothing of it ran); a stop ends it as cancelled. The node holds the run to what was approved on its own side of
every robot call and model request (cap_lmp.approval.ApprovalGuard), so that neither the program nor its sandbox
process can get around it: no acting call before approval, after it only the approved calls in their order, and no
new code from the model; a call that breaks this is refused, the program stopped and the command refused.

With `rehearse` (always, or on_approval with require_approval), each program first runs whole on a twin of the
scene (cap_lmp.rehearsal, cap_lmp_ros.twin): the node routes its robot calls to the twin, and only a clean
rehearsal lets it run on the robot, held to the motions the twin received; harm or an error there refuses the
command with what the twin saw and where. With feedback_rounds, a program that failed on the twin is followed by a
new one, rehearsed on a twin built again. After the real run, the result compares the world with the prediction.

Whatever a program or a model produced is made safe before it leaves the node (safe_text.wire_text: valid UTF-8,
bounded; logs also without control characters), so no text can kill the thread that publishes it. If the worker
thread dies anyway, the node refuses every later command naming the cause, and the standalone process (`main`)
logs one line and exits with thread_watch.FATAL_EXIT_CODE instead of living on without answering.

The `domain` parameter picks the robot domain (prompts, robot API, default cassette) from
cap_lmp_ros.domains.registry. Parameters (LmpNodeConfig in cap_lmp_ros/config.py) are read at start-up; of those
changed at run time, max_queued_commands, service_timeout_s and motion_timeout_s take effect from the next command,
and every other change is rejected with the reason.
"""
from __future__ import annotations

import os
import sys
import threading
import time
from typing import Any

import rclpy
from rcl_interfaces.msg import SetParametersResult
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.task import Future
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from geometry_msgs.msg import Point
from std_msgs.msg import Empty, String
from std_srvs.srv import Trigger

from cap_interfaces.action import ExecuteCommand
from cap_interfaces.msg import GraphNames, PlannedMotion, PredictionMiss, StatusEvent
from cap_interfaces.srv import ApproveCommand
from cap_lmp import engine as engine_module
from cap_lmp.approval import ApprovalGuard, GuardedClient, PlannedCall, guarded_functions
from cap_lmp.cassette import make_client
from cap_lmp.engine_protocol import CommandEngine
from cap_lmp.isolated_engine import JAIL_MODES, IsolatedEngine
from cap_lmp.errors import ExecutionStopped, LLMError, NotApproved, RobotApiError
from cap_lmp.engine import CommandResult
from cap_lmp.llm import NO_MODEL_CONFIGURED
from cap_lmp.local_model import INSTALL_HINT
from cap_lmp.local_server import LocalModelClient, LocalModelServer, ServerSettings, server_binary, warm_up
from cap_lmp.outcome import Outcome
from cap_lmp.rehearsal import (REHEARSAL_TOLERANCE, REHEARSE_MODES, RESTART_REHEARSAL, UNHELD_WHEN_REHEARSED, Rehearsal,
                                TwinVerdict, prediction_misses, prediction_text, rehearses)
from cap_lmp.safe_text import terminal_text, wire_text
from cap_lmp.sandbox import IN_PROCESS_WARNING, SandboxLimits
from cap_lmp.wire import MAX_CODE_CHARS
from cap_lmp_ros.command_queue import CommandQueue, Job
from cap_lmp_ros.config import RUNTIME_PARAMETERS, LmpNodeConfig
from cap_lmp_ros.domains.registry import engine_api, get_domain, prompt_heads
from cap_lmp_ros.plan_steps import PlanStep, plan_summary
from cap_lmp_ros.thread_watch import FATAL_EXIT_CODE, ThreadWatch
from cap_lmp_ros.twin import Twin
from cap_ros_common.actions import RESULT_TIMEOUT_S
from cap_ros_common.parameters import declare_config, parameter_names

# Commands and stops must not be lost: reliable, a few deep.
COMMAND_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
# Status and code are events a late subscriber may want to see the last few of.
EVENT_QOS = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)

_STAGES = {engine_module.GENERATING: StatusEvent.STAGE_GENERATING, engine_module.CODE: StatusEvent.STAGE_CODE,
           engine_module.EXECUTING: StatusEvent.STAGE_EXECUTING}
# The outcome field of a goal's result, and the final status stage of a command that ran.
RESULT_OUTCOMES = {Outcome.DONE: ExecuteCommand.Result.OUTCOME_DONE, Outcome.ERROR: ExecuteCommand.Result.OUTCOME_ERROR,
                   Outcome.CANCELLED: ExecuteCommand.Result.OUTCOME_CANCELLED,
                   Outcome.REFUSED: ExecuteCommand.Result.OUTCOME_REFUSED,
                   Outcome.MODEL_ERROR: ExecuteCommand.Result.OUTCOME_MODEL_ERROR}
_FINAL_STAGES = {Outcome.DONE: StatusEvent.STAGE_DONE, Outcome.REFUSED: StatusEvent.STAGE_REFUSED,
                 Outcome.CANCELLED: StatusEvent.STAGE_CANCELLED}  # errors of every kind: STAGE_ERROR
__all__ = ['COMMAND_QOS', 'EVENT_QOS', 'RESULT_OUTCOMES', 'RUNTIME_PARAMETERS', 'LmpNode', 'main', 'outcome_name']


def outcome_name(value: int) -> str:
    """The name of an ExecuteCommand result's `outcome` ('done', 'error', 'cancelled', 'refused', 'model_error'),
    or 'unknown' for OUTCOME_UNKNOWN (a result nobody filled in) and any other value."""
    for outcome, number in RESULT_OUTCOMES.items():
        if number == value:
            return outcome.value
    return 'unknown'


class LmpNode(Node):
    """See the module docstring. `thread_watch` is told when the worker thread dies (default: a watch of its own
    that logs it); `sandbox_command` replaces the sandbox process's command line (tests start one that misbehaves
    on purpose; not a parameter, so that nothing on the ROS graph can choose what runs); a ValueError whose message
    is one line says what to fix in the configuration."""

    def __init__(self, *, thread_watch: ThreadWatch | None = None, sandbox_command: list[str] | None = None,
                 **kwargs: Any) -> None:
        super().__init__('lmp_node', **kwargs)
        self._declared = set(parameter_names(LmpNodeConfig))
        config = self.config = declare_config(self, LmpNodeConfig)
        self.domain = get_domain(config.domain)
        cassette = config.cassette or str(self.domain.cassette)
        if config.jail not in JAIL_MODES:
            raise ValueError(f'parameter jail={config.jail!r} is not one of {", ".join(JAIL_MODES)}')

        # Unset parameters leave the environment's CAP_LLM_* values (OpenAICompatibleClient.from_env) in force.
        http_options: dict[str, Any] = {}
        if config.api:
            http_options['api'] = config.api
        if config.request_timeout_s > 0:
            http_options['timeout_s'] = config.request_timeout_s
        if config.base_url:
            http_options['base_url'] = config.base_url
        if config.model:
            http_options['model'] = config.model
        if config.llm_backend == 'cassette':
            client_options: dict[str, Any] = {'cassette': cassette}
        elif config.llm_backend == 'http':
            # Checked here, not where the client is built (possibly in the sandbox process): one line, at once.
            if not (config.model or os.environ.get('CAP_LLM_MODEL')):
                raise ValueError(NO_MODEL_CONFIGURED)
            client_options = {'cassette': cassette if config.record_cassette else None,
                              'record': config.record_cassette, **http_options}
        elif config.llm_backend != 'local':
            raise ValueError(f'parameter llm_backend={config.llm_backend!r} is not one of cassette, http, local')
        self.model_server: LocalModelServer | None = None
        if config.llm_backend == 'local':
            settings = ServerSettings(model_file=config.model_file, threads=config.model_threads,
                                      context_size=config.model_context, port=config.model_port,
                                      prompt_cache_dir=config.prompt_cache_dir)
            if not settings.model_path().is_file():  # one line at once, not a failure at the first command
                raise ValueError(f'no model file at {settings.model_path()}: {INSTALL_HINT}')
            try:
                server_binary()
            except LLMError as error:
                raise ValueError(str(error)) from None
            self.model_server = LocalModelServer(settings, on_event=self._on_model_event, on_ready=self._warm_up)
        api = config.api or os.environ.get('CAP_LLM_API', 'chat')
        if api not in ('chat', 'completions'):
            source = 'parameter api' if config.api else 'CAP_LLM_API'
            raise ValueError(f'{source}={api!r} is not one of chat, completions')

        self._code_publisher = self.create_publisher(String, GraphNames.CODE_TOPIC, EVENT_QOS)
        self._status_publisher = self.create_publisher(StatusEvent, GraphNames.STATUS_TOPIC, EVENT_QOS)
        say_publisher = self.create_publisher(String, GraphNames.SAY_TOPIC, EVENT_QOS)
        self.robot = self.domain.robot_api(self, say_publisher, config.service_timeout_s, config.motion_timeout_s)
        # Approval is held on this side of every robot call and model request, where no program reaches it.
        self.approval_guard = ApprovalGuard(self.domain.plan_functions)
        api = guarded_functions(engine_api(self.domain, self.robot.functions()), self.approval_guard,
                                self._stop_unapproved)
        # Rehearsal: while a command is rehearsed, its robot calls go to the twin, also on this side.
        if config.rehearse not in REHEARSE_MODES:
            raise ValueError(f'parameter rehearse={config.rehearse!r} is not one of {", ".join(REHEARSE_MODES)}')
        if config.rehearse != 'off' and self.domain.function_arguments:
            raise ValueError(f'domain {self.domain.name!r} cannot be rehearsed on a twin (its robot functions run '
                             'functions of the program); set rehearse to off')
        self.rehearse_mode = config.rehearse
        self.rehearsal = Rehearsal(self.domain.plan_functions)
        self.twin: Twin | None = None
        if config.rehearse != 'off':
            def twin_binding(node: Node, say: Any) -> Any:
                return self.domain.robot_api(node, say, config.service_timeout_s, config.motion_timeout_s)
            self.twin = Twin(self, self.robot, twin_binding, config.twin_joint_states_topic, config.twin_arm_joints,
                             config.service_timeout_s)
            api = self.rehearsal.routed(api, engine_api(self.domain, self.twin.binding.functions()),
                                        self.twin.check_harm)
            api[RESTART_REHEARSAL] = self._restart_rehearsal  # the engine's, for a feedback round on the twin
        limits = SandboxLimits(time_limit_s=config.time_limit_s)
        engine_options = {'regenerations': config.regenerations, 'plan_functions': list(self.domain.plan_functions),
                          'feedback_rounds': config.feedback_rounds}
        self.require_approval = config.require_approval
        self.approval_timeout_s = config.approval_timeout_s
        self.engine: CommandEngine
        self.model_ready = threading.Event()  # with llm_backend=local: set once the model has read the prompts
        self.model_ready_generation = 0  # the server start whose warm-up finished last
        local_client = (LocalModelClient(self.model_server, api=config.api or 'completions', gate=self.model_ready)
                        if self.model_server else None)
        client = GuardedClient(local_client or make_client(**client_options), self.approval_guard,
                               self._stop_unapproved)
        if config.sandbox_process:
            isolated = IsolatedEngine(self.domain.build_engine, api, client, limits,
                                      stall_limit_s=config.stall_limit_s,
                                      model_time_limit_s=config.model_time_limit_s, jail=config.jail,
                                      engine_options=engine_options,
                                      function_arguments=self.domain.function_arguments,
                                      on_deadline=self.robot.stop, child_command=sandbox_command)
            where = f'sandbox process {isolated.pid}'
            self.engine = isolated
        else:
            self.engine = self.domain.build_engine(api, client, limits, model_time_limit_s=config.model_time_limit_s,
                                                   **engine_options)
            where = 'in-process sandbox'
        self.engine.add_listener(self._on_engine_event)
        bind_engine = getattr(self.robot, 'bind_engine', None)
        if bind_engine is not None:  # a binding that calls the program's functions (a controller's ticks)
            bind_engine(self.engine)
        self.queue = CommandQueue(config.max_queued_commands)
        self._current: Job | None = None
        self._closing = False
        self.thread_watch = thread_watch or ThreadWatch(log=self._log_fatal)

        # Commands, stop and reset are handled apart from the action server so that a stop is never stuck behind
        # a goal callback; the action group is reentrant because execute callbacks wait for their job.
        control = MutuallyExclusiveCallbackGroup()
        self.create_subscription(String, GraphNames.COMMAND_TOPIC, self._on_command, COMMAND_QOS,
                                 callback_group=control)
        stopped = f'stopped on {self.resolve_topic_name(GraphNames.STOP_TOPIC)}'  # /cap/stop, or under the namespace
        self.create_subscription(Empty, GraphNames.STOP_TOPIC, lambda _: self.stop(stopped),
                                 COMMAND_QOS, callback_group=control)
        self.create_service(Trigger, GraphNames.RESET_SESSION_SERVICE, self._on_reset, callback_group=control)
        self.create_service(ApproveCommand, GraphNames.APPROVE_SERVICE, self._on_approve, callback_group=control)
        self._action = ActionServer(self, ExecuteCommand, GraphNames.EXECUTE_ACTION, self._execute_goal,
                                    goal_callback=self._on_goal, cancel_callback=lambda _: CancelResponse.ACCEPT,
                                    result_timeout=RESULT_TIMEOUT_S, callback_group=ReentrantCallbackGroup())
        # Registered after every declaration: declaring (with the start-up overrides) must not be refused.
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.thread_watch.add_callback(self._refuse_waiting)
        self._worker = self.thread_watch.start(self._work, 'lmp_worker')
        if self.model_server is not None:
            # Loading the model and reading the prompt's long prefix take seconds: on a thread of their own, so
            # the node answers at once; commands wait for the model (LocalModelClient.complete).
            self.thread_watch.start(self._start_model, 'model_start')
        ready = (f'ready: domain {self.domain.name}, LLM backend {config.llm_backend}'
                 + (f' ({cassette})' if config.llm_backend == 'cassette' else '') + f', {where}')
        self.get_logger().info(terminal_text(ready))
        # /cap/status holds an event from the start: a client that receives its history knows that this node has
        # discovered it, and with it the client's reply readers (cap send waits for that, see cli._ReplyPath).
        self._publish_model_state(ready)
        if not config.sandbox_process:  # no bound on a single C call: said in the log and on /cap/status
            self.get_logger().warning(IN_PROCESS_WARNING)
            self._publish_model_state(IN_PROCESS_WARNING)

    def _start_model(self) -> None:
        assert self.model_server is not None
        try:
            self.model_server.start()
        except LLMError as error:
            self._on_model_event(f'local model unavailable: {error}')
            self.model_ready.set()  # commands now get the server's error instead of waiting

    def _warm_up(self, generation: int) -> None:
        """Each time the server has (re)loaded its model: read the domain's prompts into its cache, then let
        commands through (they wait meanwhile: a cold prompt would cost each of them tens of seconds)."""
        assert self.model_server is not None
        self.model_ready.clear()
        try:
            warm = warm_up(LocalModelClient(self.model_server, api='completions'), prompt_heads(self.domain))
            self._on_model_event(f'model ready: {self.model_server.model_name} at {self.model_server.base_url} '
                                 f'(server start {generation}; {warm})')
            self.model_ready_generation = generation
        except LLMError as error:
            self._on_model_event(f'the local model did not read its prompts: {error}')
        finally:
            self.model_ready.set()

    def _on_model_event(self, message: str) -> None:
        """The local model's state on /cap/status (command_id empty, stage STAGE_MODEL) and in the log."""
        if self._closing:
            return
        try:
            self.get_logger().info(terminal_text(message))
        except Exception:  # the node is shutting down: nothing to tell
            return
        self._publish_model_state(message)

    def _publish_model_state(self, message: str) -> None:
        try:
            status = StatusEvent(stage=StatusEvent.STAGE_MODEL, message=wire_text(message))
            status.header.stamp = self.get_clock().now().to_msg()
            self._status_publisher.publish(status)
        except Exception:  # the node is shutting down: nothing to tell
            pass

    def _on_set_parameters(self, parameters: list) -> SetParametersResult:
        """Apply the few parameters that can change between commands; reject any other change, saying why."""
        for parameter in parameters:
            if parameter.name not in self._declared:
                continue
            if parameter.name not in RUNTIME_PARAMETERS:
                return SetParametersResult(successful=False, reason=(
                    f'{parameter.name} is read when lmp_node starts and cannot change while it runs; restart it '
                    f'with the new value (--ros-args -p {parameter.name}:=...); changeable at run time: '
                    + ', '.join(RUNTIME_PARAMETERS)))
            value = parameter.value
            if parameter.name == 'max_queued_commands' and (not isinstance(value, int) or value < 0):
                return SetParametersResult(successful=False, reason='max_queued_commands must be 0 or more')
            if parameter.name == 'require_approval' and not isinstance(value, bool):
                return SetParametersResult(successful=False, reason='require_approval is true or false')
            if parameter.name not in ('max_queued_commands', 'require_approval') and (
                    not isinstance(value, float) or not value > 0):
                return SetParametersResult(successful=False, reason=f'{parameter.name} must be more than 0 s')
        for parameter in parameters:
            if parameter.name == 'max_queued_commands':
                self.queue.max_waiting = parameter.value
            elif parameter.name == 'service_timeout_s':
                self.robot.service_timeout_s = parameter.value
            elif parameter.name == 'motion_timeout_s':
                self.robot.motion_timeout_s = parameter.value
            elif parameter.name == 'require_approval':
                self.require_approval = parameter.value
            elif parameter.name == 'approval_timeout_s':
                self.approval_timeout_s = parameter.value
        return SetParametersResult(successful=True)

    def _refuse_waiting(self, failure: str) -> None:
        """A thread the node depends on died: answer the commands that would otherwise wait for ever."""
        for job in self.queue.drain():
            job.refusal = f'refused: lmp_node cannot run commands any more ({failure})'
            job.outcome = Outcome.REFUSED
            self._publish_status(job, StatusEvent.STAGE_REFUSED, message=job.refusal)
            job.finished.set()

    def _log_fatal(self, line: str) -> None:
        self.get_logger().fatal(line)

    def _log_error(self, text: str) -> None:
        try:
            self.get_logger().error(terminal_text(text))
        except Exception:  # a logger that is gone (shutdown) must not end the thread that logs
            pass

    # -------------------------------------------------------------------------------------------- intake
    def _on_command(self, msg: String) -> None:
        self.submit(msg.data, 'topic')

    def submit(self, command: str, source: str, goal_handle: Any = None) -> tuple[Job, bool]:
        """Queue a command, or refuse it; either way its answer is on /cap/status."""
        job, queued = self.queue.submit(command, source, goal_handle)
        if queued and self.thread_watch.failure and self.queue.withdraw(job):  # nothing would ever run it
            queued = False
            job.refusal = f'refused: lmp_node cannot run commands any more ({self.thread_watch.failure})'
        if queued:
            self._publish_status(job, StatusEvent.STAGE_RECEIVED, message=f'queued behind {self.queue.waiting() - 1}'
                                 if self.queue.waiting() > 1 else '')
        else:
            self._publish_status(job, StatusEvent.STAGE_REFUSED, message=job.refusal)
            job.outcome = Outcome.REFUSED
            job.finished.set()
        return job, queued

    def _on_goal(self, goal_request) -> GoalResponse:
        # Every goal is accepted: a refusal is a result with a message, which a rejected goal cannot carry.
        return GoalResponse.ACCEPT

    def _execute_goal(self, goal_handle):
        job, queued = self.submit(goal_handle.request.command, 'action', goal_handle)
        try:
            while not job.finished.wait(0.02):
                if goal_handle.is_cancel_requested and not job.cancel_requested:
                    job.cancel_requested = True
                    job.stop_reason = 'cancelled by the client of /cap/execute'
                    if self.queue.withdraw(job):
                        job.outcome = Outcome.CANCELLED
                        self._publish_status(job, StatusEvent.STAGE_CANCELLED, message='cancelled before it ran')
                        job.finished.set()
                    elif self._current is job:
                        self._stop_running()
        finally:
            job.goal_handle = None
        result = ExecuteCommand.Result(command_id=job.command_id)
        outcome = job.outcome or Outcome.ERROR
        result.outcome = RESULT_OUTCOMES[outcome]
        if job.result is not None:
            result.success = bool(job.result.success)
            result.code = wire_text(job.result.code, MAX_CODE_CHARS)
            result.message = wire_text(job.result.message or 'done')
            result.model_calls = int(job.result.model_calls)
            result.prompt_tokens = int(job.result.prompt_tokens)
            result.completion_tokens = int(job.result.completion_tokens)
            result.model_seconds = float(job.result.timings.get('model_s', 0.0))
            result.total_seconds = float(job.result.timings.get('total_s', 0.0))
            result.rehearsed = job.verdict is not None
            if job.verdict is not None:
                result.twin_build_seconds = float(job.verdict.build_s)
                result.rehearsal_seconds = float(job.verdict.rehearse_s)
            result.prediction = wire_text(job.prediction)
            result.prediction_misses = [_prediction_miss(miss) for miss in job.prediction_misses]
        else:
            result.message = job.refusal or {Outcome.CANCELLED: 'cancelled before it ran',
                                             Outcome.ERROR: 'failed outside the program (see /cap/status)'}.get(
                job.outcome, 'lmp_node stopped before the command ran')
        if outcome is Outcome.CANCELLED and goal_handle.is_cancel_requested:
            goal_handle.canceled()
        elif result.success:
            goal_handle.succeed()
        else:
            goal_handle.abort()
        return result

    # -------------------------------------------------------------------------------------------- running
    def _work(self) -> None:
        while True:
            job = self.queue.next_job()
            if job is None:
                return
            self._current = job
            self.robot.stop_requested.clear()
            begin_command = getattr(self.robot, 'begin_command', None)  # optional (see RobotBinding)
            if begin_command is not None:
                begin_command()
            rehearse = self.twin is not None and rehearses(self.rehearse_mode, self.require_approval)
            self.engine.approval = self._gate if self.require_approval or rehearse else None
            self.engine.rehearse = rehearse
            if rehearse:
                self.approval_guard.begin(True, REHEARSAL_TOLERANCE, 'the rehearsed plan',
                                          () if self.require_approval else UNHELD_WHEN_REHEARSED)
            else:
                self.approval_guard.begin(self.require_approval)
            try:
                if not self._wait_for_model(job):
                    job.outcome = Outcome.CANCELLED
                    self._publish_status(job, StatusEvent.STAGE_CANCELLED, message=(
                        job.stop_reason or 'cancelled') + ' while it waited for the local model')
                    continue
                if rehearse and not self._begin_rehearsal(job):
                    job.outcome = self._outcome(job)
                    continue
                job.result = self.engine.run(job.command)
                self.rehearsal.end()
                if job.verdict is not None:  # a rehearsal that failed on the twin ends here
                    job.verdict.end_rehearsal()
                if job.verdict is not None and job.result.outcome is Outcome.DONE:
                    self._compare_prediction(job)
                job.outcome = self._outcome(job)
            except Exception as error:  # the engine reports program errors itself; this is a last resort
                if self._closing:
                    return
                job.outcome = Outcome.ERROR
                text = f'internal error: {type(error).__name__}: {wire_text(str(error))}'
                self._log_error(f'{job.command_id} failed outside the program: {text}')
                self._publish_status(job, StatusEvent.STAGE_ERROR, message=text)
            finally:
                self.rehearsal.end()
                self._current = None
                self.queue.finish(job)

    def _outcome(self, job: Job) -> Outcome:
        """Publish the final status of a job that ran, and name its outcome."""
        result = job.result
        outcome = result.outcome
        violation = self.approval_guard.violation
        if violation:  # the program broke its approval: refused, whatever the stop made of it in the sandbox
            outcome = result.outcome = Outcome.REFUSED
            result.success = False
            result.message = violation if violation in result.message else f'{violation} ({result.message})'
        elif outcome not in (Outcome.DONE, Outcome.REFUSED) and job.cancel_requested:
            outcome = Outcome.CANCELLED  # whatever the stop caused (a failed robot call, a lost model request)
        if outcome is Outcome.CANCELLED and job.stop_reason:
            result.message = f'{job.stop_reason} ({result.message})'
        # The final status says what the command cost, model time first: it has a deadline of its own.
        cost = (f"model {result.timings.get('model_s', 0.0):.2f} s in {result.model_calls} call(s), "
                f"total {result.timings.get('total_s', 0.0):.2f} s")
        self._publish_status(job, _FINAL_STAGES.get(outcome, StatusEvent.STAGE_ERROR), code=result.code,
                             message=f'{result.message or outcome.value} ({cost})')
        return outcome

    def _on_engine_event(self, event: engine_module.EngineEvent) -> None:
        job = self._current
        if job is None:
            return
        top_level = event.lmp == self.engine.default_lmp
        if event.stage in (engine_module.DONE, engine_module.ERROR):
            return  # the final status is published once the run returns (see _outcome)
        if event.stage == engine_module.CODE and top_level and not self._closing:
            self._code_publisher.publish(String(data=wire_text(event.code, MAX_CODE_CHARS)))
        if top_level or event.stage == engine_module.GENERATING:
            message = event.message if top_level else f'{event.lmp}: generating'
            self._publish_status(job, _STAGES[event.stage], code=event.code if top_level else '', message=message)

    def _publish_status(self, job: Job, stage: int, code: str = '', message: str = '',
                        plan: list[PlannedMotion] | None = None, twin_image: bytes = b'') -> None:
        if self._closing:
            return
        status = StatusEvent(command_id=job.command_id, command=wire_text(job.command), stage=stage,
                             code=wire_text(code, MAX_CODE_CHARS), message=wire_text(message), plan=plan or [])
        if twin_image:
            status.twin_image.format = 'png'
            status.twin_image.data = twin_image
        status.header.stamp = self.get_clock().now().to_msg()
        self._status_publisher.publish(status)
        goal_handle = job.goal_handle
        if goal_handle is not None:
            goal_handle.publish_feedback(ExecuteCommand.Feedback(status=status))

    # -------------------------------------------------------------------------------------------- rehearsal
    def _begin_rehearsal(self, job: Job) -> bool:
        """Build the twin from the world as perceived and route the program's calls to it. False when the twin
        could not be built: the command is then refused (job.result says why) and nothing moved."""
        assert self.twin is not None
        self._publish_status(job, StatusEvent.STAGE_RECEIVED, message='building the twin from the scene as '
                                                                      'perceived, to rehearse the program on it')
        started = time.monotonic()
        self.twin.stop_requested.clear()
        try:
            start = self.twin.build()
        except RobotApiError as error:
            job.result = CommandResult(command=job.command, command_id=0, success=False,
                                       outcome=Outcome.REFUSED,
                                       message=f'the twin could not be built, so the program did not run: {error}')
            return False
        job.verdict = TwinVerdict(start=start, build_s=time.monotonic() - started, rehearse_from=time.monotonic())
        self.rehearsal.begin()
        return True

    def _restart_rehearsal(self) -> None:
        """The engine asks for a new rehearsal of the running command (its program failed on the twin, and the
        model wrote another): the twin is built again from the world as it is, the calls recorded so far dropped."""
        job = self._current
        if job is None or job.verdict is None or not self.rehearsal.active:
            raise RobotApiError('no rehearsal is running')
        assert self.twin is not None
        job.verdict.start = self.twin.build()
        self.rehearsal.begin()

    def _gate(self, code: str, calls: list[PlannedCall]) -> None:
        """The engine's gate after its plan run (on the worker thread): a rehearsal's verdict first, then a
        person's approval if required. NotApproved stops the command before the robot moves."""
        job = self._current
        verdict = job.verdict if job is not None else None
        if verdict is not None:
            assert self.twin is not None
            verdict.calls = self.rehearsal.end()  # what the twin received, not what the program says it planned
            verdict.end_rehearsal()
            try:
                self.twin.verdict(verdict)
            except RobotApiError as error:
                raise NotApproved(f'the rehearsal could not be judged ({error}); the robot did not move',
                                  'rehearsal') from None
            if verdict.findings:
                raise NotApproved(f'on the twin: {"; ".join(verdict.findings)}; the robot did not move', 'rehearsal')
            calls = verdict.calls
            self._publish_status(job, StatusEvent.STAGE_CODE, code=code, message=verdict.summary())
        if self.require_approval:
            self._await_approval(code, calls, verdict)
        else:
            self.approval_guard.approve(calls)  # from now on the program may make exactly these calls

    def _compare_prediction(self, job: Job) -> None:
        """After a rehearsed program ran: where the world differs from the twin's prediction."""
        assert self.twin is not None and job.verdict is not None
        verdict = job.verdict
        try:
            observed = self.twin.observe()
        except RobotApiError as error:
            job.prediction = f'the twin\'s prediction could not be compared: {error}'
            return
        job.prediction_misses = prediction_misses(verdict.start, verdict.predicted, observed)
        job.prediction = prediction_text(job.prediction_misses, len(set(observed) & set(verdict.predicted)))
        job.result.message = f'{job.result.message or "done"}; {job.prediction}'

    # -------------------------------------------------------------------------------------------- approval
    def _await_approval(self, code: str, calls: list[PlannedCall], verdict: TwinVerdict | None = None) -> None:
        """The engine's approval gate (on the worker thread): show the code and its plan, wait for /cap/approve.

        Returns when approved; raises NotApproved when rejected or not approved within approval_timeout_s, and
        ExecutionStopped when the command is stopped meanwhile."""
        job = self._current
        if job is None:
            raise NotApproved('no command is running', 'rejected')
        self.approval_guard.may_ask()  # not after acting before asking, nor a second time: nobody is asked then
        steps = [self._plan_step(call) for call in calls]
        timeout_s = self.approval_timeout_s
        service = self.resolve_topic_name(GraphNames.APPROVE_SERVICE)
        job.decided.clear()
        job.awaiting_approval = True
        try:
            rehearsed = f'; {verdict.summary()}' if verdict is not None else ''
            self._publish_status(job, StatusEvent.STAGE_AWAITING_APPROVAL, code=code, plan=[
                _planned_motion(step) for step in steps], message=(
                    f'waiting for approval on {service} (within {timeout_s:g} s): {plan_summary(steps)}{rehearsed}'),
                twin_image=verdict.image_png if verdict is not None else b'')
            deadline = time.monotonic() + timeout_s
            while not job.decided.wait(0.05):
                if job.cancel_requested or self._closing:
                    raise ExecutionStopped('the program was cancelled while it waited for approval', 'cancelled')
                if time.monotonic() > deadline:
                    raise NotApproved(f'not approved within {timeout_s:g} s (approval_timeout_s), so nothing ran',
                                      'timeout')
        finally:
            job.awaiting_approval = False
        approved, reason = job.decision
        if not approved:
            raise NotApproved('rejected' + (f': {reason}' if reason else '') + '; nothing ran', 'rejected')
        self.approval_guard.approve(calls)  # from now on the program may make exactly these calls

    def _plan_step(self, call: PlannedCall) -> PlanStep:
        try:
            return self.domain.describe_call(call)
        except Exception as error:  # a domain's describer must not lose the plan: show the bare call
            self._log_error(f'describing a planned {call.function}() failed: {error!r}')
            return PlanStep(call.function, f'{call.function}(...)')

    def _on_approve(self, request: ApproveCommand.Request,
                    response: ApproveCommand.Response) -> ApproveCommand.Response:
        job = self._current
        if job is None or not job.awaiting_approval or job.decided.is_set() or job.command_id != request.command_id:
            waiting = (f'; {job.command_id} waits' if job is not None and job.awaiting_approval
                       and not job.decided.is_set() else '; no command waits for approval')
            response.success = False
            response.message = wire_text(f'command {request.command_id!r} does not wait for approval{waiting}')
            return response
        job.decision = (bool(request.approve), wire_text(request.reason, 500))
        job.decided.set()
        response.success = True
        response.message = f'{job.command_id} ' + ('approved: it runs now' if request.approve else
                                                   'rejected: it will not run')
        self.get_logger().info(terminal_text(response.message))
        return response

    def _stop_unapproved(self) -> None:
        """The guard refused a call of the running program: stop it (the call itself did not go through)."""
        self.engine.cancel()

    # -------------------------------------------------------------------------------------------- stop, reset
    def _wait_for_model(self, job: Job) -> bool:
        """A command that comes while the local model loads and reads its prompts waits here, before its model
        deadline starts: the warm-up is the graph's cost, not the command's. False when it was stopped meanwhile."""
        if self.model_server is None or self.model_ready.is_set():
            return True
        self._publish_status(job, StatusEvent.STAGE_RECEIVED, message=(
            'waiting for the local model to load and read its prompts (/cap/status says "model ready" when it has); '
            "the command's model deadline starts then"))
        while not self.model_ready.wait(0.1):
            if job.cancel_requested or self._closing:
                return False
        return not job.cancel_requested

    def _stop_running(self) -> None:
        self.engine.cancel()
        self.robot.stop()
        if self.twin is not None:
            self.twin.stop()

    def stop(self, reason: str) -> None:
        """End the running command and its motion; drop waiting commands."""
        for job in self.queue.drain():
            job.outcome = Outcome.CANCELLED
            self._publish_status(job, StatusEvent.STAGE_CANCELLED, message=reason)
            job.finished.set()
        current = self._current
        if current is not None:
            current.cancel_requested = True
            current.stop_reason = reason
            self._stop_running()
        self.get_logger().info(terminal_text(reason))

    def _on_reset(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        if self._current is not None:
            response.success = False
            response.message = wire_text(f'a command is running ({self._current.command!r}); stop it first')
            return response
        self.engine.reset()
        response.success = True
        response.message = 'session reset: earlier variables and generated functions are forgotten'
        return response

    def destroy_node(self) -> None:
        self._closing = True
        self.thread_watch.stop()
        self.queue.close()
        self._stop_running()
        self.engine.close()
        if self.model_server is not None:
            self.model_server.stop()
        if self.twin is not None:
            self.twin.destroy()
        super().destroy_node()


def _planned_motion(step: PlanStep) -> PlannedMotion:
    return PlannedMotion(function=wire_text(step.function, 100), object_name=wire_text(step.object_name, 200),
                         target_name=wire_text(step.target_name, 200), description=wire_text(step.description, 500),
                         points=[Point(x=x, y=y, z=z) for x, y, z in step.points[:100]])


def _prediction_miss(miss) -> PredictionMiss:
    return PredictionMiss(name=wire_text(miss.name, 200), predicted=Point(x=miss.predicted[0], y=miss.predicted[1],
                                                                          z=miss.predicted[2]),
                          observed=Point(x=miss.observed[0], y=miss.observed[1], z=miss.observed[2]),
                          distance=float(miss.distance), unexpected=bool(miss.unexpected))


def main(args=None) -> None:
    """The `lmp_node` entry point. Exits 0 on Ctrl-C or SIGTERM, 2 on a configuration error (one line), and
    FATAL_EXIT_CODE when a thread it depends on died (one line naming the thread and the error)."""
    rclpy.init(args=args)
    watch = ThreadWatch()
    watch.install_excepthook()  # any other thread of this process that dies is fatal too
    try:
        node = LmpNode(thread_watch=watch)
    except ValueError as error:
        print(f'lmp_node: {terminal_text(str(error))}', file=sys.stderr)
        rclpy.try_shutdown()
        sys.exit(2)
    watch.log = node._log_fatal
    executor = MultiThreadedExecutor(num_threads=4)
    executor.add_node(node)
    if node.twin is not None:
        executor.add_node(node.twin.node)
    died = Future()
    watch.add_callback(lambda _line: died.set_result(True))
    status = 0
    try:
        executor.spin_until_future_complete(died)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception as error:  # a callback raised: the executor re-raises it here
        watch.report('executor', error)
    finally:
        if watch.failure:
            status = FATAL_EXIT_CODE
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
    if status:
        sys.exit(status)
