"""The isolated door: a user's agent in a process of its own (``evaluate --isolate``, ``isolate=True``).

An agent that runs in the evaluating process shares its memory with the environment: nothing
hands it the environment, yet ``sys._getframe()``, ``gc.get_objects()`` or a monkeypatch reach
it (its hourly table, the episode's price shocks, its state). An :class:`IsolatedAgent` builds
the agent in a fresh Python process started with the ``spawn`` method (nothing of the evaluating
process's memory is inherited) and talks to it over a pipe:

- the evaluating process sends copies of what the in-process door passes (the observation, the
  step ``info``, the public episode context, the run seed), pickled: that direction is trusted;
- the agent's process answers with data only (:mod:`.wire`: JSON of numbers, strings, lists,
  dicts and numeric numpy arrays, never a pickle), so nothing it returns can run code here.

Each step's observation and action, numeric arrays, travel as raw array frames rather than a
pickle and JSON: the round trip is then the pipe's own cost plus the agent's time.

Hooks whose result the runner ignores (``begin_run``, ``begin_episode``, ``observe``) are sent
without waiting for an answer; an error they raise is reported with the next call that waits
(``act``, ``end_episode``, ``close``). The agent's actions reach the environment with their exact
type and bits, so an honest agent's records are the in-process door's, bit for bit.

This is a process boundary, not a sandbox: the agent's process runs as the same user, with the
same files and network (see docs/evaluate_your_agent.md#isolated-agents).
"""

from __future__ import annotations

import contextlib
import multiprocessing
import pickle
import signal
import threading
import weakref
from dataclasses import dataclass, replace
from typing import Any

from ..records_schema import AGENT_COLUMN_PREFIX
from .adapters import AgentError, AgentFailure, UserAgent, as_agent
from .request import AgentContext, AgentRequest, agent_request
from .specs import AgentSpec, AgentSpecError
from .validation import AGENT_EXTRAS_KEY
from .wire import WireError, decode, encode, frameable, is_frame, pack_array, unpack_array

#: Spec kinds the isolated door builds in the agent's process (HTTP agents are in another process already).
ISOLATED_KINDS = ("python", "file", "plugin", "sb3")
#: Hooks sent without waiting for an answer (the runner ignores what they return).
ONE_WAY = ("begin_run", "begin_episode", "observe")
#: The largest answer read from the agent's process (an end_episode dict, a snapshot).
MAX_ANSWER_BYTES = 64 * 2**20
_JOIN_S = 10.0


class IsolatedAgentError(AgentError):
    """An isolated agent that failed: a hook raised, its process ended, or an answer was not data."""

    #: The message is one line naming the agent and its position already: the door passes it on as it is.
    names_its_agent = True


@dataclass
class _Position:
    run_seed: int | None = None
    episode: int | None = None
    step: int = 0


def _serve(conn: Any, payload: tuple) -> None:
    """The agent's process: build the agent, then answer requests until ``close`` or end of input."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the evaluating process's to handle

    def answer(kind: str, *body: Any) -> None:
        if kind == "ok" and body[0] == "act" and frameable(body[1]):
            conn.send_bytes(pack_array("act", body[1]))  # the hot path: the action as raw bytes
            return
        try:
            conn.send_bytes(encode([kind, *body]))
        except WireError as error:
            conn.send_bytes(encode(["err", body[0], f"returned {error}", False]))

    try:
        agent = _build(payload)
    except BaseException as error:  # whatever the agent's import or constructor raises, SystemExit included
        conn.send_bytes(encode(["err", "build", *_line(error)]))
        return
    hooks = [h for h in ("begin_run", "begin_episode", "observe", "end_episode", "close") if hasattr(agent, h)]
    answer(
        "ready", {"name": agent.name, "action_mode": agent.action_mode, "stateless": agent.stateless, "hooks": hooks}
    )
    pending: list | None = None  # the first error of a one-way hook, reported at the next request
    while True:
        try:
            op, args, kwargs = _request_of(conn.recv_bytes())
        except EOFError:  # the evaluating process closed the pipe (or ended)
            return
        if op in ONE_WAY:
            if pending is None:
                try:
                    getattr(agent, op)(*args, **kwargs)
                except BaseException as error:
                    pending = [op, *_line(error)]
            continue
        if pending is not None:
            conn.send_bytes(encode(["err", *pending]))
            pending = None
            continue
        try:
            if op == "snapshot":
                result: Any = pickle.dumps(agent.inner)  # opaque bytes for a twin's process
            elif op == "close":
                result = agent.close() if hasattr(agent, "close") else None
            elif op == "act":
                result = agent.act_unchecked(*args)
                # A numeric array goes back as it is (the evaluating process's door checks it, with the
                # same words); anything else is checked here, so that what the wire cannot carry is
                # refused as the in-process door refuses it.
                problem = None if frameable(result) else agent.action_problem(result)
                if problem is not None:
                    raise AgentFailure(agent.name, problem)
            else:
                result = getattr(agent, op)(*args, **kwargs)
        except BaseException as error:
            answer("err", op, *_line(error))
        else:
            answer("ok", op, None if op in ("close",) else result)
        if op == "close":
            return


def _request_of(data: bytes) -> tuple[str, tuple, dict]:
    """A request from the evaluating process (trusted): an array frame for ``act``, else a pickle."""
    if is_frame(data):
        op, observation = unpack_array(data)
        return op, (observation,), {}
    return pickle.loads(data)


def _pack_request(op: str, args: tuple, kwargs: dict) -> bytes:
    if op == "act" and len(args) == 1 and not kwargs and frameable(args[0]):
        return pack_array(op, args[0])
    return pickle.dumps((op, args, kwargs), protocol=pickle.HIGHEST_PROTOCOL)


def _build(payload: tuple) -> UserAgent:
    kind = payload[0]
    if kind == "request":
        from .kinds import build_in_process

        _, request, context = payload
        return as_agent(build_in_process(request, context))
    _, data, name = payload
    # Runs only in the agent's own process, on bytes the evaluator pickled from an object its
    # caller passed in Python (or this agent's own snapshot): never on a file a run names, and the
    # evaluating process itself never unpickles what an agent sends (docs/security.md).
    return as_agent(pickle.loads(data), name=name)


def _line(error: BaseException) -> tuple[str, bool | str]:
    """The error in one line, and whose words it is: ``"failure"``, the door's refusal of what the
    agent returned (the evaluating process raises it as its own door would, so the run adds the
    position); True, the benchmark's own message, which names the agent; False, the agent's."""
    user_error = getattr(error, "user_error", None)
    if isinstance(error, AgentFailure):
        if user_error is not None:
            return _line(user_error)  # the agent's own exception, which this process's door caught
        return error.problem, "failure"
    if isinstance(error, AgentError):
        return str(error), True  # a wrong action's shape, a spec that cannot be built: as in-process
    text = " ".join(str(error).split())
    return (f"raised {type(error).__name__}: {text}" if text else f"raised {type(error).__name__}"), False


def _shutdown(conn: Any, process: Any) -> None:
    """Close the pipe (the agent's process ends at end of input) and reap the process."""
    conn.close()
    process.join(_JOIN_S)
    if process.is_alive():
        process.terminate()
        process.join(_JOIN_S)


class IsolatedAgent:
    """A user's agent running in a process of its own (see the module docstring).

    Build one with :meth:`from_request` (:meth:`from_spec`) or :meth:`from_object`. ``name``, ``action_mode`` and
    ``stateless`` are the agent's own; ``observe`` and ``end_episode`` exist when the agent has
    them. ``isolated = True`` labels its rows ``isolated``
    (:func:`~solarchain_eval.agents.base.access_label`).
    """

    isolated = True

    def __init__(self, payload: tuple, label: str) -> None:
        self._payload = payload
        self._label = label
        self._lock = threading.Lock()
        self._local = threading.local()
        self._used = False
        context = multiprocessing.get_context("spawn")  # a fresh interpreter: no copy of this memory
        self._conn, child = context.Pipe(duplex=True)
        process = context.Process(target=_serve, args=(child, payload), name=f"solarchain-agent-{label}", daemon=True)
        try:
            process.start()
        finally:
            child.close()
        self._process = process
        self._finalizer = weakref.finalize(self, _shutdown, self._conn, process)
        kind, *body = self._receive("start")
        if kind != "ready" or len(body) != 1 or not isinstance(body[0], dict):
            self._finalizer()
            raise self._error(body if kind == "err" else ["start", f"answered {kind!r}", False])
        ready = body[0]
        if not (isinstance(ready.get("name"), str) and isinstance(ready.get("hooks"), list)):
            self._finalizer()
            raise self._error(["start", "answered without a name and hooks", False])
        self.name, self.action_mode = ready["name"], str(ready.get("action_mode"))
        self.stateless = ready.get("stateless") is True
        self._hooks = frozenset(str(h) for h in ready["hooks"])
        if "observe" in self._hooks:
            self.observe = self._observe
        if "end_episode" in self._hooks:
            self.end_episode = self._end_episode

    @classmethod
    def from_spec(
        cls,
        spec: AgentSpec,
        config: Any,
        agent_args: dict[str | None, dict[str, Any]] | None = None,
        vecnormalize: dict | None = None,
    ) -> UserAgent:
        """The agent of a ``python``, ``file``, ``plugin`` or ``sb3`` spec, built in its own process
        (:meth:`from_request` with the ``--agent-arg`` and ``--vecnormalize`` mappings by agent name)."""
        request = agent_request(spec, builtins=(), agent_args=agent_args, vecnormalize=vecnormalize)
        return cls.from_request(request, AgentContext(config))

    @classmethod
    def from_request(cls, request: AgentRequest, context: AgentContext) -> UserAgent:
        """The agent of a ``python``, ``file``, ``plugin`` or ``sb3`` spec request, built in its own process
        as :func:`~.kinds.build_in_process` builds it in this one."""
        spec = request.spec
        if spec is None:
            raise ValueError("from_request builds an agent from its spec; isolate an agent object with from_object")
        if spec.kind not in ISOLATED_KINDS:
            raise AgentSpecError(f"agent {spec.label!r} ({spec.text}): a {spec.kind} agent is not run isolated")
        agent = cls(("request", replace(request, isolate=False), context), spec.label)
        return as_agent(agent, name=agent.name)

    @classmethod
    def from_object(cls, agent: Any) -> UserAgent:
        """A copy of an agent object (or function, or SB3 model) running in its own process.

        Raises
        ------
        AgentSpecError
            The agent cannot be pickled (a lambda, a local class, an open connection).
        """
        shell = as_agent(agent)
        try:
            data = pickle.dumps(shell.inner)
        except Exception as error:  # PicklingError, TypeError, AttributeError: whatever the object raises
            raise AgentSpecError(
                f"agent {shell.name!r}: an isolated agent is copied into its own process, which needs it pickled "
                f"({type(error).__name__}: {' '.join(str(error).split())}); define it at module level or pass its "
                "spec ('path/to/file.py:Class')"
            ) from None
        isolated = cls(("object", data, shell.name), shell.name)
        return as_agent(isolated, name=isolated.name)

    # --- the hooks the runner calls --------------------------------------------------------------
    @property
    def _position(self) -> _Position:
        position = getattr(self._local, "position", None)
        if position is None:
            position = self._local.position = _Position()
        return position

    def begin_run(self, run_seed: int) -> None:
        self._position.run_seed = int(run_seed)
        if "begin_run" in self._hooks:
            self._send("begin_run", run_seed)

    def begin_episode(self, **context: Any) -> None:
        position = self._position
        position.episode, position.step = context.get("episode"), 0
        if "begin_episode" in self._hooks:
            self._send("begin_episode", **context)

    def act(self, observation: Any) -> Any:
        self._position.step += 1
        return self._request("act", observation)

    def _observe(self, info: dict) -> None:
        self._send("observe", info)

    def _end_episode(self) -> Any:
        # The child's door already checked and namespaced the agent's dict ({"agent_columns":
        # {"agent_k": v}}); hand this process's door the agent's own keys, which it checks again.
        returned = self._request("end_episode")
        columns = returned.get(AGENT_EXTRAS_KEY, {}) if isinstance(returned, dict) else returned
        if not isinstance(columns, dict):
            return columns  # refused here with the door's own line
        return {key.removeprefix(AGENT_COLUMN_PREFIX): value for key, value in columns.items()} or None

    def close(self) -> None:
        """Call the agent's ``close`` (when it has one) and end its process."""
        if not self._finalizer.alive:
            return
        try:
            if self._process.is_alive():
                self._request("close")
        finally:
            self._finalizer()

    def __deepcopy__(self, memo: dict) -> IsolatedAgent:
        # A private copy (the runner copies a stateful agent per task) in a process of its own:
        # built from the same payload while this agent is untouched, else from its current state.
        if not self._used:
            twin = IsolatedAgent(self._payload, self._label)
        else:
            name = self.name
            twin = IsolatedAgent(("object", self._request("snapshot"), name), self._label)
        memo[id(self)] = twin
        return twin

    def __repr__(self) -> str:
        return f"IsolatedAgent({self.name!r}, pid {self._process.pid}, {self.action_mode})"

    # --- the pipe --------------------------------------------------------------------------------
    def _send(self, op: str, *args: Any, **kwargs: Any) -> None:
        with self._lock:
            self._used = True
            with contextlib.suppress(OSError):  # the process has ended: its reason comes with the next request
                self._conn.send_bytes(_pack_request(op, args, kwargs))

    def _request(self, op: str, *args: Any, **kwargs: Any) -> Any:
        with self._lock:
            self._used = True
            with contextlib.suppress(OSError):  # the process has ended: _receive says how
                self._conn.send_bytes(_pack_request(op, args, kwargs))
            kind, *body = self._receive(op)
        if kind != "ok" or len(body) != 2:
            raise self._error(body if kind == "err" else [op, f"answered {kind!r}", False])
        return body[1]

    def _receive(self, op: str) -> list:
        try:
            raw = self._conn.recv_bytes(MAX_ANSWER_BYTES)
        except (EOFError, OSError):
            self._process.join(_JOIN_S)
            code = self._process.exitcode
            return ["err", op, f"ended its process (exit code {code}) before answering", False]
        try:
            if is_frame(raw):
                label, action = unpack_array(raw)
                return ["ok", op, action] if label == op == "act" else ["err", op, f"answered a {label!r} frame", False]
            message = decode(raw)
        except WireError as error:
            return ["err", op, f"answered {error}", False]
        if not isinstance(message, list) or not message or not isinstance(message[0], str):
            return ["err", op, "answered something that is not an answer", False]
        return message

    def _error(self, body: list) -> AgentError:
        if len(body) == 3:
            hook, problem, own = str(body[0]), str(body[1]), body[2] is True
            refused = body[2] == "failure"
        else:
            hook, problem, own = "?", f"answered something that is not an answer: {body!r:.200}", False
            refused = False
        name = getattr(self, "name", self._label)
        if refused:  # what the agent returned, refused by the door in its process: as the in-process door says it
            if hook in ("build", "start"):
                return AgentSpecError(f"agent {name!r}: {problem}")
            return AgentFailure(name, problem)
        if hook in ("build", "start"):
            if own:  # the spec's own one-line error (a missing file, an import error), as in-process
                return AgentSpecError(problem)
            hint = ""
            if "exit code" in problem:
                hint = (
                    " (a script that evaluates with isolate=True must do so under if __name__ == '__main__':, "
                    "as multiprocessing's spawn method re-imports the script)"
                )
            elif "Can't get attribute" in problem:
                hint = (
                    " (an agent defined in a notebook or an interactive session is not importable: define it in a file)"
                )
            return AgentSpecError(f"agent {name!r} (isolated): building it {problem}{hint}")
        if own:  # an action of the wrong shape: the message the in-process door gives
            return IsolatedAgentError(problem)
        position = self._position
        where = ""
        if position.episode is not None:
            where = f" (run seed {position.run_seed}, episode {position.episode}, step {position.step})"
        call = f"{hook}()" if hook != "snapshot" else "copying it"
        return IsolatedAgentError(f"agent '{name}' (isolated): {call} {problem}{where}")


def is_isolatable(spec: AgentSpec) -> bool:
    """Whether ``--isolate`` runs the agent of ``spec`` in a process of its own."""
    return spec.kind in ISOLATED_KINDS
