"""The in-process backend: a run of the fleet inside this process (``setfleet._native``).

:class:`SimRun` is the part of :class:`setfleet.Run` the environments use (``next_request``,
``answer``, ``skip``, ``wait``, ``close``), over one run of the fleet stepped in this process
by the compiled module instead of ``fleet run``'s processes: the same world, estimators,
exchange, token order and planners, the same request bytes (:class:`setfleet.Observation`
reads them), the same answer bytes, and the observer's own measurement, so for the same
scenario, seed and answers it writes the same ``timeseries.csv`` as ``fleet run``. It is
what ``SearchEnv(backend="sim")`` runs; the process backend stays the reference for
evaluation (docs/python.md, "Backends").

What it does not do: processes, IPC, faults, deadlines (the caller is always in time) and
the run's other outputs (only ``timeseries.csv`` and a short ``summary``).
"""

from __future__ import annotations

import os
from collections import deque
from pathlib import Path
from typing import Any, Iterable, Mapping

from .layout import Observation, as_action, encode_answer
from .run import Request, RequestHandle, RunEnded, RunResult

__all__ = ["SimRun", "native", "overrides_list"]


def native() -> Any:
    """The compiled module, or an :class:`ImportError` saying how to build it."""
    try:
        from . import _native
    except ImportError as e:  # pragma: no cover - depends on the installation
        raise ImportError(
            "setfleet's compiled module is missing: install the package with "
            "`pip install -e python` (it builds it with cargo)"
        ) from e
    return _native


def overrides_list(overrides: Iterable[str] | Mapping[str, Any]) -> list[str]:
    """``--set`` overrides as ``"key=value"`` strings."""
    if isinstance(overrides, Mapping):
        return [f"{k}={v}" for k, v in overrides.items()]
    return [str(o) for o in overrides]


def _summary(episode: Any) -> dict[str, Any]:
    """What a :class:`SimRun` knows of its run's ``summary.json`` keys."""
    asked, answered, malformed, deferred = episode.counts
    return {
        "backend": "sim",
        "steps": episode.step,
        "violations": episode.violations,
        "ua_final": episode.ua,
        "external": {"asked": asked, "answered": answered, "malformed": malformed,
                     "deferred": deferred},
    }


class SimRun:
    """One run of the fleet in this process whose ``external`` UAVs this process answers.

    Args: as :class:`setfleet.Run` (``scenario``, ``seed``, ``variant``, ``external``,
    ``duration``, ``out``, ``overrides``, ``uavs``); ``out`` (default: a new temporary
    directory, as ``Run``'s) receives ``timeseries.csv`` when the run ends (:meth:`wait`).
    """

    def __init__(
        self,
        scenario: str | os.PathLike[str] | None = None,
        seed: int = 1,
        variant: str = "paper",
        external: Iterable[int] = (0,),
        duration: float | None = None,
        out: str | os.PathLike[str] | None = None,
        overrides: Iterable[str] | Mapping[str, Any] = (),
        uavs: int | None = None,
    ) -> None:
        if out is None:
            import tempfile

            out = tempfile.mkdtemp(prefix="setfleet-sim-")
        self.out = Path(out)
        self.uavs = tuple(sorted({int(u) for u in external}))
        self.episode = native().Episode(
            None if scenario is None else str(scenario),
            variant,
            overrides_list(overrides),
            int(seed),
            None if duration is None else float(duration),
            None if uavs is None else int(uavs),
            list(self.uavs),
        )
        self._queue: deque[RequestHandle] = deque()
        self._closed = False

    def next_request(self, timeout: float | None = None) -> Request:
        """The next request to answer, as ``(uav, obs, handle)``: the run steps until one
        comes. Raises :class:`setfleet.RunEnded` once the run has taken its last step.
        ``timeout`` is accepted for :class:`setfleet.Run`'s signature: nothing is waited for."""
        if self._closed:
            raise RunEnded("the run is closed")
        while not self._queue:
            if not self.episode.run():
                raise RunEnded("the run is over")
            for uav, _step, data in self.episode.pending():
                self._queue.append(RequestHandle(uav, Observation(data), None))
        h = self._queue.popleft()
        return Request(h.uav, h.obs, h)

    def answer(self, handle: RequestHandle, action: Any, planner_ns: int = 0) -> bool:
        """Answers ``handle``'s request with ``action`` (anything :func:`~setfleet.as_action`
        takes), as :meth:`setfleet.Run.answer`."""
        return self.answer_bytes(handle, encode_answer(handle.obs, as_action(action), planner_ns))

    def answer_bytes(self, handle: RequestHandle, data: bytes, planner_ns: int | None = None) -> bool:
        """Answers with ``data`` unchecked; bytes the agent would refuse leave the decision
        to the UAV's own planner, as they do in a process run."""
        if handle.done:
            raise RuntimeError(f"{handle!r} was already answered or skipped")
        handle._done = True
        self.episode.answer(handle.uav, bytes(data))
        return True

    def skip(self, handle: RequestHandle) -> None:
        """Leaves ``handle``'s decision to the UAV's own planner (an agent's fallback)."""
        if not handle.done:
            self.answer_bytes(handle, b"")

    def wait(self, timeout: float | None = None) -> RunResult:
        """Runs to the end, every request left unanswered (their UAVs' own planners decide),
        writes ``timeseries.csv`` into ``out`` and returns the result."""
        while self._queue:
            self.skip(self._queue.popleft())
        while self.episode.run():
            for uav, _step, _data in self.episode.pending():
                self.episode.answer(uav, b"")
        self.out.mkdir(parents=True, exist_ok=True)
        (self.out / "timeseries.csv").write_text(self.episode.timeseries_csv())
        return self.result()

    def result(self) -> RunResult:
        """What the run measured so far."""
        summary = _summary(self.episode)
        return RunResult(
            out=self.out,
            run_id="sim",
            exit_code=0 if self.episode.finished else None,
            summary=summary,
            decisions=summary["external"]["answered"],
            errors=summary["external"]["malformed"],
        )

    def close(self, timeout: float = 30.0) -> None:
        """Drops the run."""
        self._closed = True
        self._queue.clear()

    def __enter__(self) -> "SimRun":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
