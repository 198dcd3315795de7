"""The LMP engine: prompts a code-writing model, generates missing functions, checks and runs the code.

An LMP (language model program) is a few-shot prompt plus an LMPConfig. All LMPs of an Engine share one variable
scope: the robot API, np and Shapely names, the LMPs that generated code may call (e.g. `parse_obj_name`), the
functions generated so far, and the variables of the session. `Engine.run(command)` is what a front end (the ROS
node, a CLI, a benchmark) calls; it never raises for problems of the generated code and returns a CommandResult.

Prompt assembly, as in the Code as Policies paper: base prompt, then the session history (for LMPs that keep a
session), then the context line (e.g. `objects = ['blue block', ...]`), then the query as a comment
(`# put the blue block in the red bowl.`). The model's answer is code up to the stop sequences.

Hierarchical function generation: the checked code's AST is searched for called bare names nothing defines; for
each, the function-generation LMP is asked `# define function: y = f(x).`, the answer must define `f`, and its body
is searched the same way, depth first. Children are defined before their parents, in the one shared scope, so a
parent finds its children by name when it runs (that is the re-binding). A name already being generated higher in
the chain is not asked for again (the cycle guard: mutual recursion then works once both exist); a chain longer
than `max_function_depth` or more than `max_generated_functions` per command is an error.

Limits of one command besides the sandbox's (sandbox.py):
- **model deadline**: the model requests of one command (the top-level program, nested LMP calls and function
  generation) take at most `model_time_limit_s` together; each request is sent with the budget that is left
  (`CompletionRequest.time_budget_s`), and once it is spent the command stops with reason 'model_timeout' (inside a
  running program through the watchdog, so the program cannot catch it). Model time does not count against the
  execution time limit.
- **program size**: a model answer, and a program together with the functions generated for it, may hold at most
  wire.MAX_PROGRAM_CHARS characters; a longer one is refused before anything runs, so what runs is always what the
  result and /cap/code show in full.
- **memory**: a command stopped for memory (the watchdog's limit, or a MemoryError) drops the variables it bound;
  if the session still holds more than half the limit afterwards, the session is reset, and the result says so.

Approval (approval.py): with `approval` set, the checked code is first run in plan-only mode (the
`plan_functions` only record their calls, on a copy of the session) and the gate is asked with the code (the nested
LMPs' code the plan asked for included) and that plan; the program runs only once it returns. A rejection, or no
approval in time, ends the command as refused; nothing of it ran. The approved run executes the code it was
approved with: a nested LMP asked with a query the plan did not ask stops it (reason 'unapproved', refused), with
no new model request.

Execution feedback (feedback.py): with `feedback_rounds`, a program that fails while it runs (a robot call's error,
a Python error) is followed by a new one the model writes after reading its failed program, the error and its
line, the robot actions that completed and the scene now; it continues the command from there. The programs of one
command share its time limit and its model deadline; stops, the sandbox's refusals and approved runs stay final.
0 (the default) is the paper's protocol: one program per command.

Threads: `run` executes on the calling thread and holds a lock (one command at a time); `cancel()` may be called
from any thread and stops the running program at its next checkpoint with ExecutionStopped(reason='cancelled').
"""
from __future__ import annotations

import ast
import ctypes
import gc
import itertools
import logging
import threading
import time
import traceback
from dataclasses import dataclass, field
from typing import Any, Callable, Iterable, Mapping

from cap_lmp.approval import ApprovalGate, PlannedCall, recorders, session_copy
from cap_lmp.continuation import continued_program
from cap_lmp.errors import (CapLLMError, CodeRejected, ExecutionStopped, GenerationError, NotApproved, UndefinedName,
                            UnusableAnswer)
from cap_lmp.feedback import action_recorders, continue_query, failure_lines, feedback_block, worth_feedback
from cap_lmp.rehearsal import RESTART_REHEARSAL
from cap_lmp.functions import top_level_functions, undefined_calls
from cap_lmp.llm import Completion, CompletionRequest, LLMClient
from cap_lmp.outcome import Outcome, outcome_of
from cap_lmp.provided_imports import drop_provided_imports
from cap_lmp.unbound import bound_names, unbound_names
from cap_lmp.sandbox import SANDBOX_FILE_PREFIX, CompiledProgram, Sandbox, SandboxLimits, bounded_exception_text
from cap_lmp.wire import MAX_CODE_CHARS, MAX_PROGRAM_CHARS

_log = logging.getLogger(__name__)


@dataclass(frozen=True)
class LMPConfig:
    """One language model program: its prompt and how its answers are used."""

    name: str
    prompt: str  # the few-shot prompt text (see cap_lmp.prompts.load_prompt)
    query_prefix: str = '# '
    query_suffix: str = '.'
    stop: tuple[str, ...] = ('#', 'objects = [')
    maintain_session: bool = False  # keep earlier commands (context, query, code) in the prompt
    has_return: bool = False  # the code sets `return_val_name`, which the call returns
    return_val_name: str = 'ret_val'
    context_var: str | None = None  # top-level runs add `<context_var> = <context_api()>`, e.g. objects = [...]
    context_api: str | None = None
    execute_context: bool = True  # run the context line before the code (so the code can use the variable)
    callable_from_code: bool = False  # generated code may call this LMP by name: name(query, context='')
    max_tokens: int = 512
    temperature: float = 0.0
    # The answer continues the query's text instead of following it on a new line, and the program is the query
    # followed by the answer: for prompts that end inside a function (HumanEval's signature and docstring).
    answer_continues_query: bool = False
    # A benchmark harness's own rules for this LMP's programs, applied before the sandbox checks them (HumanEval's
    # imports become provided names); it may raise to refuse a program. None for every robot LMP.
    prepare_source: Callable[[str], str] | None = None
    generate_functions: bool = True  # False: a call of an undefined function is an error in this LMP's code
    # Of the function-generation LMP: how a missing function is asked for, 'call' (as the program called it, the
    # paper's queries) or 'parameters' (parameter names in place of the call's values; see functions.UndefinedCall).
    signature_style: str = 'call'
    # The domain's own check of an answer before it runs: (program's AST, query, context line) -> a reason the
    # answer cannot be meant (e.g. it names an object that is neither in the scene nor in the command) or None.
    # A reason makes the answer unusable: asked for again (Engine's regenerations), else the command fails.
    check_answer: Callable[[ast.Module, str, str], str | None] | None = None


@dataclass(frozen=True)
class EngineEvent:
    """Progress of a command, for /cap/status and /cap/code. stage: generating, code, executing, done, error."""

    command_id: int
    stage: str
    lmp: str
    code: str = ''
    message: str = ''


GENERATING, CODE, EXECUTING, DONE, ERROR = 'generating', 'code', 'executing', 'done', 'error'


@dataclass
class CommandResult:
    """What one command did. `code` is the top-level program followed by the functions generated for it."""

    command: str
    command_id: int
    success: bool
    code: str = ''
    message: str = ''
    outcome: Outcome = Outcome.ERROR  # how it ended; DONE exactly when success
    error_type: str = ''
    error_line: int | None = None
    error_source: str | None = None
    stop_reason: str = ''  # of ExecutionStopped: 'timeout', 'cancelled', 'memory', 'recursion', 'unapproved', ...
    model_calls: int = 0
    prompt_tokens: int = 0
    completion_tokens: int = 0
    timings: dict[str, float] = field(default_factory=dict)
    generated_functions: list[str] = field(default_factory=list)


@dataclass
class _RunStats:
    model_calls: int = 0
    prompt_tokens: int = 0
    completion_tokens: int = 0
    model_s: float = 0.0
    generated: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class PreparedCode:
    """A checked answer of the model with the functions it needed, ready to run."""

    main: CompiledProgram
    functions: tuple[tuple[str, CompiledProgram], ...]

    def full_code(self) -> str:
        parts = [self.main.source.rstrip()]
        parts += [program.source.rstrip() for _, program in self.functions]
        return '\n\n'.join(part for part in parts if part)


def _worth_asking_again(error: Exception) -> bool:
    """An answer that cannot run (another sample may), not one the sandbox refused on purpose (final)."""
    if isinstance(error, (UndefinedName, UnusableAnswer)):
        return True
    return _is_syntax_error(error)


def _is_syntax_error(error: Exception) -> bool:
    """The sandbox's check reports code that is not Python as a CodeRejected saying 'syntax error'."""
    return isinstance(error, CodeRejected) and 'syntax error' in str(error)


def _has_statements(source: str) -> bool:
    try:
        return bool(ast.parse(source).body)
    except (SyntaxError, ValueError, RecursionError, MemoryError):
        return True  # not for this check to judge: the sandbox's check already passed it


def check_program_size(text: str, what: str = "the model's answer") -> None:
    """Refuse a program longer than wire.MAX_PROGRAM_CHARS before it is parsed or run."""
    if len(text) > MAX_PROGRAM_CHARS:
        raise CodeRejected(f'{what} has {len(text):,} characters; programs are limited to {MAX_PROGRAM_CHARS:,} '
                           'characters, so it was not run')


def _return_freed_memory() -> None:
    """Collect garbage and hand freed heap back to the system (glibc), so resident memory reflects what is kept."""
    gc.collect()
    try:
        ctypes.CDLL(None).malloc_trim(0)  # the process' own symbols: no file to open, no helper to run
    except (OSError, AttributeError):
        pass  # not glibc: resident memory shrinks later, or not at all


def last_assigned_name(source: str) -> str | None:
    """The variable the program's last statement assigns (`x = ...`), or None."""
    try:
        body = ast.parse(source).body
    except SyntaxError:
        return None
    if body and isinstance(body[-1], ast.Assign) and len(body[-1].targets) == 1 \
            and isinstance(body[-1].targets[0], ast.Name):
        return body[-1].targets[0].id
    return None


def literal_assignment(line: str) -> tuple[str, Any] | None:
    """(name, value) if `line` is `name = <Python literal>`, else None."""
    try:
        tree = ast.parse(line)
    except (SyntaxError, ValueError, RecursionError, MemoryError):
        return None
    if len(tree.body) != 1 or not isinstance(tree.body[0], ast.Assign):
        return None
    statement = tree.body[0]
    if len(statement.targets) != 1 or not isinstance(statement.targets[0], ast.Name):
        return None
    name = statement.targets[0].id
    if name.startswith('_'):
        return None
    try:
        return name, ast.literal_eval(statement.value)
    except (ValueError, TypeError, SyntaxError, MemoryError, RecursionError):
        return None


class Engine:
    """LMPs over one shared scope, one LLM client and one sandbox. See the module docstring."""

    def __init__(self, lmps: Iterable[LMPConfig], client: LLMClient, api: Mapping[str, Any] | None = None, *,
                 limits: SandboxLimits | None = None, default_lmp: str | None = None, fgen_lmp: str | None = 'fgen',
                 max_function_depth: int = 4, max_generated_functions: int = 16,
                 model_time_limit_s: float = 120.0, regenerations: int = 0,
                 regeneration_temperature: float = 0.7, plan_functions: Iterable[str] = (),
                 feedback_rounds: int = 0) -> None:
        self.lmps: dict[str, LMPConfig] = {config.name: config for config in lmps}
        if not self.lmps:
            raise ValueError('an Engine needs at least one LMP')
        self.client = client
        self.api = dict(api or {})
        # The node's call that rebuilds the twin for a new rehearsal (cap_lmp.rehearsal): the engine's, not the
        # program's, so it is kept out of the program's scope.
        self._restart_rehearsal = self.api.pop(RESTART_REHEARSAL, None)
        self.sandbox = Sandbox(limits)
        self.default_lmp = default_lmp or next(iter(self.lmps))
        self.fgen_lmp = fgen_lmp if fgen_lmp in self.lmps else None
        self.max_function_depth = max_function_depth
        self.max_generated_functions = max_generated_functions
        self.model_time_limit_s = model_time_limit_s
        self.regenerations = regenerations
        self.regeneration_temperature = regeneration_temperature
        # Execution feedback: how often a program that failed while running (a robot call's error, a Python error)
        # is followed by a new one the model writes knowing what happened (see _execute_with_feedback). 0: the paper's
        # protocol, one program per command.
        self.feedback_rounds = max(0, int(feedback_rounds))
        self._done_actions: list[str] = []  # the robot actions of the running command that completed
        self._feedback_note = ''  # how feedback rounds ended a failed command, for its message
        # The functions that act on the world (move the robot, speak): a plan-only run records their calls.
        self.plan_functions = tuple(name for name in plan_functions if name in self.api)
        self.approval: ApprovalGate | None = None  # set: every command waits for it after a plan-only run
        # With approval set: the plan run is a rehearsal on a twin (cap_lmp.rehearsal): the acting calls are made
        # too (the node routes them to the twin), not only recorded.
        self.rehearse = False
        self._kept_answers: dict[tuple[Any, ...], PreparedCode] | None = None  # nested LMPs' code of a planned command
        self._approved_run = False  # the approved program runs: no new code may be asked for
        self._listeners: list[Callable[[EngineEvent], None]] = []
        self._cancel = threading.Event()
        self._run_lock = threading.Lock()
        self._ids = itertools.count(1)
        self._command_id = 0
        self._stats = _RunStats()
        self.reset()

    # -- session ---------------------------------------------------------------------------------------------
    def reset(self) -> None:
        """Start a new session: forget variables, generated functions and prompt history of earlier commands.

        Waits for a running command to finish (call cancel() first to end it sooner). Rebinds `self.api`.
        """
        with self._run_lock:
            self._reset_scope()

    def _reset_scope(self) -> None:
        names: dict[str, Any] = dict(self.api)
        for config in self.lmps.values():
            if config.callable_from_code:
                names[config.name] = self._lmp_caller(config.name)
        self.scope = self.sandbox.new_scope(names)
        # The robot API, the LMPs, np and the Shapely names are put back before every command: a program that
        # shadows one (`put_first_on_second = lambda a, b: ...`) changes it for its own command only.
        fixed = set(names) | {'np'} | set(self.sandbox.shapely_names)
        self._fixed_names = {name: self.scope[name] for name in fixed}
        self.sandbox.reset_memory_baseline()  # variables the session keeps count against the memory limit
        self.histories: dict[str, list[str]] = {name: [] for name in self.lmps}
        self.functions: dict[str, str] = {}

    def _lmp_caller(self, name: str) -> Callable[..., Any]:
        def call_lmp(query: str, context: str = '', **variables: Any) -> Any:
            return self.call_lmp(name, query, context, **variables)
        return call_lmp

    def add_listener(self, listener: Callable[[EngineEvent], None]) -> None:
        """Receive an EngineEvent for every stage of every command (called on the running thread)."""
        self._listeners.append(listener)

    def cancel(self) -> None:
        """Stop the running command at its next checkpoint (thread-safe; no effect when idle)."""
        self._cancel.set()

    def close(self) -> None:
        """Nothing to release in this process (IsolatedEngine ends its sandbox process here)."""

    def _emit(self, stage: str, lmp: str, code: str = '', message: str = '') -> None:
        event = EngineEvent(self._command_id, stage, lmp, code, message)
        for listener in self._listeners:
            try:
                listener(event)
            except Exception:  # a broken listener must not break the command
                _log.exception('engine event listener failed')

    # -- prompting -------------------------------------------------------------------------------------------
    def build_prompt(self, config: LMPConfig, query: str, context: str = '', feedback: str = '') -> str:
        """The prompt, the session's earlier commands, `feedback` (what an earlier program of this command did:
        text for the model only, never run), the context line and the query."""
        parts = [config.prompt.rstrip('\n')]
        if config.maintain_session:
            parts.extend(self.histories[config.name])
        if feedback:
            parts.append(feedback)
        if context:
            parts.append(context)
        parts.append(f'{config.query_prefix}{query}{config.query_suffix}')
        if config.answer_continues_query:
            return '\n'.join(part for part in parts if part)
        return '\n'.join(parts) + '\n'

    def _ask(self, config: LMPConfig, query: str, context: str, attempt: int = 0, feedback: str = '') -> str:
        """The model's answer; a later attempt (after an unusable answer) is sampled, with the attempt as seed."""
        self._check_cancel()
        remaining = self.model_time_limit_s - self._stats.model_s
        if remaining <= 0:
            self._model_deadline_passed()
        temperature = config.temperature if attempt == 0 else max(config.temperature, self.regeneration_temperature)
        request = CompletionRequest(lmp=config.name, prompt=self.build_prompt(config, query, context, feedback),
                                    query=query,
                                    context=context, stop=config.stop, max_tokens=config.max_tokens,
                                    temperature=temperature, seed=attempt if attempt else None,
                                    time_budget_s=remaining)
        started = time.monotonic()
        completion: Completion | None = None
        try:
            completion = self.client.complete(request)
        except Exception:
            self._count_model_time(time.monotonic() - started)
            self._check_cancel()
            if self._stats.model_s >= self.model_time_limit_s:
                self._model_deadline_passed()
            raise
        elapsed = time.monotonic() - started
        # A client that measured the model itself (the sandbox process' node, which answers for it) knows better:
        # the round trip around it is the program's time, as it is for the node's clock.
        self._count_model_time(min(elapsed, completion.latency_s) if completion.latency_s > 0 else elapsed)
        self._stats.prompt_tokens += completion.prompt_tokens
        self._stats.completion_tokens += completion.completion_tokens
        self._check_cancel()
        check_program_size(completion.text)
        return completion.text

    def _count_model_time(self, seconds: float) -> None:
        self._stats.model_s += seconds
        self._stats.model_calls += 1
        watchdog = self.sandbox.watchdog
        if watchdog is not None:  # a nested LMP: the model's time does not count against the program
            watchdog.exclude(seconds)

    def _model_deadline_passed(self) -> None:
        message = (f'the model deadline of {self.model_time_limit_s:g} s for one command passed '
                   f'({self._stats.model_calls} model requests took {self._stats.model_s:.1f} s), so the command '
                   'was stopped')
        watchdog = self.sandbox.watchdog
        if watchdog is not None:  # inside a running program: a stop it cannot catch
            watchdog.stop(message, 'model_timeout')
        raise ExecutionStopped(message, 'model_timeout')

    def _check_cancel(self) -> None:
        if self._cancel.is_set():
            raise ExecutionStopped('the program was cancelled', 'cancelled')

    # -- generation ------------------------------------------------------------------------------------------
    def _known_names(self) -> set[str]:
        return set(self.scope) | set(self.scope['__builtins__'])

    @staticmethod
    def _source(config: LMPConfig, code: str, known: set[str]) -> str:
        """The program as the sandbox checks it: the harness's own rules (prepare_source), then the imports of
        names the scope already holds dropped."""
        if config.prepare_source is not None:
            code = config.prepare_source(code)
        return drop_provided_imports(code, known)

    def _prepare(self, config: LMPConfig, code: str, context: str = '', variables: Iterable[str] = (),
                 query: str = '') -> PreparedCode:
        known = self._known_names()
        code = self._source(config, code, known)
        tree = self.sandbox.check(code)
        self._check_names(config, tree, code, known | self._context_names(config, context) | set(variables))
        if config.check_answer is not None:
            reason = config.check_answer(tree, query, context)
            if reason:
                raise UnusableAnswer(f'the generated code was not run: {reason}')
        functions: list[tuple[str, CompiledProgram]] = []
        if config.generate_functions:
            self._define_missing(tree, known, (), functions)
        else:
            missing = undefined_calls(tree, known)
            if missing:
                raise GenerationError(f'the code calls {missing[0].name}(), which is not defined')
        prepared = PreparedCode(self.sandbox.compile_checked(tree, code, config.name), tuple(functions))
        check_program_size(prepared.full_code(), 'the program with the functions generated for it')
        return prepared

    @staticmethod
    def _context_names(config: LMPConfig, context: str) -> set[str]:
        """What the context line binds before the code runs (`objects`), if it runs."""
        if not context or not config.execute_context:
            return set()
        try:
            return bound_names(ast.parse(context))
        except (SyntaxError, ValueError, RecursionError, MemoryError):
            return set()  # the context's own run reports it

    def _check_names(self, config: LMPConfig, tree: Any, code: str, known: set[str]) -> None:
        """A name the program reads and nothing binds is a NameError to come: refuse it before anything runs."""
        unbound = unbound_names(tree, known)
        if unbound:
            first = unbound[0]
            lines = code.splitlines()
            text = lines[first.line - 1].strip() if 0 < first.line <= len(lines) else None
            raise UndefinedName(first.name, first.line, text, self._origin_text(config.name))

    def _define_missing(self, tree: Any, known: set[str], chain: tuple[str, ...],
                        out: list[tuple[str, CompiledProgram]]) -> None:
        for missing in undefined_calls(tree, known):
            if missing.name in chain or any(name == missing.name for name, _ in out):
                continue  # being generated above us (recursion between functions) or already done
            if self.fgen_lmp is None:
                raise GenerationError(f'the code calls {missing.name}(), which is not defined')
            if len(chain) >= self.max_function_depth:
                path = ' -> '.join(chain + (missing.name,))
                raise GenerationError(f'function generation went deeper than {self.max_function_depth} levels '
                                      f'({path}); giving up')
            if len(self._stats.generated) >= self.max_generated_functions:
                raise GenerationError(f'the code needed more than {self.max_generated_functions} new functions; '
                                      'giving up')
            fgen = self.lmps[self.fgen_lmp]
            query = f'define function: {missing.query_signature(fgen.signature_style)}'
            self._emit(GENERATING, self.fgen_lmp, message=query)
            source = self._ask(fgen, query, '')
            self._stats.generated.append(missing.name)
            source = self._source(fgen, source, known)
            try:
                function_tree = self.sandbox.check(source)
            except CodeRejected as error:
                raise CodeRejected(f'the generated function {missing.name}() was refused: {error}', error.line,
                                   error.source_line) from None
            defined = top_level_functions(function_tree)
            if missing.name not in defined:
                found = ', '.join(f'{name}()' for name in defined) or 'no function'
                raise UnusableAnswer(f'asked the model to define {missing.name}(), but its code defines {found}')
            self._define_missing(function_tree, known | set(defined), chain + (missing.name,), out)
            out.append((missing.name, self.sandbox.compile_checked(function_tree, source, f'function {missing.name}')))

    def generate(self, lmp: str, query: str, context: str = '', variables: Iterable[str] = (),
                 feedback: str = '', first_attempt: int = 0) -> PreparedCode:
        """Ask the LMP's model for code and prepare it (checked, missing functions generated); nothing runs.

        An answer that cannot run at all (a syntax error, a name nothing defines, a generated function that does
        not define itself) is asked for again up to `regenerations` times, sampled at `regeneration_temperature`
        (a small model at temperature 0 gives the same answer again); a refusal of the sandbox is final.
        `variables`: names the caller sets in the program's scope before it runs; `feedback`: see build_prompt;
        `first_attempt` > 0 samples from the first answer on (as a later attempt is sampled).
        """
        config = self.lmps[lmp]
        variables = tuple(variables)
        attempt = first_attempt
        while True:
            self._emit(GENERATING, lmp, message=query)
            generated = len(self._stats.generated)
            code = self._ask(config, query, context, attempt, feedback)
            if config.answer_continues_query:
                code = continued_program(f'{config.query_prefix}{query}{config.query_suffix}', code)
                check_program_size(code, 'the query with the answer')
            try:
                return self._prepare(config, code, context, variables, query)
            except (CodeRejected, GenerationError) as error:
                if attempt >= self.regenerations or not _worth_asking_again(error):
                    raise
                del self._stats.generated[generated:]  # the functions of the unusable answer are not kept
                attempt += 1
                self._emit(GENERATING, lmp, message=f'{query} (asking again, the answer could not run: {error})')

    # -- execution -------------------------------------------------------------------------------------------
    def _execute(self, config: LMPConfig, prepared: PreparedCode, query: str, context: str,
                 variables: Mapping[str, Any] | None = None) -> Any:
        for name, program in prepared.functions:
            self.sandbox.execute(program, self.scope, self._cancel)
            self.functions[name] = program.source
        scope = self.scope if config.maintain_session else dict(self.scope)
        scope.update(variables or {})
        if context and config.execute_context:
            literal = literal_assignment(context)
            if literal is not None:  # the usual `objects = [...]`: no code to run
                scope[literal[0]] = literal[1]
            else:
                self.sandbox.execute(self.sandbox.compile(context, f'{config.name} context'), scope, self._cancel)
        self.sandbox.execute(prepared.main, scope, self._cancel)
        if config.maintain_session:
            use_query = f'{config.query_prefix}{query}{config.query_suffix}'
            entry = '\n'.join(part for part in (context, use_query, prepared.main.source.rstrip()) if part)
            self.histories[config.name].append(entry)
        if config.has_return:
            if config.return_val_name in scope:
                return scope[config.return_val_name]
            # Small models often end with `block_names = [...]` instead of `ret_val = ...`: that value is meant.
            last = last_assigned_name(prepared.main.source)
            if last is not None and last in scope:
                return scope[last]
            raise GenerationError(f'the {config.name} program did not set {config.return_val_name}')
        return None

    def call_lmp(self, lmp: str, query: str, context: str = '', **variables: Any) -> Any:
        """Run an LMP from generated code (or directly): generate, prepare, execute; return its value.

        `variables` are set in the program's scope first (e.g. transform_shape_pts(..., shape_pts=pts)).
        """
        config = self.lmps[lmp]
        # Generated code passes whatever it likes: only text travels as a query (anything else once took the
        # sandbox process's messages apart and cost the session).
        for what, value in (('description', query), ('context', context)):
            if not isinstance(value, str):
                raise TypeError(f'{lmp}() takes its {what} as text, not {type(value).__name__}')
        bad = [name for name in variables if name.startswith('_')]
        if bad:
            raise ValueError(f'variables passed to {lmp} may not start with "_": {", ".join(bad)}')
        key = (lmp, query, context, tuple(sorted(variables)))
        kept = self._kept_answers
        prepared = kept.get(key) if kept is not None else None  # planned: the run executes what was approved
        if prepared is None and self._approved_run:
            self._stop_unapproved(f'the program asked {lmp} for code with a query the approved plan did not ask '
                                  f'({query[:200]!r}); new code nobody reviewed was not asked for')
        if prepared is None:
            watchdog = self.sandbox.watchdog
            if watchdog is not None:  # called from a running program: our own host work needs no tracing
                with watchdog.suspended():
                    prepared = self.generate(lmp, query, context, variables)
                watchdog.check()
            else:
                prepared = self.generate(lmp, query, context, variables)
            if kept is not None:
                kept[key] = prepared
        self._emit(CODE, lmp, code=prepared.full_code())
        return self._execute(config, prepared, query, context, variables)

    def context_for(self, config: LMPConfig) -> str:
        """The context line of a top-level run, e.g. `objects = ['blue block', 'red bowl']`."""
        if not config.context_var or not config.context_api:
            return ''
        value = self.api[config.context_api]()
        return f'{config.context_var} = {list(value) if isinstance(value, tuple) else value!r}'

    def run(self, command: str, lmp: str | None = None, context: str | None = None) -> CommandResult:
        """Run one command end to end. Never raises for problems of the generated code: see CommandResult."""
        with self._run_lock:
            self._cancel.clear()
            self._command_id = next(self._ids)
            self._stats = _RunStats()
            name = lmp or self.default_lmp
            config = self.lmps[name]
            result = CommandResult(command=command, command_id=self._command_id, success=False)
            started = time.monotonic()
            prepared: PreparedCode | None = None
            execute_started = started
            planning = False
            self._kept_answers = {} if self.approval is not None else None
            kept_scope, kept_functions = dict(self.scope), dict(self.functions)  # names only, for a memory stop
            try:
                if context is None:
                    context = self.context_for(config)
                prepared = self.generate(name, command, context)
                result.code = prepared.full_code()
                self._emit(CODE, name, code=result.code)
                if self.approval is not None:
                    planning = True
                    prepared, plan = self._plan_with_feedback(config, prepared, command, context, result)
                    shown = self._code_for_approval(prepared.full_code())  # what runs, not earlier rounds
                    planning = False
                    self.approval(shown, plan)
                    self._check_cancel()
                    self._approved_run = True
                self._emit(EXECUTING, name, code=result.code)
                execute_started = time.monotonic()
                self._done_actions, self._feedback_note = [], ''
                with self.sandbox.watching(self._cancel) as watchdog:  # one time limit for the command's programs
                    self._execute_with_feedback(config, prepared, command, context, result, watchdog)
                result.success = True
                result.outcome = Outcome.DONE
            except Exception as error:  # everything a generated program can cause ends here, reported
                self._report_failure(result, error)
                result.message += self._feedback_note
                if planning and self.rehearse and result.outcome is not Outcome.CANCELLED:
                    result.outcome = Outcome.REFUSED  # what the twin saw is the reason nothing moved
                    if not isinstance(error, NotApproved):
                        result.message = (f'the rehearsal on the twin failed, so the robot did not move: '
                                          f'{result.message}')
                elif planning and not isinstance(error, NotApproved):
                    result.message = f'the plan-only run failed, so nothing moved: {result.message}'
                del error  # its traceback holds the program's frames and their memory
            finally:
                self._kept_answers = None
                self._approved_run = False
            if result.stop_reason == 'memory' or result.error_type == 'MemoryError':
                result.message += self._recover_memory(kept_scope, kept_functions)
            del kept_scope, kept_functions
            finished = time.monotonic()
            stats = self._stats
            result.model_calls = stats.model_calls
            result.prompt_tokens = stats.prompt_tokens
            result.completion_tokens = stats.completion_tokens
            result.generated_functions = list(stats.generated)
            total = finished - started
            result.timings = {'total_s': total, 'model_s': stats.model_s,
                              'execute_s': finished - execute_started if prepared else 0.0,
                              'overhead_s': total - stats.model_s}
            if result.success:
                self._emit(DONE, name, code=result.code, message='done')
            else:
                self._emit(ERROR, name, code=result.code, message=result.message)
            return result

    def _execute_with_feedback(self, config: LMPConfig, prepared: PreparedCode, command: str, context: str,
                               result: CommandResult, watchdog: Any) -> None:
        """Run the command's program; with `feedback_rounds`, a program that fails while running is followed by a
        new one, written by the model from what happened (see feedback.py), which continues from the world as it
        is now. Stops, cancels, limits, the sandbox's refusals and approved runs are final: only a robot call's
        error or a Python error is fed back. Each round is on the events (GENERATING, CODE, EXECUTING)."""
        rounds = 0
        feeding_back = self.feedback_rounds > 0 and self.approval is None  # an approved program is all that runs
        while True:
            self.scope.update(self._fixed_names)
            if feeding_back:
                self.scope.update(action_recorders(self._fixed_names, self.plan_functions, self._done_actions))
            try:
                self._execute(config, prepared, command, context)
                return
            except Exception as error:
                if not feeding_back or not worth_feedback(error):
                    raise
                if rounds >= self.feedback_rounds:
                    self._feedback_note = f' (the program of feedback round {rounds} of {self.feedback_rounds})'
                    raise
                failure = error
                line, source_line, _origin = self._locate(error)
                what = failure_lines(error, line, source_line, self._done_actions)
            rounds += 1
            stopped = what[0].removeprefix('# ')  # where and why, in words
            self._emit(GENERATING, config.name, message=f'{command} (round {rounds} of {self.feedback_rounds} '
                                                        f'after the program failed: {stopped})')
            feedback = feedback_block(config.query_prefix, config.query_suffix, context, command,
                                      prepared.main.source, what)
            context = self.context_for(config)  # the scene as it is now
            query = continue_query(command)
            failed_source = prepared.main.source.strip()
            try:
                with watchdog.suspended():  # the model's time is not the program's
                    prepared = self.generate(config.name, query, context, feedback=feedback)
                    if prepared.main.source.strip() == failed_source:
                        # the same program again would fail the same way: one answer sampled instead (at
                        # temperature 0 a small model often repeats itself whatever it was told)
                        self._emit(GENERATING, config.name, message=f'{query} (the model wrote the program that '
                                                                    'failed again; asking once more, sampled)')
                        prepared = self.generate(config.name, query, context, feedback=feedback, first_attempt=1)
                if not _has_statements(prepared.main.source):
                    raise GenerationError('it wrote no code')  # "nothing left to do" after a failure is not so
            except ExecutionStopped:
                raise
            except Exception as again:  # no program to continue with: the command failed as it failed
                self._feedback_note = (f'; asked to finish the command after that, the model gave no program that '
                                       f'could run ({bounded_exception_text(again)})')
                raise failure from None
            finally:
                del failure
            watchdog.check()
            result.code = f'{result.code}\n\n# round {rounds}, after: {stopped}\n{prepared.full_code()}'
            self._emit(CODE, config.name, code=prepared.full_code())
            self._emit(EXECUTING, config.name, code=result.code)

    def _plan_with_feedback(self, config: LMPConfig, prepared: PreparedCode, command: str, context: str,
                            result: CommandResult) -> tuple[PreparedCode, list[PlannedCall]]:
        """The plan phase; when it is a rehearsal on a twin and `feedback_rounds` allows, a program that failed
        there (an error, harm the twin saw) is followed by a new one, written by the model from what the twin saw,
        and rehearsed on a twin built again: the robot has not moved, so the new program does the whole command.
        What the twin saw is the failure a closed loop learns from (see _execute_with_feedback for the real run's)."""
        rounds = 0
        while True:
            try:
                return prepared, self._plan(config, prepared, command, context)
            except Exception as error:
                if not (self.rehearse and self._restart_rehearsal is not None and rounds < self.feedback_rounds
                        and worth_feedback(error)):
                    raise
                line, source_line, _origin = self._locate(error)
                what = failure_lines(error, line, source_line, [])
                what[0] = what[0].replace('# the program above stopped', '# rehearsed on a twin, the program above '
                                                                        'stopped', 1)
            rounds += 1
            stopped = what[0].removeprefix('# ')
            self._emit(GENERATING, config.name, message=f'{command} (rehearsal round {rounds} of '
                                                        f'{self.feedback_rounds}: {stopped})')
            feedback = feedback_block(config.query_prefix, config.query_suffix, context, command,
                                      prepared.main.source, what)
            self._restart_rehearsal()  # the twin as the world is: nothing of the failed program stays on it
            failed_source = prepared.main.source.strip()
            prepared = self.generate(config.name, continue_query(command), context, feedback=feedback)
            if prepared.main.source.strip() == failed_source:  # as in _execute_with_feedback: sampled once
                prepared = self.generate(config.name, continue_query(command), context, feedback=feedback,
                                         first_attempt=1)
            result.code = f'{result.code}\n\n# rehearsal round {rounds}, after: {stopped}\n{prepared.full_code()}'
            self._emit(CODE, config.name, code=prepared.full_code())

    def _plan(self, config: LMPConfig, prepared: PreparedCode, query: str, context: str) -> list[PlannedCall]:
        """Run the program in plan-only mode (see approval.py) and return the calls it would make of the
        plan_functions. The session is left as it was: the run works on copies of its scope (every value copied,
        approval.session_copy), histories and functions (nested LMPs included), and a function defined for it, or
        by earlier commands, sees the recorders too."""
        plan: list[PlannedCall] = []
        kept = self.scope, self.histories, self.functions
        scope = session_copy(self.scope, self._fixed_names.values())
        scope.update(self._fixed_names)
        scope.update(recorders(self.plan_functions, plan, self.api if self.rehearse else None))
        self.scope = scope
        self.histories = {name: list(history) for name, history in self.histories.items()}
        self.functions = dict(self.functions)
        try:
            with self.sandbox.watching(self._cancel):
                self._execute(config, prepared, query, context)
        finally:
            self.scope, self.histories, self.functions = kept
        return plan

    def _code_for_approval(self, code: str) -> str:
        """The program with the code of every nested LMP its plan-only run asked for: all the code that will run."""
        parts = [code.rstrip()]
        for (lmp, query, _context, _variables), prepared in (self._kept_answers or {}).items():
            parts.append(f'# {lmp}({query[:200]!r}):\n{prepared.full_code()}')
        shown = '\n\n'.join(parts)
        if len(shown) > MAX_CODE_CHARS:
            raise CodeRejected(f'the program and the code of its nested LMPs have {len(shown):,} characters, more than '
                               f'the {MAX_CODE_CHARS:,} an approval can show; it was not run')
        return shown

    def _stop_unapproved(self, message: str) -> None:
        """End the approved run at a step the approval did not cover (ExecutionStopped, reason 'unapproved')."""
        watchdog = self.sandbox.watchdog
        if watchdog is not None:  # inside a running program: a stop it cannot catch
            watchdog.stop(message, 'unapproved')
        raise ExecutionStopped(message, 'unapproved')

    def _report_failure(self, result: CommandResult, error: Exception) -> None:
        """Describe the failure; a message that cannot be built (a program's exception can carry anything) is
        replaced by its type, and the session goes on."""
        result.outcome = outcome_of(error)
        try:
            self._describe_failure(result, error)
        except Exception:  # a MemoryError, an int too long for str(), ...: the report itself must not fail
            result.error_type = result.error_type or type(error).__name__
            result.message = f'{type(error).__name__} (its message could not be shown)'

    def _recover_memory(self, kept_scope: dict[str, Any], kept_functions: dict[str, str]) -> str:
        """After a memory stop: drop what the command bound, reset the session if it still holds too much."""
        self.scope.clear()
        self.scope.update(kept_scope)
        self.functions = kept_functions
        _return_freed_memory()
        if self.sandbox.memory_growth() <= self.sandbox.limits.max_memory_growth_bytes // 2:
            return '; the variables this command set were dropped, the rest of the session is kept'
        self._reset_scope()
        _return_freed_memory()
        self.sandbox.reset_memory_baseline()
        return ('; the session still held too much memory, so it was reset (earlier variables and generated '
                'functions are forgotten)')

    def _describe_failure(self, result: CommandResult, error: Exception) -> None:
        line, source_line, origin = self._locate(error)
        if isinstance(error, UndefinedName):
            result.error_type = 'NameError'
            line, source_line = error.line, error.source_line
            result.message = str(error)
        elif isinstance(error, CodeRejected):
            result.error_type = 'SyntaxError' if _is_syntax_error(error) else 'CodeRejected'
            line, source_line = error.line, error.source_line
            result.message = f'the generated code was refused: {error}'
        elif isinstance(error, CapLLMError):
            result.error_type = 'GenerationError' if isinstance(error, GenerationError) else type(error).__name__
            result.message = str(error)
            if isinstance(error, ExecutionStopped):
                result.stop_reason = error.reason
        elif isinstance(error, MemoryError):
            result.error_type = 'MemoryError'
            result.message = 'MemoryError: the program ran out of memory'
        else:
            result.error_type = type(error).__name__
            result.message = f'{type(error).__name__}: {bounded_exception_text(error)}'
        if line is not None and not isinstance(error, CodeRejected) and source_line:
            result.message += f' (line {line} of {origin}: `{source_line}`)'
        result.error_line = line
        result.error_source = source_line

    def _origin_text(self, origin: str) -> str:
        """How a message names a program: the top-level one, an LMP's, or a generated function."""
        if origin == self.default_lmp:
            return 'the generated program'
        if origin in self.lmps:
            return f'the generated {origin} program'
        return f'the generated {origin}'

    def error_text(self, error: BaseException) -> str:
        """'Type: message (line N of <program>: `source`)' for an exception raised by generated code that the host
        called (a controller function's tick); built with bounded work."""
        text = f'{type(error).__name__}: {bounded_exception_text(error)}'
        line, source_line, origin = self._locate(error)
        if line is not None and source_line:
            text += f' (line {line} of {origin}: `{source_line}`)'
        return text

    def _locate(self, error: BaseException) -> tuple[int | None, str | None, str]:
        """Line of generated code where the error arose: the innermost frame that belongs to a generated program."""
        found: tuple[int | None, str | None, str] = (None, None, '')
        for frame, line in traceback.walk_tb(error.__traceback__):
            filename = frame.f_code.co_filename
            if not filename.startswith(SANDBOX_FILE_PREFIX):
                continue
            program = self.sandbox.program_for(filename)
            if program is None:
                continue
            lines = program.source.splitlines()
            text = lines[line - 1].strip() if 0 < line <= len(lines) else None
            origin = self._origin_text(program.origin)
            found = (line, text, origin)
        return found


__all__ = ['CODE', 'DONE', 'ERROR', 'EXECUTING', 'GENERATING', 'CommandResult', 'Engine', 'EngineEvent',
           'LMPConfig']
