"""Running the fleet with guidance planners written in Python.

:class:`Run` starts ``fleet run --planner external:...`` (or joins a run someone else started,
:meth:`Run.attach`), joins the run's iceoryx2 domain with the configuration the run writes to
``OUT/config/iceoryx2.toml``, opens the plan services of the UAVs it serves and answers their
requests (``docs/python.md``):

- ``{run}/uav/{i}/plan``: request-response, bytes both ways; the agent is the client, this
  process the server;
- ``{run}/planner/wake``: event, the asking UAV's index; an agent sends it after each request
  and this process waits on it;
- ``{run}/uav/{i}/wake``: event, id 8 (``PlanAnswer``), sent after each answer.

:meth:`Run.serve` answers every request with a :class:`~setfleet.Planner` until the run ends;
:meth:`Run.next_request` and :meth:`Run.answer` are the same one request at a time (the
Gymnasium environments use them).

**A planner's exception** in :meth:`Run.serve` stops the run: the fleet process is terminated,
the ports are released and the exception is raised again (``on_error="raise"``, the default).
With ``on_error="fallback"`` it is logged instead and the request is left unanswered: the agent
falls back on its own planner once its deadline passes.
"""

from __future__ import annotations

import ctypes
import itertools
import logging
import math
import os
import re
import secrets
import shutil
import signal
import subprocess
import time
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping, NamedTuple, Sequence

import numpy as np

from .layout import (
    ANSWER_HEADER_BYTES,
    MAX_ANSWER_INCREMENTS,
    MAX_ANSWER_VIEWS,
    LayoutError,
    Observation,
    as_action,
    encode_answer,
)
from .planner import Planner, as_planner
from .results import read_summary, read_timeseries, read_tracks

try:  # Python 3.11+
    import tomllib as _toml
except ModuleNotFoundError:  # pragma: no cover - Python 3.10
    import tomli as _toml  # type: ignore[no-redef]

__all__ = [
    "Run",
    "RunResult",
    "Request",
    "RequestHandle",
    "Latency",
    "RunEnded",
    "find_fleet",
    "fleet_supports_planner",
    "new_run_id",
    "PLAN_ANSWER_EVENT",
]

log = logging.getLogger("setfleet")

#: Environment variable naming the ``fleet`` binary.
FLEET_ENV = "SETFLEET_FLEET"
#: Event id an answer's wake-up carries on ``{run}/uav/{i}/wake`` (``WakeEvent::PlanAnswer``).
PLAN_ANSWER_EVENT = 8
#: Prefix of every iceoryx2 file of a run: ``iox2_sf_{run}_``.
FILE_PREFIX = "iox2_sf_"
#: What ``fleet run --run-id`` accepts.
RUN_ID_RE = re.compile(r"^[A-Za-z0-9_-]{1,40}$")
#: Largest answer this process may send.
MAX_ANSWER_BYTES = ANSWER_HEADER_BYTES + 8 * MAX_ANSWER_INCREMENTS + 32 * MAX_ANSWER_VIEWS

_REPO = Path(__file__).resolve().parents[2]
_run_counter = itertools.count()


class RunEnded(Exception):
    """The run is over (its process exited, or its agents left) and no request is pending."""


# --------------------------------------------------------------------------------------------
# The fleet binary


def find_fleet(fleet: str | os.PathLike[str] | None = None) -> Path:
    """The ``fleet`` binary: ``fleet`` if given, else ``$SETFLEET_FLEET``, else ``fleet`` on
    ``PATH``, else ``<repo>/target/release/fleet``, else ``<repo>/target/debug/fleet``.
    Raises :class:`FileNotFoundError` if none exists."""
    if fleet is not None:
        return Path(fleet)
    env = os.environ.get(FLEET_ENV)
    if env:
        return Path(env)
    on_path = shutil.which("fleet")
    if on_path:
        return Path(on_path)
    for profile in ("release", "debug"):
        candidate = _REPO / "target" / profile / "fleet"
        if candidate.is_file() and os.access(candidate, os.X_OK):
            return candidate
    raise FileNotFoundError(
        f"no fleet binary: set ${FLEET_ENV}, put fleet on PATH or build it "
        f"(cargo build --release in {_REPO})"
    )


_supports_cache: dict[tuple[str, float], bool] = {}


def fleet_supports_planner(fleet: str | os.PathLike[str] | None = None) -> bool:
    """Whether the ``fleet`` binary knows ``fleet run --planner`` (False if there is none)."""
    try:
        path = find_fleet(fleet)
        key = (str(path), path.stat().st_mtime)
    except (FileNotFoundError, OSError):
        return False
    if key not in _supports_cache:
        try:
            out = subprocess.run(
                [str(path), "run", "--help"],
                capture_output=True,
                text=True,
                timeout=30,
            ).stdout
        except (OSError, subprocess.SubprocessError):
            out = ""
        _supports_cache[key] = "--planner" in out
    return _supports_cache[key]


def new_run_id(prefix: str = "py") -> str:
    """A fresh run id: ``{prefix}{pid}-{counter}-{random}`` (at most 40 characters)."""
    rid = f"{prefix}{os.getpid()}-{next(_run_counter)}-{secrets.token_hex(3)}"
    return rid[-40:]


# --------------------------------------------------------------------------------------------
# Results


@dataclass(frozen=True)
class Latency:
    """Quantiles of the planner's own time per decision, ms."""

    count: int
    median_ms: float
    p99_ms: float
    max_ms: float
    mean_ms: float

    @classmethod
    def of_ns(cls, ns: Sequence[int] | np.ndarray) -> "Latency | None":
        """The quantiles of ``ns`` (nanoseconds); ``None`` without any."""
        v = np.sort(np.asarray(ns, dtype=np.float64)) / 1e6
        n = v.size
        if n == 0:
            return None
        rank = lambda q: float(v[min(max(math.ceil(q * n), 1), n) - 1])  # noqa: E731
        return cls(n, rank(0.5), rank(0.99), float(v[-1]), float(v.mean()))


@dataclass
class RunResult:
    """What a finished run left: its output directory and what this process measured.

    ``summary`` is ``OUT/summary.json`` (``None`` if the run wrote none); ``decide_ns`` is the
    planner's own time on each answered decision; ``decisions`` counts answers sent,
    ``late`` answers whose agent had stopped waiting, ``stale`` requests found already
    abandoned, ``errors`` planner exceptions under ``on_error="fallback"``."""

    out: Path
    run_id: str
    exit_code: int | None
    summary: dict[str, Any] | None
    decisions: int = 0
    late: int = 0
    stale: int = 0
    errors: int = 0
    decide_ns: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    answered: dict[int, int] = field(default_factory=dict)

    def timeseries(self, pandas: bool = False) -> Any:
        """``OUT/timeseries.csv`` (:func:`setfleet.read_timeseries`)."""
        return read_timeseries(self.out, pandas=pandas)

    def tracks(self, pandas: bool = False) -> Any:
        """``OUT/tracks.csv`` (:func:`setfleet.read_tracks`)."""
        return read_tracks(self.out, pandas=pandas)

    @property
    def latency(self) -> Latency | None:
        """Quantiles of the planner's own decide time."""
        return Latency.of_ns(self.decide_ns)

    @property
    def violations(self) -> int | None:
        """``summary.json``'s ``violations``."""
        return None if self.summary is None else self.summary.get("violations")

    @property
    def ua_final(self) -> float | None:
        """``summary.json``'s ``ua_final``."""
        return None if self.summary is None else self.summary.get("ua_final")

    def agent(self, uav: int) -> dict[str, Any]:
        """``summary.json``'s ``agents`` entry of ``uav``."""
        if self.summary is None:
            raise KeyError("the run wrote no summary.json")
        for a in self.summary.get("agents", []):
            if a.get("uav") == uav:
                return a
        raise KeyError(f"no agent {uav} in summary.json")


# --------------------------------------------------------------------------------------------
# Requests


class RequestHandle:
    """One received request, until it is answered or skipped (it holds the agent's sample;
    ``obs`` is valid while it does)."""

    __slots__ = ("uav", "obs", "received_ns", "_active", "_done")

    def __init__(self, uav: int, obs: Observation, active: Any) -> None:
        self.uav = uav
        self.obs = obs
        self.received_ns = time.perf_counter_ns()
        self._active = active
        self._done = False

    @property
    def done(self) -> bool:
        """Whether it was answered or skipped."""
        return self._done

    def __repr__(self) -> str:
        return f"RequestHandle(uav={self.uav}, step={self.obs.step}, done={self._done})"


class Request(NamedTuple):
    """A request waiting for its answer: ``uav, obs, handle = run.next_request()``."""

    uav: int
    obs: Observation
    handle: RequestHandle


# --------------------------------------------------------------------------------------------
# iceoryx2 ports


def _iox2() -> Any:
    import iceoryx2  # imported late: the layout and the results need no iceoryx2

    return iceoryx2


def _read_prefix(config_file: Path) -> str | None:
    """``[global] prefix`` of an iceoryx2 configuration file, if it can be read."""
    try:
        with open(config_file, "rb") as f:
            return _toml.load(f).get("global", {}).get("prefix")
    except (OSError, ValueError):
        return None


def run_id_of_prefix(prefix: str) -> str:
    """The run id of a run's iceoryx2 prefix ``iox2_sf_{run}_`` (a simulated host's domain
    suffix ``.h{n}`` dropped: service names do not carry it)."""
    if not (prefix.startswith(FILE_PREFIX) and prefix.endswith("_")):
        raise ValueError(f"{prefix!r} is not a setfleet run's iceoryx2 prefix")
    rid = re.sub(r"\.h\d+$", "", prefix[len(FILE_PREFIX) : -1])
    if not RUN_ID_RE.match(rid):
        raise ValueError(f"{prefix!r} holds no valid run id")
    return rid


class _Ports:
    """This process's node and ports in a run's domain."""

    def __init__(
        self,
        config_file: Path,
        run_id: str,
        uavs: Sequence[int],
        timeout: float,
        alive: Callable[[], str | None],
    ) -> None:
        iox2 = _iox2()
        self.iox2 = iox2
        cfg = iox2.config.from_file(iox2.FilePath.new(str(config_file)))
        self.node = (
            iox2.NodeBuilder.new()
            .config(cfg)
            .name(iox2.NodeName.new(f"setfleet-planner-{os.getpid()}"))
            .signal_handling_mode(iox2.SignalHandlingMode.Disabled)
            .create(iox2.ServiceType.Ipc)
        )
        self.uavs = tuple(uavs)
        self.plan_services: dict[int, Any] = {}
        self.servers: dict[int, Any] = {}
        self.wake_services: dict[int, Any] = {}
        self.notifiers: dict[int, Any] = {}
        self.planner_wake: Any = None
        self.listener: Any = None
        slice_u8 = iox2.Slice[ctypes.c_uint8]
        deadline = time.monotonic() + timeout
        last_error = ""  # text only: a kept exception would keep this frame (and its ports) alive
        while True:
            try:
                if self.listener is None:
                    svc = self._open_event(f"{run_id}/planner/wake")
                    self.planner_wake = svc
                    self.listener = svc.listener_builder().create()
                for uav in self.uavs:
                    if uav not in self.servers:
                        svc = (
                            self.node.service_builder(iox2.ServiceName.new(f"{run_id}/uav/{uav}/plan"))
                            .request_response(slice_u8, slice_u8)
                            .open()
                        )
                        server = (
                            svc.server_builder()
                            .initial_max_slice_len(MAX_ANSWER_BYTES)
                            .allocation_strategy(iox2.AllocationStrategy.PowerOfTwo)
                            .create()
                        )
                        self.plan_services[uav] = svc
                        self.servers[uav] = server
                    if uav not in self.notifiers:
                        svc = self._open_event(f"{run_id}/uav/{uav}/wake")
                        self.wake_services[uav] = svc
                        self.notifiers[uav] = (
                            svc.notifier_builder()
                            .default_event_id(iox2.EventId.new(PLAN_ANSWER_EVENT))
                            .create()
                        )
                return
            except (iox2.RequestResponseOpenError, iox2.EventOpenError) as e:
                if "Incompatible" in str(e):
                    self.release()
                    raise RuntimeError(
                        f"the run's plan services do not match this package's layout: {e}"
                    ) from e
                last_error = str(e)
            why = alive()
            if why is not None:
                self.release()
                raise RuntimeError(f"the run ended before its plan services could be opened: {why}")
            if time.monotonic() >= deadline:
                missing = [u for u in self.uavs if u not in self.servers or u not in self.notifiers]
                self.release()
                raise TimeoutError(
                    f"the plan services of UAVs {missing} of run {run_id} did not appear within "
                    f"{timeout:.0f} s (last error: {last_error}); does the run ask an external "
                    f"planner for them (fleet run --planner external:...)?"
                )
            time.sleep(0.05)

    def _open_event(self, name: str) -> Any:
        return self.node.service_builder(self.iox2.ServiceName.new(name)).event().open()

    def clients(self) -> int:
        """Clients (agents) connected to the served plan services, all together."""
        return sum(s.dynamic_config.number_of_clients for s in self.plan_services.values())

    def wait(self, seconds: float) -> None:
        """Waits at most ``seconds`` for a planner wake-up."""
        self.listener.timed_wait(self.iox2.Duration.from_secs_f64(max(seconds, 0.0)))

    def release(self) -> None:
        """Deletes every port and drops the node (idempotent)."""
        for ports in (self.servers, self.notifiers):
            for p in ports.values():
                try:
                    p.delete()
                except Exception:  # noqa: BLE001 - best effort while tearing down
                    pass
            ports.clear()
        if self.listener is not None:
            try:
                self.listener.delete()
            except Exception:  # noqa: BLE001
                pass
            self.listener = None
        self.plan_services.clear()
        self.wake_services.clear()
        self.planner_wake = None
        self.node = None


# --------------------------------------------------------------------------------------------
# Runs


def _override_args(overrides: Iterable[str] | Mapping[str, Any]) -> list[str]:
    if isinstance(overrides, Mapping):
        items = []
        for k, v in overrides.items():
            if isinstance(v, bool):
                v = "true" if v else "false"
            items.append(f"{k}={v}")
    else:
        items = [str(o) for o in overrides]
    args: list[str] = []
    for item in items:
        if "=" not in item:
            raise ValueError(f"an override is KEY=VALUE, not {item!r}")
        args += ["--set", item]
    return args


def _external_arg(external: Any) -> str | None:
    """``--planner``'s value for ``external`` (``None``: no external planner)."""
    if external is None:
        return None
    if isinstance(external, str):
        if external == "all":
            return "external:all"
        raise ValueError(f"external is 'all' or a list of UAVs, not {external!r}")
    if isinstance(external, int):
        external = [external]
    uavs = sorted({int(u) for u in external})
    if not uavs:
        return None
    return "external:" + ",".join(str(u) for u in uavs)


class Run:
    """A run of the fleet whose external-planner UAVs this process serves.

    ``Run(...)`` starts ``fleet run --planner external:...`` with the given scenario flags
    (its stdout and stderr go to ``OUT/fleet.stdout.log`` and ``OUT/fleet.stderr.log``), waits
    for the run's iceoryx2 configuration, joins its domain and opens the plan services of the
    ``external`` UAVs (retrying up to ``connect_timeout`` seconds while the agents have not
    created them; it never creates them). Then :meth:`serve` answers with a planner, or
    :meth:`next_request` / :meth:`answer` one request at a time. Use it as a context manager,
    or call :meth:`close`, so that the fleet process and the ports are always released.

    Args:
        scenario: scenario TOML file (default: the paper's scenario).
        seed: the run's seed.
        variant: the guidance variant of the other UAVs and of the fallback.
        external: the UAVs whose decisions this process takes: a list, an int, or ``"all"``;
            ``None`` or ``[]`` runs without an external planner (nothing to serve).
        duration: simulated seconds (default: the scenario's).
        out: output directory (default: a new temporary directory).
        overrides: ``--set`` overrides, as ``"key=value"`` strings or a mapping.
        uavs: ``uavs.count`` (default: the scenario's).
        run_id: the run id (default: a fresh one, :func:`new_run_id`).
        fleet: the ``fleet`` binary (default: :func:`find_fleet`).
        extra_args: more ``fleet run`` arguments (e.g. ``["--strict"]``).
        connect_timeout: longest wait for the run's configuration and services, s.
        env: environment of the fleet process (default: this process's).
    """

    def __init__(
        self,
        scenario: str | os.PathLike[str] | None = None,
        seed: int = 1,
        variant: str = "paper",
        external: Any = (0,),
        duration: float | None = None,
        out: str | os.PathLike[str] | None = None,
        overrides: Iterable[str] | Mapping[str, Any] = (),
        uavs: int | None = None,
        run_id: str | None = None,
        fleet: str | os.PathLike[str] | None = None,
        extra_args: Sequence[str] = (),
        *,
        connect_timeout: float = 30.0,
        env: Mapping[str, str] | None = None,
    ) -> None:
        self._init_state()
        self.run_id = run_id if run_id is not None else new_run_id()
        if not RUN_ID_RE.match(self.run_id):
            raise ValueError(f"run id {self.run_id!r}: 1 to 40 characters of [A-Za-z0-9_-]")
        if out is None:
            import tempfile

            out = tempfile.mkdtemp(prefix=f"setfleet-{self.run_id}-")
        self.out = Path(out).resolve()
        self.out.mkdir(parents=True, exist_ok=True)
        planner_arg = _external_arg(external)
        args = [
            str(find_fleet(fleet)),
            "run",
            "--out",
            str(self.out),
            "--run-id",
            self.run_id,
            "--seed",
            str(int(seed)),
            "--variant",
            variant,
        ]
        if scenario is not None:
            args += ["--scenario", str(scenario)]
        if duration is not None:
            args += ["--duration", repr(float(duration))]
        if uavs is not None:
            args += ["--uavs", str(int(uavs))]
        if planner_arg is not None:
            args += ["--planner", planner_arg]
        args += _override_args(overrides)
        args += [str(a) for a in extra_args]
        self.args = args
        self._stdout = open(self.out / "fleet.stdout.log", "wb")
        self._stderr = open(self.out / "fleet.stderr.log", "wb")
        self._started_wall = time.time()
        log.info("starting %s", " ".join(args))
        self.process = subprocess.Popen(
            args,
            stdin=subprocess.DEVNULL,
            stdout=self._stdout,
            stderr=self._stderr,
            env=None if env is None else dict(env),
            start_new_session=True,
        )
        try:
            config = self._await_config(connect_timeout)
            self.scenario = self._read_scenario()
            if planner_arg is None:
                self.uavs: tuple[int, ...] = ()
            elif external == "all":
                self.uavs = tuple(range(int(self.scenario["uavs"]["count"])))
            else:
                self.uavs = tuple(sorted({int(u) for u in ([external] if isinstance(external, int) else external)}))
            if self.uavs:
                self._ports = _Ports(config, self.run_id, self.uavs, connect_timeout, self._why_ended)
        except BaseException:
            self.close()
            raise

    def _init_state(self) -> None:
        self.process: subprocess.Popen[bytes] | None = None
        self._ports: _Ports | None = None
        self._pending: deque[RequestHandle] = deque()
        self._stdout: Any = None
        self._stderr: Any = None
        self._closed = False
        self._decide_ns: list[int] = []
        self._answered: dict[int, int] = {}
        self._late = 0
        self._stale = 0
        self._errors = 0
        self._seen_clients = False
        self._last_answered: set[int] = set()
        self._clientless_since: float | None = None
        self._started_wall = time.time()
        self.scenario: dict[str, Any] = {}
        self.uavs = ()
        self.args: list[str] = []

    @classmethod
    def attach(
        cls,
        out_dir: str | os.PathLike[str],
        uavs: Any,
        run_id: str | None = None,
        *,
        connect_timeout: float = 30.0,
    ) -> "Run":
        """Joins a run started elsewhere (``fleet run --planner external:... --out OUT``) to
        serve ``uavs`` (a list, an int or ``"all"``). The run id comes from the prefix in
        ``OUT/config/iceoryx2.toml`` (``iox2_sf_{run}_``) unless given; the configuration is
        awaited up to ``connect_timeout`` seconds. Such a run ends for this process when its
        agents leave (no client on any served plan service for 2 s) or its ``summary.json``
        appears; :meth:`close` releases the ports and stops nothing else."""
        self = cls.__new__(cls)
        self._init_state()
        self.out = Path(out_dir).resolve()
        config = self.out / "config" / "iceoryx2.toml"
        deadline = time.monotonic() + connect_timeout
        prefix = _read_prefix(config)
        while prefix is None or (run_id is not None and prefix != f"{FILE_PREFIX}{run_id}_"):
            if time.monotonic() >= deadline:
                raise TimeoutError(f"no iceoryx2 configuration of the run in {config}")
            time.sleep(0.05)
            prefix = _read_prefix(config)
        self.run_id = run_id if run_id is not None else run_id_of_prefix(prefix)
        self.scenario = self._read_scenario()
        if uavs == "all":
            self.uavs = tuple(range(int(self.scenario["uavs"]["count"])))
        else:
            self.uavs = tuple(sorted({int(u) for u in ([uavs] if isinstance(uavs, int) else uavs)}))
        self._ports = _Ports(config, self.run_id, self.uavs, connect_timeout, self._why_ended)
        return self

    # ---- start-up helpers ------------------------------------------------------------------

    def _await_config(self, timeout: float) -> Path:
        """Waits for this run's ``OUT/config/iceoryx2.toml`` (its prefix names this run)."""
        config = self.out / "config" / "iceoryx2.toml"
        expected = f"{FILE_PREFIX}{self.run_id}_"
        deadline = time.monotonic() + timeout
        while _read_prefix(config) != expected:
            why = self._why_ended()
            if why is not None:
                raise RuntimeError(f"fleet run failed before starting: {why}")
            if time.monotonic() >= deadline:
                raise TimeoutError(f"fleet run wrote no {config} within {timeout:.0f} s")
            time.sleep(0.02)
        return config

    def _read_scenario(self) -> dict[str, Any]:
        try:
            with open(self.out / "scenario.toml", "rb") as f:
                return _toml.load(f)
        except (OSError, ValueError):
            return {}

    def _stderr_tail(self, n: int = 2000) -> str:
        try:
            text = (self.out / "fleet.stderr.log").read_text(errors="replace")
        except OSError:
            return ""
        return text[-n:].strip()

    def _why_ended(self) -> str | None:
        """Why the run is over, or ``None`` while it goes on."""
        if self.process is not None:
            code = self.process.poll()
            if code is None:
                return None
            tail = self._stderr_tail()
            return f"fleet exited with code {code}" + (f":\n{tail}" if tail else "")
        # An attached run: over once its summary is written or its agents left.
        try:
            if (self.out / "summary.json").stat().st_mtime >= self._started_wall:
                return "the run wrote its summary"
        except OSError:
            pass
        if self._ports is not None and self._ports.plan_services:
            if self._ports.clients() > 0:
                self._seen_clients = True
                self._clientless_since = None
            elif self._seen_clients:
                now = time.monotonic()
                if self._clientless_since is None:
                    self._clientless_since = now
                elif now - self._clientless_since >= 2.0:
                    return "its agents left"
        return None

    # ---- state -----------------------------------------------------------------------------

    @property
    def ended(self) -> bool:
        """Whether the run is over (the fleet process exited; for an attached run, its agents
        left or its summary appeared)."""
        return self._why_ended() is not None

    @property
    def pending(self) -> int:
        """Requests received and not yet answered or skipped."""
        return sum(1 for h in self._pending if not h.done)

    @property
    def returncode(self) -> int | None:
        """The fleet process's exit code, once it exited."""
        return None if self.process is None else self.process.poll()

    # ---- one request at a time -------------------------------------------------------------

    def _drain(self) -> None:
        """Takes every request waiting on the served plan services."""
        ports = self._ports
        if ports is None:
            return
        for uav, server in ports.servers.items():
            while True:
                active = server.receive()
                if active is None:
                    break
                if not active.is_connected:
                    self._stale += 1
                    active.delete()
                    continue
                try:
                    obs = Observation(active.payload().as_memory_view())
                except LayoutError:
                    active.delete()
                    raise
                self._pending.append(RequestHandle(uav, obs, active))

    def next_request(self, timeout: float | None = None, poll_s: float = 0.05) -> Request | None:
        """The next request to answer, as ``(uav, obs, handle)``: waits at most ``timeout``
        seconds (``None``: until one comes or the run ends) and returns ``None`` if none came.

        ``obs``'s arrays are valid until the request is answered (:meth:`answer`) or skipped
        (:meth:`skip`). Raises :class:`RunEnded` once the run is over with nothing pending,
        and :class:`~setfleet.LayoutError` for a request that does not follow the layout (a
        ``fleet`` of another layout version)."""
        if self._closed or (self._ports is None and self.process is None):
            raise RunEnded("the run is closed")
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            while self._pending:
                h = self._pending.popleft()
                if not h.done:
                    return Request(h.uav, h.obs, h)
            self._drain()
            if self._pending:
                continue
            if self._ports is not None and self._last_answered.issuperset(self.uavs):
                # Every served UAV took its last decision: no request can come. Leave the
                # run's domain now, before the run removes its files at its end.
                self._release_ports()
            why = self._why_ended()
            if why is not None or (self._ports is None and self.process is None):
                self._release_ports()
                raise RunEnded(why or "the run is over")
            wait = poll_s
            if deadline is not None:
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    return None
                wait = min(wait, remaining)
            if self._ports is not None:
                self._ports.wait(wait)
            else:
                time.sleep(wait)

    def answer(self, handle: RequestHandle, action: Any, planner_ns: int = 0) -> bool:
        """Answers ``handle``'s request with ``action`` (anything :func:`~setfleet.as_action`
        takes) and wakes its agent. Returns whether the agent was still waiting for it.
        Raises :class:`~setfleet.ActionError` (without answering) for an action the agent
        would refuse."""
        data = encode_answer(handle.obs, as_action(action), planner_ns)
        return self.answer_bytes(handle, data, planner_ns)

    def answer_bytes(self, handle: RequestHandle, data: bytes, planner_ns: int | None = None) -> bool:
        """Sends ``data`` as the answer to ``handle``'s request, unchecked (tests send
        malformed answers this way), and wakes its agent. Returns whether the agent was still
        waiting for it."""
        if handle.done:
            raise RuntimeError(f"{handle!r} was already answered or skipped")
        handle._done = True
        active, handle._active = handle._active, None
        if handle.obs.is_last_decision:
            self._last_answered.add(handle.uav)
        ports = self._ports
        try:
            if ports is None or not active.is_connected:
                self._late += 1
                return False
            n = len(data)
            response = active.loan_slice_uninit(n)
            ctypes.memmove(response.payload_ptr, bytes(data), n)
            response.assume_init().send()
            notifier = ports.notifiers.get(handle.uav)
            if notifier is not None:
                notifier.notify()
            self._answered[handle.uav] = self._answered.get(handle.uav, 0) + 1
            if planner_ns is not None:
                self._decide_ns.append(int(planner_ns))
            return True
        except Exception as e:  # noqa: BLE001 - an agent that left must not stop the planner
            if isinstance(e, (MemoryError, KeyboardInterrupt)):
                raise
            log.warning("cannot answer UAV %d's request of step %d: %s", handle.uav, handle.obs.step, e)
            self._late += 1
            return False
        finally:
            try:
                active.delete()
            except Exception:  # noqa: BLE001
                pass

    def skip(self, handle: RequestHandle) -> None:
        """Releases ``handle``'s request without answering: its agent falls back once its
        deadline passes."""
        if handle.done:
            return
        handle._done = True
        active, handle._active = handle._active, None
        if handle.obs.is_last_decision:
            self._last_answered.add(handle.uav)
        try:
            active.delete()
        except Exception:  # noqa: BLE001
            pass

    # ---- serving ---------------------------------------------------------------------------

    def serve(
        self,
        planner: Any,
        *,
        timeout: float | None = None,
        on_error: str = "raise",
    ) -> RunResult:
        """Answers every request of the served UAVs until the run ends; returns its result.

        ``planner`` is a :class:`~setfleet.Planner` (or a callable ``obs -> decision``) for
        every served UAV, or a mapping ``{uav: planner}`` covering each of them. Each
        planner's :meth:`~setfleet.Planner.reset` is called first. The planner's own time
        (its ``decide``) goes into each answer's ``planner_ns`` and into
        :attr:`RunResult.decide_ns`.

        A planner exception (or an invalid action) closes the run and is raised again
        (``on_error="raise"``); with ``on_error="fallback"`` it is logged, the request is
        left unanswered and the agent's fallback planner decides. ``timeout`` (wall seconds)
        closes the run and raises :class:`TimeoutError` when it passes."""
        if on_error not in ("raise", "fallback"):
            raise ValueError("on_error is 'raise' or 'fallback'")
        if isinstance(planner, Mapping):
            planners = {int(u): as_planner(p) for u, p in planner.items()}
            missing = [u for u in self.uavs if u not in planners]
            if missing:
                raise ValueError(f"no planner for served UAVs {missing}")
        else:
            one = as_planner(planner)
            planners = {u: one for u in self.uavs}
        for p in {id(p): p for p in planners.values()}.values():
            p.reset()
        end = None if timeout is None else time.monotonic() + timeout
        try:
            while True:
                wait = None if end is None else max(end - time.monotonic(), 0.0)
                req = self.next_request(timeout=wait)
                if req is None:
                    raise TimeoutError(f"the run did not end within {timeout} s")
                self._decide_and_answer(planners[req.uav], req, on_error)
        except RunEnded:
            pass
        except BaseException:
            self.close()
            raise
        return self.wait()

    def _decide_and_answer(self, planner: Planner, req: Request, on_error: str) -> None:
        t0 = time.perf_counter_ns()
        try:
            decision = planner.decide(req.obs)
            planner_ns = time.perf_counter_ns() - t0
            data = encode_answer(req.obs, as_action(decision), planner_ns)
        except Exception:
            if on_error == "raise":
                raise
            self._errors += 1
            log.exception("planner failed on UAV %d's request of step %d", req.uav, req.obs.step)
            self.skip(req.handle)
            return
        self.answer_bytes(req.handle, data, planner_ns)

    # ---- ending ----------------------------------------------------------------------------

    def _release_ports(self) -> None:
        for h in self._pending:
            self.skip(h)
        self._pending.clear()
        if self._ports is not None:
            self._ports.release()
            self._ports = None

    def wait(self, timeout: float | None = None) -> RunResult:
        """Releases the ports (agents still asking fall back at once) and waits for the run
        to end (the fleet process to exit; an attached run, for its summary, up to
        ``timeout``); returns its result. Raises :class:`subprocess.TimeoutExpired` if the
        process outlives ``timeout``."""
        self._release_ports()
        if self.process is not None:
            self.process.wait(timeout)
        else:
            end = None if timeout is None else time.monotonic() + timeout
            while not (self.out / "summary.json").exists():
                if end is not None and time.monotonic() >= end:
                    break
                time.sleep(0.1)
        self._close_logs()
        return self.result()

    def result(self) -> RunResult:
        """What the run left so far (``summary`` once the run wrote it)."""
        summary = None
        path = self.out / "summary.json"
        try:
            if path.stat().st_mtime >= self._started_wall - 1.0:
                summary = read_summary(self.out)
        except (OSError, ValueError):
            summary = None
        return RunResult(
            out=self.out,
            run_id=self.run_id,
            exit_code=self.returncode,
            summary=summary,
            decisions=sum(self._answered.values()),
            late=self._late,
            stale=self._stale,
            errors=self._errors,
            decide_ns=np.asarray(self._decide_ns, dtype=np.int64),
            answered=dict(self._answered),
        )

    def _close_logs(self) -> None:
        for f in (self._stdout, self._stderr):
            if f is not None:
                try:
                    f.close()
                except OSError:
                    pass
        self._stdout = self._stderr = None

    def close(self, timeout: float = 30.0) -> None:
        """Releases the ports, then stops the fleet process if it still runs: SIGTERM (the
        fleet stops its children itself), then, after ``timeout`` seconds, SIGKILL to its
        whole process group. Idempotent; an attached run's processes are left alone."""
        if self._closed:
            return
        self._closed = True
        self._release_ports()
        proc = self.process
        if proc is not None and proc.poll() is None:
            try:
                proc.send_signal(signal.SIGTERM)
                proc.wait(timeout)
            except subprocess.TimeoutExpired:
                log.warning("fleet did not stop within %.0f s of SIGTERM: killing it", timeout)
                try:
                    os.killpg(proc.pid, signal.SIGKILL)  # its own session: fleet and children
                except ProcessLookupError:
                    pass
                proc.wait()
            except ProcessLookupError:
                pass
        self._close_logs()

    def __enter__(self) -> "Run":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def __del__(self) -> None:
        try:
            if not self._closed:
                self.close(timeout=5.0)
        except Exception:  # noqa: BLE001 - interpreter shutdown
            pass

    def __repr__(self) -> str:
        state = "closed" if self._closed else ("ended" if self.returncode is not None else "running")
        return f"Run(run_id={self.run_id!r}, out={str(self.out)!r}, uavs={list(self.uavs)}, {state})"
