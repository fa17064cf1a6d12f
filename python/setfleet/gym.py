"""Gymnasium and PettingZoo environments over real fleet runs (extra ``gym``).

:class:`SearchEnv` is a :class:`gymnasium.Env` in which one UAV (the *learner*, UAV 0 by
default) takes its guidance decisions from the agent's actions while the other UAVs keep the
chosen variant's planner. :class:`ParallelSearchEnv` is a PettingZoo ``ParallelEnv`` with
several learning UAVs (agents ``uav_{i}``). Each ``reset`` starts a new run; each ``step``
answers the pending request(s) and waits for the next one: one guidance period.
:class:`setfleet.vector.SimVectorEnv` steps several runs at once (``gymnasium.vector``).

**Backends** (``backend=``): ``"process"`` (the default) starts ``fleet run``, the real
distributed fleet, and is the reference for evaluation; ``"sim"`` runs the same run inside this
process (:class:`setfleet.sim.SimRun`, the compiled ``setfleet._native``), without processes
or IPC. For the same seed and actions both give the same observations, rewards and
``timeseries.csv``: the same world, estimators, exchange, token order and planners, and the
same request and answer bytes.

**Observation** (per agent), a dict:

- ``"sets"``: ``Box(0, 1, (4, S, S), float32)``, the channels X̄ (undetected), the union of
  the cars' sets, H̄ (unseen) and the recently hidden ground, each as the fraction of each
  pixel covered. The pixels tile the whole planning grid (the region), row 0 at the south,
  column 0 at the west, area-resampled from the planning cells with exact area weights. The
  cars' union is the sum of their counts per planning cell clipped at a full cell (the counts
  cannot tell overlapping sets apart).
- ``"pose"``: ``Box(-inf, inf, (4,), float32)``: ``x / b``, ``y / b``, ``cos yaw``,
  ``sin yaw``, with ``b = border_half_m``, the half side of the square the plans stay in
  (the region's by default, the world's geofence a little inside it with
  ``guidance.border = "geofence"``: ``|x / b| <= 1`` for a UAV inside the border).

**Action**: ``Discrete(len(increments))``, the index of the yaw increment applied now
(default: the scenario's increments ``-π/3, -π/6, 0, π/6, π/3``). With ``defer=True`` one
more action, the last, defers the decision to the UAV's own planner (:class:`Actions`): a
policy that steps in only where it does better than the variant's planner.

**Reward** of a step: ``(w_ua * ΔX̄ + w_targets * ΔX) / (2b)²``, where ``ΔX̄`` is the decrease
of the agent's ``undetected_m2`` and ``ΔX`` that of its ``targets_m2`` between the request
answered and the next one, so a reward is a fraction of the planning square. The step that
answers the last decision (none is left before ``total_steps``) returns ``terminated=True``,
reward 0 and the last observation again, after the run finished (its outputs are then in
:attr:`SearchEnv.run_dir`, its :class:`~setfleet.RunResult` in ``last_result``).
``truncated`` is always False. ``info``: ``step``, ``time_s``, ``undetected_m2``,
``targets_m2`` of the request observed.

**Deadline**: the agent waits ``timing.external_planner_ms`` (1000 ms by default) for each
answer; an agent that calls ``step`` later than that loses the decision to the fallback planner.
``deadline_ms`` sets it for a learner that trains between its steps.

**Run directories**: with ``out_dir``, episode ``n`` runs in ``out_dir/episode-{n:05d}`` and is
kept; without, each run has a temporary directory removed at the next ``reset`` and at
``close``.
"""

from __future__ import annotations

import math
import os
import shutil
import tempfile
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

import gymnasium
import numpy as np
from gymnasium import spaces

from .layout import DEFAULT_INCREMENTS, Action, Observation, PlanGrid
from .run import Request, Run, RunEnded, RunResult
from .sim import SimRun, overrides_list

__all__ = [
    "SearchEnv",
    "ParallelSearchEnv",
    "SetsRaster",
    "Actions",
    "observe",
    "reward",
    "square_m2",
    "observation_space",
    "BACKENDS",
    "DEFAULT_INCREMENTS",
]

#: The environments' backends: ``"process"`` runs ``fleet run`` (the real distributed fleet,
#: the reference), ``"sim"`` the same run in this process (:class:`setfleet.sim.SimRun`).
BACKENDS = ("process", "sim")


def _overlap_matrix(n_in: int, origin: float, cell: float, lo: float, hi: float, n_out: int) -> np.ndarray:
    """``(n_out, n_in)`` weights: the share of output bin ``i`` (of ``n_out`` equal bins over
    ``[lo, hi]``) that input cell ``j`` (``[origin + j cell, origin + (j + 1) cell]``) covers."""
    edges_out = np.linspace(lo, hi, n_out + 1)
    edges_in = origin + np.arange(n_in + 1) * cell
    left = np.maximum(edges_out[:-1, None], edges_in[None, :-1])
    right = np.minimum(edges_out[1:, None], edges_in[None, 1:])
    width = (hi - lo) / n_out
    return (np.clip(right - left, 0.0, None) / width).astype(np.float32)


class SetsRaster:
    """Area resampling of planning rasters onto ``size × size`` pixels over the planning
    grid's extent; the weights are computed once per grid."""

    def __init__(self, size: int = 64) -> None:
        self.size = size
        self._grid: PlanGrid | None = None
        self._ry: np.ndarray | None = None
        self._rx: np.ndarray | None = None

    def _weights(self, plan: PlanGrid) -> tuple[np.ndarray, np.ndarray]:
        if plan != self._grid:
            x0, x1, y0, y1 = plan.extent
            self._ry = _overlap_matrix(plan.ny, plan.origin_y, plan.cell_m, y0, y1, self.size)
            self._rx = _overlap_matrix(plan.nx, plan.origin_x, plan.cell_m, x0, x1, self.size)
            self._grid = plan
        return self._ry, self._rx  # type: ignore[return-value]

    def __call__(self, fractions: np.ndarray, plan: PlanGrid) -> np.ndarray:
        """``fractions`` (``(ny, nx)``, each cell's covered fraction) as the covered
        fraction of each pixel, ``float32`` ``(size, size)`` in ``[0, 1]``."""
        ry, rx = self._weights(plan)
        out = ry @ fractions.astype(np.float32, copy=False) @ rx.T
        return np.clip(out, 0.0, 1.0, out=out)


def observe(obs: Observation, raster: SetsRaster) -> dict[str, np.ndarray]:
    """The environments' observation of a request (new arrays, valid after answering)."""
    b = obs.border_half_m if obs.border_half_m > 0 else max(abs(v) for v in obs.plan.extent)
    sets = np.empty((4, raster.size, raster.size), dtype=np.float32)
    for k, counts in enumerate(
        (obs.undetected, obs.targets_dense("sum"), obs.unseen, obs.recently_hidden)
    ):
        sets[k] = raster(obs.fraction(counts), obs.plan)
    pose = np.array(
        [obs.x / b, obs.y / b, math.cos(obs.yaw), math.sin(obs.yaw)], dtype=np.float32
    )
    return {"sets": sets, "pose": pose}


def square_m2(obs: Observation) -> float:
    """The area rewards are fractions of: the planning square ``(2b)²`` (1 without a border)."""
    b = obs.border_half_m
    return (2 * b) ** 2 if b > 0 else 1.0


def reward(prev: Observation, nxt: Observation, w_ua: float = 1.0, w_targets: float = 1.0) -> float:
    """The reward between two requests of a learner (the module's documentation)."""
    return float(
        (w_ua * (prev.undetected_m2 - nxt.undetected_m2) + w_targets * (prev.targets_m2 - nxt.targets_m2))
        / square_m2(prev)
    )


def _info(obs: Observation) -> dict[str, Any]:
    return {
        "step": obs.step,
        "time_s": obs.time_s,
        "undetected_m2": obs.undetected_m2,
        "targets_m2": obs.targets_m2,
    }


def _copy_obs(o: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    return {k: v.copy() for k, v in o.items()}


class _Episodes:
    """Starting, numbering and cleaning up the runs of an environment."""

    def __init__(
        self,
        *,
        learners: Sequence[int],
        variant: str,
        scenario: str | os.PathLike[str] | None,
        uavs: int | None,
        duration: float | None,
        overrides: Iterable[str] | Mapping[str, Any],
        deadline_ms: int | None,
        fleet: str | os.PathLike[str] | None,
        out_dir: str | os.PathLike[str] | None,
        extra_overrides: Sequence[str] = (),
        extra_args: Sequence[str] = (),
        connect_timeout: float = 60.0,
        backend: str = "process",
    ) -> None:
        if backend not in BACKENDS:
            raise ValueError(f"backend: one of {BACKENDS}, not {backend!r}")
        if backend == "sim" and extra_args:
            raise ValueError("extra_args are fleet run's: the sim backend takes none")
        self.backend = backend
        self.overrides = overrides_list(overrides) + list(extra_overrides)
        if deadline_ms is not None:
            self.overrides.append(f"timing.external_planner_ms={int(deadline_ms)}")
        self.learners = list(learners)
        self.variant = variant
        self.scenario = scenario
        self.uavs = uavs
        self.duration = duration
        self.fleet = fleet
        self.out_dir = None if out_dir is None else Path(out_dir)
        self.extra_args = list(extra_args)
        self.connect_timeout = connect_timeout
        self.count = 0
        self.run: Run | SimRun | None = None
        self.run_dir: Path | None = None
        self._temp: Path | None = None

    def start(self, seed: int) -> Run | SimRun:
        self.stop()
        self._remove_temp()
        if self.out_dir is not None:
            out = self.out_dir / f"episode-{self.count:05d}"
        else:
            self._temp = Path(tempfile.mkdtemp(prefix="setfleet-episode-"))
            out = self._temp
        self.count += 1
        self.run_dir = out
        common = dict(
            scenario=self.scenario,
            seed=seed,
            variant=self.variant,
            external=self.learners,
            duration=self.duration,
            out=out,
            overrides=self.overrides,
            uavs=self.uavs,
        )
        if self.backend == "sim":
            self.run = SimRun(**common)
            return self.run
        self.run = Run(
            **common,
            fleet=self.fleet,
            extra_args=self.extra_args,
            connect_timeout=self.connect_timeout,
        )
        return self.run

    def finish(self) -> RunResult | None:
        """Lets the run end on its own (the agents take any decision left) and closes it."""
        if self.run is None:
            return None
        try:
            result = self.run.wait()
        finally:
            self.run.close()
            self.run = None
        return result

    def stop(self) -> None:
        if self.run is not None:
            self.run.close()
            self.run = None

    def _remove_temp(self) -> None:
        if self._temp is not None:
            shutil.rmtree(self._temp, ignore_errors=True)
            self._temp = None

    def close(self) -> None:
        self.stop()
        self._remove_temp()


def observation_space(size: int) -> spaces.Dict:
    """One agent's observation space (the module's documentation)."""
    return spaces.Dict(
        {
            "sets": spaces.Box(0.0, 1.0, (4, size, size), np.float32),
            "pose": spaces.Box(-np.inf, np.inf, (4,), np.float32),
        }
    )


def _checked_increments(increments: Sequence[float]) -> tuple[float, ...]:
    """The actions' yaw increments: at least one, each in [-pi, pi]."""
    checked = tuple(float(u) for u in increments)
    if not checked or any(not -math.pi <= u <= math.pi for u in checked):
        raise ValueError("increments: at least one, each in [-pi, pi]")
    return checked


class Actions:
    """The environments' discrete actions: index ``k < len(increments)`` turns by
    ``increments[k]`` now; with ``defer``, one more index, ``len(increments)``, defers to the
    UAV's own planner (:meth:`setfleet.Action.deferred`: the variant's planner decides, at
    once, as if the UAV had no external planner)."""

    def __init__(self, increments: Sequence[float], defer: bool = False) -> None:
        self.increments = _checked_increments(increments)
        self.defer = bool(defer)

    @property
    def n(self) -> int:
        """How many actions."""
        return len(self.increments) + int(self.defer)

    def space(self) -> spaces.Discrete:
        """``Discrete(n)``."""
        return spaces.Discrete(self.n)

    def action(self, index: Any) -> Action:
        """The :class:`setfleet.Action` of action ``index``."""
        k = int(index)
        if not 0 <= k < self.n:
            raise ValueError(f"action {k} outside 0..{self.n - 1}")
        return Action.deferred() if k == len(self.increments) else Action.turn(self.increments[k])


def _draw_seed(rng: np.random.Generator) -> int:
    return int(rng.integers(1, 2**31 - 1))


class _FleetEnv:
    """What both environments share: their settings, their runs, the reward."""

    def _setup(
        self,
        learners: Sequence[int],
        actions: Actions,
        size: int,
        w_ua: float,
        w_targets: float,
        request_timeout: float,
        **episodes: Any,
    ) -> None:
        self.actions = actions
        self.w_ua, self.w_targets = float(w_ua), float(w_targets)
        self.request_timeout = request_timeout
        self._raster = SetsRaster(size)
        self._episodes = _Episodes(learners=learners, **episodes)
        self.last_result: RunResult | None = None

    @property
    def increments(self) -> tuple[float, ...]:
        """The actions' yaw increments, rad."""
        return self.actions.increments

    @property
    def run(self) -> Run | SimRun | None:
        """The current episode's run."""
        return self._episodes.run

    @property
    def run_dir(self) -> Path | None:
        """The current (or last) episode's output directory."""
        return self._episodes.run_dir

    def _reward(self, prev: Observation, nxt: Observation) -> float:
        """The reward between two requests of a learner (the module's documentation)."""
        return reward(prev, nxt, self.w_ua, self.w_targets)


class SearchEnv(_FleetEnv, gymnasium.Env):
    """One learning UAV in a fleet run (see the module's documentation for the spaces, the
    reward and the episode's end).

    Args:
        learner: the UAV the agent flies (its decisions come from :meth:`step`).
        variant: the other UAVs' planner (and the learner's fallback).
        scenario, uavs, duration, overrides, fleet: as :class:`setfleet.Run`; keep runs small
            and short for tests (e.g. ``overrides=["region.half_extent_m=150"]``, ``uavs=2``,
            ``duration=30``).
        increments: the yaw increments of the actions, rad.
        defer: one more action, the last, that defers to the UAV's own planner
            (:class:`Actions`).
        size: side ``S`` of the ``"sets"`` rasters.
        w_ua, w_targets: weights of the decrease of X̄ and of the cars' sets in the reward.
        deadline_ms: ``timing.external_planner_ms`` of the runs (default: the scenario's).
        out_dir: where runs are kept (default: temporary directories, see the module's doc).
        request_timeout: longest wait for a request, s (start-up included).
        backend: ``"process"`` (``fleet run``'s processes, the default and the reference) or
            ``"sim"`` (the same run in this process; ``fleet`` and ``extra_args`` unused).
    """

    metadata = {"render_modes": []}

    def __init__(
        self,
        *,
        learner: int = 0,
        variant: str = "paper",
        scenario: str | os.PathLike[str] | None = None,
        uavs: int | None = None,
        duration: float | None = None,
        overrides: Iterable[str] | Mapping[str, Any] = (),
        increments: Sequence[float] = DEFAULT_INCREMENTS,
        defer: bool = False,
        size: int = 64,
        w_ua: float = 1.0,
        w_targets: float = 1.0,
        deadline_ms: int | None = None,
        fleet: str | os.PathLike[str] | None = None,
        out_dir: str | os.PathLike[str] | None = None,
        request_timeout: float = 120.0,
        extra_args: Sequence[str] = (),
        backend: str = "process",
    ) -> None:
        super().__init__()
        self.learner = int(learner)
        self._setup(
            [self.learner],
            Actions(increments, defer),
            size,
            w_ua,
            w_targets,
            request_timeout,
            variant=variant,
            scenario=scenario,
            uavs=uavs,
            duration=duration,
            overrides=overrides,
            deadline_ms=deadline_ms,
            fleet=fleet,
            out_dir=out_dir,
            extra_args=extra_args,
            backend=backend,
        )
        self.observation_space = observation_space(size)
        self.action_space = self.actions.space()
        self._pending: Request | None = None
        self._last: dict[str, np.ndarray] | None = None
        self._last_info: dict[str, Any] | None = None

    def _next(self, run: Run) -> Request | None:
        try:
            req = run.next_request(timeout=self.request_timeout)
        except RunEnded:
            return None
        if req is None:
            raise TimeoutError(f"no request from UAV {self.learner} within {self.request_timeout} s")
        return req

    def _take(self, req: Request) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        obs = observe(req.obs, self._raster)
        info = _info(req.obs)
        self._pending = req
        self._last, self._last_info = obs, info
        return obs, info

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """Starts a new run (seeded by ``seed``, else drawn from the environment's generator)
        and returns the learner's first observation and its info."""
        super().reset(seed=seed)
        self._pending = None
        run_seed = int(seed) if seed is not None else _draw_seed(self.np_random)
        run = self._episodes.start(run_seed)
        req = self._next(run)
        if req is None:
            raise RuntimeError(
                f"the run ended before UAV {self.learner}'s first decision: "
                f"see {self._episodes.run_dir}/fleet.stderr.log"
            )
        obs, info = self._take(req)
        return _copy_obs(obs), dict(info)

    def step(self, action: Any) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        """Answers the pending request with action ``action`` (:class:`Actions`) and waits for
        the learner's next request (one guidance period)."""
        req = self._pending
        run = self._episodes.run
        if req is None or run is None:
            raise RuntimeError("step() needs a reset() first (or the episode terminated)")
        prev = req.obs  # its scalars stay valid once answered; its arrays are not read
        last = prev.is_last_decision
        self._pending = None
        run.answer(req.handle, self.actions.action(action))
        nxt = None if last else self._next(run)
        if nxt is None:
            self.last_result = self._episodes.finish()
            assert self._last is not None and self._last_info is not None
            return _copy_obs(self._last), 0.0, True, False, dict(self._last_info)
        obs, info = self._take(nxt)
        return _copy_obs(obs), self._reward(prev, nxt.obs), False, False, dict(info)

    def close(self) -> None:
        """Stops any run and removes temporary run directories."""
        self._pending = None
        self._episodes.close()
        super().close()


try:
    from pettingzoo import ParallelEnv as _ParallelEnv
except ImportError:  # pragma: no cover - pettingzoo is optional
    _ParallelEnv = object  # type: ignore[misc,assignment]


class ParallelSearchEnv(_FleetEnv, _ParallelEnv):  # type: ignore[misc,valid-type]
    """Several learning UAVs in a fleet run, as a PettingZoo ``ParallelEnv``: agents
    ``uav_{i}`` for ``i`` in ``learners``, the others on ``variant``'s planner.

    The runs ask at the start of each round (``guidance.external_request=round_start``), so
    every learner's request of a round exists before any of them acts; :meth:`step` answers
    them all and waits for the next round's. Spaces, reward and ending are
    :class:`SearchEnv`'s, per agent (each agent's reward from its own requests). Every agent
    terminates together, at the last round.
    """

    metadata = {"name": "setfleet_parallel_v0", "render_modes": []}

    def __init__(
        self,
        *,
        learners: Sequence[int] = (0, 1),
        variant: str = "paper",
        scenario: str | os.PathLike[str] | None = None,
        uavs: int | None = None,
        duration: float | None = None,
        overrides: Iterable[str] | Mapping[str, Any] = (),
        increments: Sequence[float] = DEFAULT_INCREMENTS,
        defer: bool = False,
        size: int = 64,
        w_ua: float = 1.0,
        w_targets: float = 1.0,
        deadline_ms: int | None = None,
        fleet: str | os.PathLike[str] | None = None,
        out_dir: str | os.PathLike[str] | None = None,
        request_timeout: float = 120.0,
        extra_args: Sequence[str] = (),
        backend: str = "process",
    ) -> None:
        self.learners = tuple(sorted({int(u) for u in learners}))
        if not self.learners:
            raise ValueError("at least one learner")
        self.possible_agents = [f"uav_{u}" for u in self.learners]
        self.agents: list[str] = []
        self._uav_of = {f"uav_{u}": u for u in self.learners}
        self._setup(
            self.learners,
            Actions(increments, defer),
            size,
            w_ua,
            w_targets,
            request_timeout,
            variant=variant,
            scenario=scenario,
            uavs=uavs,
            duration=duration,
            overrides=overrides,
            deadline_ms=deadline_ms,
            fleet=fleet,
            out_dir=out_dir,
            extra_overrides=["guidance.external_request=round_start"],
            extra_args=extra_args,
            backend=backend,
        )
        self._observation_space = observation_space(size)
        self.observation_spaces = {a: self._observation_space for a in self.possible_agents}
        self.action_spaces = {a: self.actions.space() for a in self.possible_agents}
        self._rng = np.random.default_rng()
        self._pending: dict[str, Request] = {}
        self._last: dict[str, tuple[dict[str, np.ndarray], dict[str, Any]]] = {}

    def observation_space(self, agent: str) -> spaces.Space:
        return self.observation_spaces[agent]

    def action_space(self, agent: str) -> spaces.Space:
        return self.action_spaces[agent]

    def _collect(self, run: Run, after: dict[int, int]) -> dict[int, Request] | None:
        """One request of every learner, each of a later step than ``after[uav]``; ``None``
        if the run ended first."""
        got: dict[int, Request] = {}
        while len(got) < len(self.learners):
            try:
                req = run.next_request(timeout=self.request_timeout)
            except RunEnded:
                for r in got.values():
                    run.skip(r.handle)
                return None
            if req is None:
                raise TimeoutError(f"no request within {self.request_timeout} s")
            if req.uav not in self._uav_of.values() or req.obs.step <= after.get(req.uav, -1):
                run.skip(req.handle)
                continue
            old = got.get(req.uav)
            if old is not None:
                run.skip(old.handle)
            got[req.uav] = req
        return got

    def _take(self, got: dict[int, Request]) -> tuple[dict[str, Any], dict[str, Any]]:
        obs, infos = {}, {}
        self._pending = {}
        for uav, req in got.items():
            agent = f"uav_{uav}"
            o, i = observe(req.obs, self._raster), _info(req.obs)
            self._pending[agent] = req
            self._last[agent] = (o, i)
            obs[agent], infos[agent] = _copy_obs(o), dict(i)
        return obs, infos

    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, Any], dict[str, Any]]:
        """Starts a new run and returns every learner's first observation and info."""
        if seed is not None:
            self._rng = np.random.default_rng(seed)
        run_seed = int(seed) if seed is not None else _draw_seed(self._rng)
        self._pending = {}
        self._last = {}
        run = self._episodes.start(run_seed)
        got = self._collect(run, {})
        if got is None:
            raise RuntimeError(f"the run ended before the first round: see {self._episodes.run_dir}")
        self.agents = self.possible_agents[:]
        return self._take(got)

    def step(
        self, actions: Mapping[str, Any]
    ) -> tuple[dict[str, Any], dict[str, float], dict[str, bool], dict[str, bool], dict[str, Any]]:
        """Answers every live learner's request (a learner without an action keeps its yaw:
        increment 0 if the increments hold one, else the first) and waits for the next round."""
        run = self._episodes.run
        if run is None or not self.agents:
            raise RuntimeError("step() needs a reset() first (or the episode terminated)")
        default = self.increments.index(0.0) if 0.0 in self.increments else 0
        prev = {a: r.obs for a, r in self._pending.items()}  # scalars only, after answering
        last = any(o.is_last_decision for o in prev.values())
        for agent, req in self._pending.items():
            a = actions.get(agent, default)
            run.answer(req.handle, self.actions.action(a))
        self._pending = {}
        got = None if last else self._collect(run, {self._uav_of[a]: o.step for a, o in prev.items()})
        agents = self.agents
        if got is None:
            self.last_result = self._episodes.finish()
            obs = {a: _copy_obs(self._last[a][0]) for a in agents}
            infos = {a: dict(self._last[a][1]) for a in agents}
            self.agents = []
            return (
                obs,
                {a: 0.0 for a in agents},
                {a: True for a in agents},
                {a: False for a in agents},
                infos,
            )
        obs, infos = self._take(got)
        rewards = {a: self._reward(prev[a], self._pending[a].obs) for a in agents}
        return (
            obs,
            rewards,
            {a: False for a in agents},
            {a: False for a in agents},
            infos,
        )

    def render(self) -> None:
        """No rendering: a run's pictures are in its output directory."""
        return None

    def close(self) -> None:
        """Stops any run and removes temporary run directories."""
        self._pending = {}
        self.agents = []
        self._episodes.close()
