"""A policy whose actions come from an agent server over HTTP, so an agent in any language can be evaluated.

Each step, :meth:`HttpAgent.act` POSTs the observation and the step's public context as JSON to
the agent's URL and reads the action from the reply (the contract, with an example exchange:
docs/http_agents.md). One keep-alive connection serves a whole evaluation; connection errors,
timeouts and HTTP 5xx answers are retried after a short wait, any other bad reply fails at once
with an :class:`HttpAgentError` naming the agent, the URL, the run seed, episode and step.
"""

from __future__ import annotations

import copy
import json
import math
import socket
import threading
import time
from dataclasses import dataclass
from typing import Any
from urllib.parse import urlsplit

import httpx
import numpy as np

from ..common.redaction import redact_url
from ..tasks.base import observation_names_of
from ..tasks.registry import get_task
from .adapters import AgentFailure

ACTION_MODES = ("continuous", "discrete")
DEFAULT_TIMEOUT_S = 5.0
DEFAULT_RETRIES = 2
#: Seconds waited before retry 1, 2, 3, ... (the last value repeats): short, since a local agent
#: server that drops one request is usually back at once.
RETRY_WAITS_S = (0.05, 0.2, 0.5)
#: The keys of every request body, in the order they are sent.
REQUEST_KEYS = (
    "observation",
    "observation_names",
    "hour",
    "hour_of_day",
    "step",
    "episode",
    "episode_seed",
    "run_seed",
)
_HEADERS = {"Content-Type": "application/json", "Accept": "application/json"}
_SNIPPET_CHARS = 120


class HttpAgentError(AgentFailure):
    """An agent server that cannot be reached or gave a reply the benchmark cannot use.

    The message is one line: ``agent 'NAME' (URL): PROBLEM (run seed R, episode E, step S)``;
    the position is left out for problems found before the first step (a bad URL, nothing
    listening). The URL is shown with any user info and query values redacted.

    Attributes
    ----------
    agent, url, problem : str
    run_seed, episode, step : int or None
    """

    def __init__(
        self,
        agent: str,
        url: str,
        problem: str,
        *,
        run_seed: int | None = None,
        episode: int | None = None,
        step: int | None = None,
    ) -> None:
        super().__init__(agent, problem, where=f" ({url})", run_seed=run_seed, episode=episode, step=step)
        self.url = url


@dataclass
class _Episode:
    """The public context of the episode being played (one per thread)."""

    run_seed: int
    episode: int
    episode_seed: int
    start_hour: int
    step: int = 0


class _Connections:
    """Every HTTP client of one agent and its copies, so :meth:`HttpAgent.close` reaches them all."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.clients: list[httpx.Client] = []


class HttpAgent:
    """A policy answered by an agent server: one POST per step, the action read from the reply.

    Parameters
    ----------
    name : str
        The policy's name in every record.
    url : str
        ``http://`` or ``https://`` URL with a host (the port defaults to 80/443), e.g.
        ``http://127.0.0.1:8000/act``. Contacted directly (proxy environment variables are
        ignored). Construction checks that the host accepts a TCP connection on that port.
    action_mode : {"continuous", "discrete"}
        ``continuous``: the reply's ``action`` is three numbers in [0, 1] (normalised reward
        ratio, liquidity ratio, burn rate); ``discrete``: an integer index (or ``[index]``)
        into the grid of ``discrete_actions`` actions.
    timeout_s : float
        Limit on each phase of one request (connecting, sending, waiting for the reply,
        reading it), seconds.
    retries : int
        Further attempts after a connection error, a timeout or an HTTP 5xx answer (after
        waits of :data:`RETRY_WAITS_S`). Other bad replies are not retried.
    discrete_actions : int
        Size of the discrete action grid (``discrete_levels ** 3``; 125 by default).
    stateless : bool
        Declare that the server's answer depends on the request alone and that it serves
        concurrent requests; the runner may then play episodes on several threads (each
        thread has its own connection). Default False: a run's episodes are played in order.

    Raises
    ------
    HttpAgentError
        A bad URL or option, or nothing accepting connections at the URL's host and port.
    """

    #: The server is another process that receives only the request's JSON: rows are labelled
    #: ``isolated`` (:func:`~solarchain_eval.agents.base.access_label`).
    isolated = True

    def __init__(
        self,
        name: str,
        url: str,
        *,
        action_mode: str = "continuous",
        timeout_s: float = DEFAULT_TIMEOUT_S,
        retries: int = DEFAULT_RETRIES,
        discrete_actions: int = 125,
        stateless: bool = False,
    ) -> None:
        self.name = str(name)
        self.url = str(url)
        self.shown_url = redact_url(self.url)
        host, port = self._check_options(action_mode, timeout_s, retries, discrete_actions)
        self.action_mode = action_mode
        self.timeout_s = float(timeout_s)
        self.retries = int(retries)
        self.discrete_actions = int(discrete_actions)
        self.stateless = bool(stateless)
        #: Sent with each observation: the solar market's feature names unless the evaluation sets its task's.
        self.observation_names: tuple[str, ...] | None = observation_names_of(get_task())
        self._connections = _Connections()
        self._local = threading.local()
        self._check_reachable(host, port)

    # --- construction -------------------------------------------------------------------------
    def _fail(self, problem: str, episode: _Episode | None = None) -> HttpAgentError:
        if episode is None:
            return HttpAgentError(self.name, self.shown_url, problem)
        return HttpAgentError(
            self.name, self.shown_url, problem, run_seed=episode.run_seed, episode=episode.episode, step=episode.step
        )

    def _check_options(
        self, action_mode: str, timeout_s: float, retries: int, discrete_actions: int
    ) -> tuple[str, int]:
        """The URL's host and port, after checking the URL and the options."""
        if action_mode not in ACTION_MODES:
            raise self._fail(f"action_mode must be one of {', '.join(ACTION_MODES)}, not {action_mode!r}")
        if not (isinstance(timeout_s, int | float) and math.isfinite(timeout_s) and timeout_s > 0):
            raise self._fail(f"timeout_s must be a positive number of seconds, not {timeout_s!r}")
        if isinstance(retries, bool) or not isinstance(retries, int) or retries < 0:
            raise self._fail(f"retries must be an integer >= 0, not {retries!r}")
        if isinstance(discrete_actions, bool) or not isinstance(discrete_actions, int) or discrete_actions < 1:
            raise self._fail(f"discrete_actions must be an integer >= 1, not {discrete_actions!r}")
        parts = urlsplit(self.url)
        if parts.scheme not in ("http", "https"):
            raise self._fail("the URL must start with http:// or https://")
        if not parts.hostname:
            raise self._fail("the URL names no host")
        try:
            port = parts.port
        except ValueError:
            raise self._fail("the URL's port is not a number in 0..65535") from None
        return parts.hostname, port if port is not None else (443 if parts.scheme == "https" else 80)

    def _check_reachable(self, host: str, port: int) -> None:
        try:
            socket.create_connection((host, port), timeout=self.timeout_s).close()
        except OSError as error:
            reason = error.strerror or str(error) or type(error).__name__
            raise self._fail(f"cannot connect to {host}:{port} ({reason}); is the agent server running?") from None

    # --- Policy protocol ----------------------------------------------------------------------
    def begin_run(self, run_seed: int) -> None:
        """Nothing to prepare: each episode's context carries its run seed."""
        return None

    def begin_episode(self, *, episode: int, run_seed: int, episode_seed: int, start_hour: int) -> None:
        """Start an episode's context (sent with every step): nothing but the observation and this
        public context ever reaches the server."""
        self._local.episode = _Episode(int(run_seed), int(episode), int(episode_seed), int(start_hour))

    def act(self, observation: np.ndarray) -> np.ndarray | int:
        """POST the observation and the step's context; the validated action of the reply.

        Returns
        -------
        numpy.ndarray or int
            Three float32 numbers in [0, 1] (continuous) or an index (discrete).

        Raises
        ------
        HttpAgentError
            No usable reply (after the retries, for connection errors, timeouts and 5xx).
        RuntimeError
            ``act`` before ``begin_episode``.
        """
        episode = getattr(self._local, "episode", None)
        if episode is None:
            raise RuntimeError(f"agent '{self.name}': act() before begin_episode() (the request needs the episode)")
        hour = episode.start_hour + episode.step
        request = {
            "observation": np.asarray(observation, dtype=np.float64).ravel().tolist(),
            # the task's feature names (the solar market's twelve); an empty list when it declares none
            "observation_names": list(self.observation_names or ()),
            "hour": hour,
            "hour_of_day": hour % 24,
            "step": episode.step,
            "episode": episode.episode,
            "episode_seed": episode.episode_seed,
            "run_seed": episode.run_seed,
        }
        try:
            body = json.dumps(request, allow_nan=False).encode()
        except ValueError:
            raise self._fail("the observation has a non-finite value; nothing was sent", episode) from None
        action = self._read_action(self._post(body, episode), episode)
        episode.step += 1
        return action

    def close(self) -> None:
        """Close every connection (a later ``act`` opens a new one)."""
        with self._connections.lock:
            clients, self._connections.clients = self._connections.clients, []
        for client in clients:
            client.close()

    def __enter__(self) -> HttpAgent:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __deepcopy__(self, memo: dict) -> HttpAgent:
        # A private copy (the runner copies stateful policies per task) plays on its own
        # connection; it shares the registry of connections, so closing the original closes it.
        twin = copy.copy(self)
        twin._local = threading.local()
        memo[id(self)] = twin
        return twin

    def __repr__(self) -> str:
        return f"HttpAgent(name={self.name!r}, url={self.shown_url!r}, action_mode={self.action_mode!r})"

    # --- requests -----------------------------------------------------------------------------
    def _client(self) -> httpx.Client:
        client = getattr(self._local, "client", None)
        if client is None or client.is_closed:
            # One keep-alive connection; TCP_NODELAY so the request body (a second small write after
            # the headers) is not held back waiting for the server's delayed ACK.
            transport = httpx.HTTPTransport(
                limits=httpx.Limits(max_connections=1, max_keepalive_connections=1),
                socket_options=[(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)],
            )
            client = httpx.Client(timeout=self.timeout_s, transport=transport, trust_env=False)
            with self._connections.lock:
                self._connections.clients.append(client)
            self._local.client = client
        return client

    def _post(self, body: bytes, episode: _Episode) -> httpx.Response:
        """The first 2xx answer; retries connection errors, timeouts and 5xx."""
        client = self._client()
        problem = ""
        for attempt in range(self.retries + 1):
            if attempt:
                time.sleep(RETRY_WAITS_S[min(attempt, len(RETRY_WAITS_S)) - 1])
            try:
                response = client.post(self.url, content=body, headers=_HEADERS)
            except httpx.TimeoutException:
                problem = f"no reply within timeout_s={self.timeout_s:g}"
                continue
            except httpx.TransportError as error:
                problem = f"connection failed ({_one_line(str(error)) or type(error).__name__})"
                continue
            if response.status_code >= 500:
                problem = f"HTTP {response.status_code} {response.reason_phrase}{_quoted(response.text)}"
                continue
            if not response.is_success:
                problem = f"HTTP {response.status_code} {response.reason_phrase}{_quoted(response.text)}"
                raise self._fail(f"reply {problem}", episode)
            return response
        attempts = self.retries + 1
        raise self._fail(f"{problem} ({attempts} attempt{'s' if attempts > 1 else ''})", episode)

    def _read_action(self, response: httpx.Response, episode: _Episode) -> np.ndarray | int:
        try:
            reply = json.loads(response.content)
        except (ValueError, UnicodeDecodeError):
            raise self._fail(f"reply is not JSON{_quoted(response.text)}", episode) from None
        if not isinstance(reply, dict) or "action" not in reply:
            raise self._fail(f'reply has no "action" key{_quoted(response.text)}', episode)
        action = reply["action"]
        if self.action_mode == "discrete":
            return self._discrete(action, episode)
        if not isinstance(action, list) or len(action) != 3:
            raise self._fail(f"reply action must be a list of 3 numbers, got {_shown(action)}", episode)
        for i, value in enumerate(action):
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise self._fail(f"reply action[{i}]={_shown(value)} is not a number", episode)
            if not math.isfinite(value):
                raise self._fail(f"reply action[{i}]={_shown(value)} is not finite", episode)
            if not 0 <= value <= 1:
                raise self._fail(f"reply action[{i}]={_shown(value)} is outside [0, 1]", episode)
        return np.array(action, dtype=np.float32)

    def _discrete(self, action: Any, episode: _Episode) -> int:
        index = action[0] if isinstance(action, list) and len(action) == 1 else action
        if isinstance(index, bool) or not isinstance(index, int):
            raise self._fail(f"reply action must be an integer index or [index], got {_shown(action)}", episode)
        if not 0 <= index < self.discrete_actions:
            raise self._fail(f"reply action={index} is outside 0..{self.discrete_actions - 1}", episode)
        return index


def _one_line(text: str) -> str:
    return " ".join(text.split())


def _shown(value: Any) -> str:
    """A reply value as the server wrote it (JSON), shortened."""
    text = json.dumps(value)
    return text if len(text) <= _SNIPPET_CHARS else text[: _SNIPPET_CHARS - 3] + "..."


def _quoted(text: str) -> str:
    text = _one_line(text)
    if not text:
        return ""
    return f": {text if len(text) <= _SNIPPET_CHARS else text[: _SNIPPET_CHARS - 3] + '...'!r}"
