"""Vectorised learning: several in-process runs stepped in one call (``gymnasium.vector``).

:class:`SimVectorEnv` is a :class:`gymnasium.vector.VectorEnv` of ``num_envs`` copies of
:class:`setfleet.gym.SearchEnv` on the in-process backend (``backend="sim"``): the same
spaces, reward and ending per environment, each episode with its own seed. A ``step``
answers every environment's request, then the compiled module steps all the runs to their
next request at once, over ``threads`` threads with the GIL released
(``setfleet._native.run_many``); the observations are then built here, as ``SearchEnv``
builds them.

**Autoreset**: ``AutoresetMode.NEXT_STEP``, gymnasium's default: the step after an episode
ended starts that environment's next episode, ignores its action and returns the new
episode's first observation with reward 0, ``terminated`` and ``truncated`` False.

**Seeds**: ``reset(seed=s)`` seeds episode ``i``'s run with ``s + i`` and the generator that
draws the seeds of later episodes from ``seed_range`` (inclusive); ``reset()`` draws them all
from the generator (seeded by the constructor's ``seed``).

**Baseline** (``baseline=True``): each step's reward less the reward of the same step in
the run of the same seed where the learner defers every decision (the variant alone: the
same world, every UAV on the variant's planner). That run is stepped beside the episode's,
the first time its seed comes, and its values are kept for the seed's later episodes. A
policy that always defers then earns 0 at every step, and an episode's return is what the
learner gained over the variant in the reward's terms: the seed's own luck (how many cars,
where) cancels out. It costs a second run per new seed.

**Info** (arrays of ``num_envs``, each with its ``_key`` mask): ``step``, ``time_s``,
``undetected_m2`` and ``targets_m2`` of each observation (``SearchEnv``'s info), ``ua`` (the
fleet's mean undetected fraction at the run's last measured step), ``violations`` (guarantee
violations of the episode so far) and ``seed`` (the episode's run seed).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

import gymnasium
import numpy as np
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space

from .gym import Actions, SetsRaster, _info, observation_space, observe, reward, square_m2
from .layout import DEFAULT_INCREMENTS, Action, Observation, encode_answer
from .sim import native, overrides_list

__all__ = ["SimVectorEnv"]

_INFO_KEYS = ("step", "time_s", "undetected_m2", "targets_m2", "ua", "violations", "seed")


class _Slot:
    """One environment of the vector: its run, its pending request, its last observation,
    and the baseline's run beside it (``shadow``, while its values are being measured)."""

    __slots__ = ("episode", "seed", "request", "obs", "last", "done", "shadow", "shadow_values")

    def __init__(self) -> None:
        self.episode: Any = None
        self.seed = 0
        self.request: tuple[int, Observation] | None = None
        self.obs: dict[str, np.ndarray] | None = None
        self.last: Observation | None = None
        self.done = False
        self.shadow: Any = None
        self.shadow_values: dict[int, float] = {}


class SimVectorEnv(gymnasium.vector.VectorEnv):
    """``num_envs`` in-process runs with one learning UAV each (see the module's
    documentation).

    Args:
        num_envs: how many runs.
        learner, variant, scenario, uavs, duration, overrides, increments, defer, size, w_ua,
            w_targets: as :class:`setfleet.gym.SearchEnv`.
        baseline: rewards relative to the variant's own run of the same seed (the module's
            documentation).
        threads: threads that step the runs (default: the machine's CPUs).
        seed_range: the range (inclusive) later episodes' seeds are drawn from.
        seed: seeds the generator that draws them (``reset(seed=...)`` reseeds it).
    """

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": []}

    def __init__(
        self,
        num_envs: int = 1,
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
        baseline: bool = False,
        threads: int | None = None,
        seed_range: tuple[int, int] = (1, 2**31 - 2),
        seed: int | None = None,
    ) -> None:
        if num_envs < 1:
            raise ValueError("num_envs: at least 1")
        lo, hi = (int(v) for v in seed_range)
        if not 0 <= lo <= hi:
            raise ValueError("seed_range: 0 <= low <= high")
        self._native = native()
        self.num_envs = int(num_envs)
        self.learner = int(learner)
        self.variant = variant
        self.scenario = None if scenario is None else str(Path(scenario))
        self.uavs = uavs
        self.duration = duration
        self.overrides = overrides_list(overrides)
        self.actions = Actions(increments, defer)
        self.w_ua, self.w_targets = float(w_ua), float(w_targets)
        self.baseline = bool(baseline)
        #: The baseline's values per seed: ``{step: w_ua undetected_m2 + w_targets targets_m2}``.
        self._baselines: dict[int, dict[int, float]] = {}
        self.threads = int(threads) if threads is not None else (os.cpu_count() or 1)
        self.seed_range = (lo, hi)
        self._raster = SetsRaster(size)
        self.single_observation_space = observation_space(size)
        self.single_action_space = self.actions.space()
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._slots = [_Slot() for _ in range(self.num_envs)]
        self._rng = np.random.default_rng(seed)

    @property
    def increments(self) -> tuple[float, ...]:
        """The actions' yaw increments, rad."""
        return self.actions.increments

    # ---- the runs ----------------------------------------------------------------------

    def _episode(self, seed: int) -> Any:
        return self._native.Episode(
            self.scenario,
            self.variant,
            self.overrides,
            seed,
            self.duration,
            self.uavs,
            [self.learner],
        )

    def _start(self, slot: _Slot, seed: int) -> None:
        slot.seed = int(seed)
        slot.episode = self._episode(slot.seed)
        slot.request, slot.obs, slot.last, slot.done = None, None, None, False
        measured = not self.baseline or slot.seed in self._baselines
        slot.shadow = None if measured else self._episode(slot.seed)
        slot.shadow_values = {}

    def _value(self, obs: Observation) -> float:
        """What the reward counts the decrease of, m²."""
        return self.w_ua * obs.undetected_m2 + self.w_targets * obs.targets_m2

    def _draw_seed(self) -> int:
        return int(self._rng.integers(self.seed_range[0], self.seed_range[1] + 1))

    def _run(self, slots: list[_Slot]) -> None:
        """Steps the runs of ``slots`` to their learner's next request, all at once; a run
        that ended is marked done."""
        if not slots:
            return
        shadows = [s for s in slots if s.shadow is not None]
        asking = self._native.run_many(
            [s.episode for s in slots] + [s.shadow for s in shadows], self.threads
        )
        for slot, asks in zip(shadows, asking[len(slots):]):
            self._shadow_step(slot, asks)
        for slot, asks in zip(slots, asking[: len(slots)]):
            if not asks:
                slot.request, slot.done = None, True
                continue
            pending = slot.episode.pending()
            if len(pending) != 1 or pending[0][0] != self.learner:
                raise RuntimeError(f"expected one request of UAV {self.learner}, got {len(pending)}")
            obs = Observation(pending[0][2])
            slot.request = (self.learner, obs)
            slot.obs = observe(obs, self._raster)
            slot.last = obs

    def _shadow_step(self, slot: _Slot, asks: bool) -> None:
        """Records the baseline run's value at its learner's request and defers the decision;
        keeps the seed's values once that run ended."""
        if not asks:
            self._baselines[slot.seed] = slot.shadow_values
            slot.shadow, slot.shadow_values = None, {}
            return
        ((uav, _step, data),) = slot.shadow.pending()
        obs = Observation(data)
        slot.shadow_values[obs.step] = self._value(obs)
        slot.shadow.answer(uav, encode_answer(obs, Action.deferred()))

    def _baseline_reward(self, slot: _Slot, prev: Observation, nxt: Observation) -> float:
        """The baseline run's reward between the steps of ``prev`` and ``nxt``."""
        values = self._baselines.get(slot.seed, slot.shadow_values)
        try:
            drop = values[prev.step] - values[nxt.step]
        except KeyError as e:
            raise RuntimeError(f"the baseline run of seed {slot.seed} has no request at step {e}") from None
        return drop / square_m2(prev)

    def _answer(self, slot: _Slot, action: Any) -> Observation:
        assert slot.request is not None
        uav, obs = slot.request
        data = encode_answer(obs, self.actions.action(action))
        slot.episode.answer(uav, data)
        slot.request = None
        return obs

    # ---- the vector API ----------------------------------------------------------------

    def reset(
        self, *, seed: int | Sequence[int] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """Starts a new episode in every environment (seeds as the module's documentation
        says) and returns their first observations and infos."""
        if isinstance(seed, int):
            self._rng = np.random.default_rng(seed)
            seeds = [seed + i for i in range(self.num_envs)]
        elif seed is not None:
            seeds = [int(s) for s in seed]
            if len(seeds) != self.num_envs:
                raise ValueError(f"{len(seeds)} seeds for {self.num_envs} environments")
        else:
            seeds = [self._draw_seed() for _ in range(self.num_envs)]
        for slot, s in zip(self._slots, seeds):
            self._start(slot, s)
        self._run(self._slots)
        for i, slot in enumerate(self._slots):
            if slot.done:
                raise RuntimeError(f"environment {i}'s run ended before its first decision")
        return self._batch(), self._infos()

    def step(
        self, actions: Any
    ) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Answers every environment's request with its action (an environment whose episode
        ended at the last step starts its next one instead) and steps every run to its next
        request."""
        actions = np.asarray(actions)
        rewards = np.zeros(self.num_envs, dtype=np.float64)
        terminated = np.zeros(self.num_envs, dtype=np.bool_)
        prev: dict[int, Observation] = {}
        for i, slot in enumerate(self._slots):
            if slot.done:
                self._start(slot, self._draw_seed())
            elif slot.request is None:
                raise RuntimeError("step() needs a reset() first")
            else:
                prev[i] = self._answer(slot, actions[i])
        self._run(self._slots)
        for i, slot in enumerate(self._slots):
            if i not in prev:
                if slot.done:
                    raise RuntimeError(f"environment {i}'s run ended before its first decision")
                continue
            if slot.done:
                terminated[i] = True
            else:
                assert slot.last is not None
                rewards[i] = reward(prev[i], slot.last, self.w_ua, self.w_targets)
                if self.baseline:
                    rewards[i] -= self._baseline_reward(slot, prev[i], slot.last)
        return self._batch(), rewards, terminated, np.zeros(self.num_envs, dtype=np.bool_), self._infos()

    def _batch(self) -> dict[str, np.ndarray]:
        return {
            key: np.stack([slot.obs[key] for slot in self._slots])  # type: ignore[index]
            for key in ("sets", "pose")
        }

    def _infos(self) -> dict[str, Any]:
        infos: dict[str, Any] = {}
        rows = []
        for slot in self._slots:
            assert slot.last is not None
            row = _info(slot.last)
            ua = slot.episode.ua
            row.update(ua=np.nan if ua is None else ua, violations=slot.episode.violations, seed=slot.seed)
            rows.append(row)
        for key in _INFO_KEYS:
            infos[key] = np.array([row[key] for row in rows])
            infos[f"_{key}"] = np.ones(self.num_envs, dtype=np.bool_)
        return infos

    def close_extras(self, **kwargs: Any) -> None:
        """Drops the runs."""
        for slot in self._slots:
            slot.episode = slot.shadow = None
