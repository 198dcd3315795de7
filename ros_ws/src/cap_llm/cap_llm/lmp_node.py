"""lmp_node: natural-language commands in, generated and executed policy code out.

Commands arrive on /cap/command (std_msgs/String) or as /cap/execute goals. One runs at a time on a worker thread;
later ones wait in a FIFO of `max_queued_commands` and are refused when it is full (see command_queue.py). Every
stage is published on /cap/status; the generated code on /cap/code, what the robot says on /cap/say. /cap/stop
ends the running program and its motion and drops waiting commands. /cap/reset_session forgets the session.
"""
from __future__ import annotations

import pathlib
import threading
from typing import Any

import rclpy
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import Empty, String
from std_srvs.srv import Trigger

from cap_interfaces.action import ExecuteCommand
from cap_interfaces.msg import GraphNames, StatusEvent
from cap_llm import engine as engine_module
from cap_llm.cassette import make_client
from cap_llm.command_queue import CommandQueue, Job
from cap_llm.isolated_engine import IsolatedEngine
from cap_llm.ros_robot_api import RosTabletopApi
from cap_llm.sandbox import SandboxLimits
from cap_llm.tabletop import build_tabletop_engine

DEFAULT_CASSETTE = pathlib.Path(__file__).resolve().parent / 'cassettes' / 'tabletop_reference.yaml'

# Commands and stops must not be lost: reliable, a few deep.
COMMAND_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
# Status and code are events a late subscriber may want to see the last few of.
EVENT_QOS = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)

_STAGES = {engine_module.GENERATING: StatusEvent.STAGE_GENERATING, engine_module.CODE: StatusEvent.STAGE_CODE,
           engine_module.EXECUTING: StatusEvent.STAGE_EXECUTING}


class LmpNode(Node):
    def __init__(self, **kwargs: Any) -> None:
        super().__init__('lmp_node', **kwargs)
        backend = self._parameter('llm_backend', 'cassette', 'cassette (replay a recorded cassette, offline) or '
                                  'http (an OpenAI-compatible endpoint; CAP_LLM_BASE_URL, CAP_LLM_MODEL, '
                                  'CAP_LLM_API_KEY from the environment unless set below).')
        cassette = self._parameter('cassette', '', 'Cassette file for llm_backend=cassette, or the file to record '
                                   'into with record_cassette=true; empty: the packaged reference cassette.')
        cassette = cassette or str(DEFAULT_CASSETTE)
        record = self._parameter('record_cassette', False, 'With llm_backend=http: also record every answer '
                                 'into `cassette`.')
        base_url = self._parameter('base_url', '', 'OpenAI-compatible endpoint; empty: CAP_LLM_BASE_URL.')
        model = self._parameter('model', '', 'Model name; empty: CAP_LLM_MODEL.')
        api = self._parameter('api', 'chat', 'chat (chat completions) or completions (legacy completions).')
        request_timeout = self._parameter('request_timeout_s', 60.0, 'Timeout of one model request [s].')
        time_limit = self._parameter('time_limit_s', 300.0, 'Wall-clock limit of one generated program, robot '
                                     'motion included [s].')
        service_timeout = self._parameter('service_timeout_s', 5.0, 'Timeout of one perception request [s].')
        motion_timeout = self._parameter('motion_timeout_s', 180.0, 'Timeout of one pick-and-place [s].')
        max_queued = self._parameter('max_queued_commands', 5, 'Commands that may wait while one runs; more are '
                                     'refused.')
        domain = self._parameter('domain', 'tabletop', 'Robot domain of the prompts and API (tabletop).')
        if domain != 'tabletop':
            raise ValueError(f'parameter domain={domain!r}: only "tabletop" exists so far')

        isolated = self._parameter('sandbox_process', True, 'Run generated programs in a sandbox process of their '
                                   'own (a crash or a stuck C call then costs the session, not the node); false: '
                                   'in this process (faster to start, for debugging).')
        stall_limit = self._parameter('stall_limit_s', 10.0, 'With sandbox_process: kill the sandbox process when '
                                      'one operation holds it this long without a pause [s].')

        http_options: dict[str, Any] = {'timeout_s': request_timeout, 'api': api}
        if base_url:
            http_options['base_url'] = base_url
        if model:
            http_options['model'] = model
        if backend == 'cassette':
            client_options: dict[str, Any] = {'cassette': cassette}
        elif backend == 'http':
            client_options = {'cassette': cassette if record else None, 'record': record, **http_options}
        else:
            raise ValueError(f'parameter llm_backend={backend!r} is not one of cassette, http')

        self._code_publisher = self.create_publisher(String, GraphNames.CODE_TOPIC, EVENT_QOS)
        self._status_publisher = self.create_publisher(StatusEvent, GraphNames.STATUS_TOPIC, EVENT_QOS)
        say_publisher = self.create_publisher(String, GraphNames.SAY_TOPIC, EVENT_QOS)
        self.robot = RosTabletopApi(self, say_publisher, service_timeout, motion_timeout)
        limits = SandboxLimits(time_limit_s=time_limit)
        if isolated:
            self.engine = IsolatedEngine(self.robot.functions(), client_options, limits, domain=domain,
                                         stall_limit_s=stall_limit)
        else:
            self.engine = build_tabletop_engine(self.robot.functions(), make_client(**client_options), limits)
        self.engine.add_listener(self._on_engine_event)
        self.queue = CommandQueue(max_queued)
        self._current: Job | None = None

        # Commands, stop and reset are handled apart from the action server so that a stop is never stuck behind
        # a goal callback; the action group is reentrant because execute callbacks wait for their job.
        control = MutuallyExclusiveCallbackGroup()
        self.create_subscription(String, GraphNames.COMMAND_TOPIC, self._on_command, COMMAND_QOS,
                                 callback_group=control)
        self.create_subscription(Empty, GraphNames.STOP_TOPIC, lambda _: self.stop('stopped on /cap/stop'),
                                 COMMAND_QOS, callback_group=control)
        self.create_service(Trigger, GraphNames.RESET_SESSION_SERVICE, self._on_reset, callback_group=control)
        self._action = ActionServer(self, ExecuteCommand, GraphNames.EXECUTE_ACTION, self._execute_goal,
                                    goal_callback=self._on_goal, cancel_callback=lambda _: CancelResponse.ACCEPT,
                                    callback_group=ReentrantCallbackGroup())
        self._worker = threading.Thread(target=self._work, name='lmp_worker', daemon=True)
        self._worker.start()
        where = f'sandbox process {self.engine.pid}' if isolated else 'in-process sandbox'
        self.get_logger().info(f'ready: LLM backend {backend}' + (f' ({cassette})' if backend == 'cassette' else '')
                               + f', {where}')

    def _parameter(self, name: str, default: Any, description: str) -> Any:
        return self.declare_parameter(name, default, ParameterDescriptor(description=description)).value

    # -------------------------------------------------------------------------------------------- intake
    def _on_command(self, msg: String) -> None:
        self.submit(msg.data, 'topic')

    def submit(self, command: str, source: str, goal_handle: Any = None) -> tuple[Job, bool]:
        job, queued = self.queue.submit(command, source, goal_handle)
        if queued:
            self._publish_status(job, StatusEvent.STAGE_RECEIVED, message=f'queued behind {self.queue.waiting() - 1}'
                                 if self.queue.waiting() > 1 else '')
        else:
            self._publish_status(job, StatusEvent.STAGE_REFUSED,
                                 message=f'busy: {self.queue.max_waiting} commands are already waiting')
            job.outcome = 'refused'
            job.finished.set()
        return job, queued

    def _on_goal(self, goal_request) -> GoalResponse:
        if not goal_request.command.strip():
            return GoalResponse.REJECT
        return GoalResponse.REJECT if self.queue.waiting() >= self.queue.max_waiting else GoalResponse.ACCEPT

    def _execute_goal(self, goal_handle):
        job, queued = self.submit(goal_handle.request.command, 'action', goal_handle)
        try:
            while not job.finished.wait(0.02):
                if goal_handle.is_cancel_requested and not job.cancel_requested:
                    job.cancel_requested = True
                    job.stop_reason = 'cancelled by the client of /cap/execute'
                    if self.queue.withdraw(job):
                        job.outcome = 'cancelled'
                        self._publish_status(job, StatusEvent.STAGE_CANCELLED, message='cancelled before it ran')
                        job.finished.set()
                    elif self._current is job:
                        self._stop_running()
        finally:
            job.goal_handle = None
        result = ExecuteCommand.Result(command_id=job.command_id)
        if job.result is not None:
            result.success = bool(job.result.success)
            result.code = job.result.code
            result.message = job.result.message or 'done'
            result.model_calls = int(job.result.model_calls)
            result.prompt_tokens = int(job.result.prompt_tokens)
            result.completion_tokens = int(job.result.completion_tokens)
            result.model_seconds = float(job.result.timings.get('model_s', 0.0))
            result.total_seconds = float(job.result.timings.get('total_s', 0.0))
        else:
            result.message = {'refused': 'refused: too many commands waiting',
                              'cancelled': 'cancelled before it ran'}.get(job.outcome, job.outcome)
        if job.outcome == 'cancelled' and goal_handle.is_cancel_requested:
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
            try:
                job.result = self.engine.run(job.command)
                job.outcome = self._outcome(job)
            except Exception as error:  # the engine reports program errors itself; this is a last resort
                self.get_logger().error(f'{job.command_id} failed outside the program: {error!r}')
                job.outcome = 'error'
                self._publish_status(job, StatusEvent.STAGE_ERROR, message=f'internal error: {error}')
            finally:
                self._current = None
                self.queue.finish(job)

    def _outcome(self, job: Job) -> str:
        """Publish the final status of a job that ran, and name its outcome."""
        result = job.result
        if result.success:
            stage, outcome = StatusEvent.STAGE_DONE, 'done'
        elif result.error_type in ('CodeRejected', 'SyntaxError'):
            # The program never ran: nothing moved.
            stage, outcome = StatusEvent.STAGE_REFUSED, 'refused'
        elif result.stop_reason == 'cancelled' or result.error_type == 'StoppedError' or job.cancel_requested:
            stage, outcome = StatusEvent.STAGE_CANCELLED, 'cancelled'
            if job.stop_reason:
                result.message = f'{job.stop_reason} ({result.message})'
        else:
            stage, outcome = StatusEvent.STAGE_ERROR, 'error'
        self._publish_status(job, stage, code=result.code, message=result.message or outcome)
        return outcome

    def _on_engine_event(self, event: engine_module.EngineEvent) -> None:
        job = self._current
        if job is None:
            return
        top_level = event.lmp == self.engine.default_lmp
        if event.stage in (engine_module.DONE, engine_module.ERROR):
            return  # the final status is published once the run returns (see _outcome)
        if event.stage == engine_module.CODE and top_level:
            self._code_publisher.publish(String(data=event.code))
        if top_level or event.stage == engine_module.GENERATING:
            message = event.message if top_level else f'{event.lmp}: generating'
            self._publish_status(job, _STAGES[event.stage], code=event.code if top_level else '', message=message)

    def _publish_status(self, job: Job, stage: int, code: str = '', message: str = '') -> None:
        status = StatusEvent(command_id=job.command_id, command=job.command, stage=stage, code=code,
                             message=message)
        status.header.stamp = self.get_clock().now().to_msg()
        self._status_publisher.publish(status)
        goal_handle = job.goal_handle
        if goal_handle is not None:
            goal_handle.publish_feedback(ExecuteCommand.Feedback(status=status))

    # -------------------------------------------------------------------------------------------- stop, reset
    def _stop_running(self) -> None:
        self.engine.cancel()
        self.robot.stop()

    def stop(self, reason: str) -> None:
        """End the running command and its motion; drop waiting commands."""
        for job in self.queue.drain():
            job.outcome = 'cancelled'
            self._publish_status(job, StatusEvent.STAGE_CANCELLED, message=reason)
            job.finished.set()
        current = self._current
        if current is not None:
            current.cancel_requested = True
            current.stop_reason = reason
            self._stop_running()
        self.get_logger().info(reason)

    def _on_reset(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        if self._current is not None:
            response.success = False
            response.message = f'a command is running ({self._current.command!r}); stop it first'
            return response
        self.engine.reset()
        response.success = True
        response.message = 'session reset: earlier variables and generated functions are forgotten'
        return response

    def destroy_node(self) -> None:
        self.queue.close()
        self._stop_running()
        close = getattr(self.engine, 'close', None)
        if close is not None:
            close()
        super().destroy_node()


def main(args=None) -> None:
    rclpy.init(args=args)
    node = LmpNode()
    executor = MultiThreadedExecutor(num_threads=4)
    executor.add_node(node)
    try:
        executor.spin()
    except KeyboardInterrupt:
        pass
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
