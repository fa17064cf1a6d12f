"""The in-process backend against the process backend, and the vectorised environment.

The sim backend must be the same run as ``fleet run``: for the same seed and actions, the
same observations (bit for bit), rewards, infos and ``timeseries.csv`` (the test against the
real ``fleet`` binary). Both pass Gymnasium's and PettingZoo's API checks, and
``SimVectorEnv``'s environment ``i`` runs exactly as a ``SearchEnv(backend="sim")`` seeded
``seed + i`` given the same actions.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from conftest import SMALL, SMALL_UAVS, check_search_env, real_fleet_or_skip

pytest.importorskip("setfleet._native", reason="the compiled module is built by `pip install -e python`")

from gymnasium.spaces import Discrete  # noqa: E402

from setfleet.gym import ParallelSearchEnv, SearchEnv, observation_space  # noqa: E402
from setfleet.vector import SimVectorEnv  # noqa: E402

SIM_KW = dict(uavs=SMALL_UAVS, overrides=SMALL, size=32)
ENV_KW = dict(SIM_KW, deadline_ms=2000)


def actions(seed: int, n: int, k: int = 5) -> list[int]:
    return [int(a) for a in np.random.default_rng(seed).integers(0, k, n)]


def play(env: SearchEnv, seed: int, acts: list[int]) -> list[tuple]:
    """Every (observation, reward, terminated, info) of an episode flown with ``acts``."""
    obs, info = env.reset(seed=seed)
    out = [(obs, 0.0, False, info)]
    for a in acts:
        obs, reward, terminated, truncated, info = env.step(a)
        assert not truncated
        out.append((obs, reward, terminated, info))
        if terminated:
            break
    return out


def assert_same_episode(a: list[tuple], b: list[tuple]) -> None:
    assert len(a) == len(b)
    for n, ((oa, ra, ta, ia), (ob, rb, tb, ib)) in enumerate(zip(a, b)):
        for key in ("sets", "pose"):
            assert oa[key].dtype == ob[key].dtype
            assert np.array_equal(oa[key], ob[key]), f"step {n}: {key} differs"
        assert ra == rb, f"step {n}: reward {ra} != {rb}"
        assert ta == tb and ia == ib, f"step {n}"


def test_the_backends_give_the_same_episode_and_timeseries(tmp_path: Path):
    # Action 5 defers to the UAV's own planner: both backends decide by it at once.
    fleet = real_fleet_or_skip()
    acts = actions(1, 20, k=6)
    episodes, dirs, results = [], [], []
    for backend in ("process", "sim"):
        kw = dict(fleet=fleet) if backend == "process" else {}
        env = SearchEnv(duration=30, backend=backend, out_dir=tmp_path / backend, defer=True,
                        **ENV_KW, **kw)
        assert env.action_space == Discrete(6)
        try:
            episodes.append(play(env, 5, acts))
            dirs.append(env.run_dir)
            assert episodes[-1][-1][2], "the episode ended"
            assert env.last_result is not None and env.last_result.violations == 0
            results.append(env.last_result)
        finally:
            env.close()
    assert_same_episode(*episodes)
    answered = acts[: len(episodes[0]) - 1]
    assert 0 < answered.count(5) < len(answered)
    process, sim = results
    assert process.agent(0)["external_decisions"] == len(answered)
    assert process.agent(0)["external_fallbacks"] == 0
    assert sim.summary["external"]["deferred"] == answered.count(5)
    process_csv, sim_csv = ((d / "timeseries.csv").read_text() for d in dirs)
    assert process_csv.count("\n") == 61  # header and 60 steps
    assert sim_csv == process_csv


def test_the_backends_give_the_same_parallel_episode():
    fleet = real_fleet_or_skip()
    runs = []
    for backend in ("process", "sim"):
        kw = dict(fleet=fleet) if backend == "process" else {}
        env = ParallelSearchEnv(
            learners=(0, 2), uavs=3, duration=12, overrides=SMALL, size=16, deadline_ms=2000,
            backend=backend, **kw,
        )
        try:
            obs, _ = env.reset(seed=8)
            steps = [obs]
            rng = np.random.default_rng(2)
            while env.agents:
                acts = {a: int(rng.integers(0, 5)) for a in env.agents}
                obs, rewards, terms, truncs, infos = env.step(acts)
                steps.append((obs, rewards, terms, infos))
            runs.append(steps)
        finally:
            env.close()
    a, b = runs
    assert len(a) == len(b) == 5
    for sa, sb in zip(a, b):
        oa, ob = (sa, sb) if isinstance(sa, dict) else (sa[0], sb[0])
        for agent in oa:
            for key in ("sets", "pose"):
                assert np.array_equal(oa[agent][key], ob[agent][key])
        if not isinstance(sa, dict):
            assert sa[1:] == sb[1:]


def test_the_sim_search_env_passes_check_env():
    check_search_env(SearchEnv(duration=12, backend="sim", **ENV_KW))


def test_the_sim_parallel_env_passes_the_api_test():
    from pettingzoo.test import parallel_api_test

    env = ParallelSearchEnv(
        learners=(0, 2), uavs=3, duration=12, overrides=SMALL, size=16, backend="sim"
    )
    try:
        parallel_api_test(env, num_cycles=8)
    finally:
        env.close()


def test_an_episode_of_the_sim_backend_ends_with_its_timeseries(tmp_path: Path):
    env = SearchEnv(duration=30, backend="sim", out_dir=tmp_path, **ENV_KW)
    try:
        episode = play(env, 3, actions(3, 20))
        assert len(episode) == 11 and episode[-1][2]
        result = env.last_result
        assert result is not None and result.violations == 0
        assert result.summary["external"] == {"asked": 10, "answered": 10, "malformed": 0, "deferred": 0}
        rows = result.timeseries()
        assert len(rows["step"]) == 60 and int(np.sum(rows["violations"])) == 0
    finally:
        env.close()


def test_the_sim_backend_refuses_what_it_cannot_take():
    with pytest.raises(ValueError, match="backend"):
        SearchEnv(backend="threads", **ENV_KW)
    with pytest.raises(ValueError, match="extra_args"):
        SearchEnv(backend="sim", extra_args=["--strict"], **ENV_KW)
    env = SearchEnv(backend="sim", uavs=2, overrides=["region.half_extent_m=-5"])
    with pytest.raises(ValueError, match="half_extent_m"):
        env.reset(seed=1)
    env.close()
    env = SearchEnv(backend="sim", variant="fastest", **ENV_KW)
    with pytest.raises(ValueError, match="variant"):
        env.reset(seed=1)
    env.close()


def test_the_vector_env_runs_each_environment_as_a_single_one():
    seed, n = 20, 3
    acts = [actions(100 + i, 12) for i in range(n)]
    alone = []
    for i in range(n):
        env = SearchEnv(duration=30, backend="sim", **SIM_KW)
        try:
            alone.append(play(env, seed + i, acts[i]))
        finally:
            env.close()
    venv = SimVectorEnv(n, duration=30, threads=2, **SIM_KW)
    try:
        assert venv.single_observation_space == observation_space(32)
        assert venv.single_action_space == Discrete(5)
        obs, infos = venv.reset(seed=seed)
        assert obs in venv.observation_space
        assert list(infos["seed"]) == [seed + i for i in range(n)]
        for t in range(11):
            for i in range(n):
                o, r, term, info = alone[i][t]
                for key in ("sets", "pose"):
                    assert np.array_equal(obs[key][i], o[key]), (t, i, key)
                if t > 0:
                    assert rewards[i] == r and terminated[i] == term
                assert infos["step"][i] == info["step"] and infos["violations"][i] == 0
            if t == 10:
                break
            obs, rewards, terminated, truncated, infos = venv.step([acts[i][t] for i in range(n)])
            assert not truncated.any()
        assert terminated.all()
        # NEXT_STEP autoreset: the next step starts new episodes, whatever the actions.
        obs, rewards, terminated, truncated, infos = venv.step([0] * n)
        assert not terminated.any() and (rewards == 0).all()
        assert (infos["step"] == 0).all()
        assert not set(infos["seed"]) & {seed + i for i in range(n)}
    finally:
        venv.close()


def rewards_of(venv: SimVectorEnv, seed: int, acts: list[list[int]]) -> np.ndarray:
    """The rewards of one episode of every environment (``acts[t][i]``), from ``reset(seed)``."""
    venv.reset(seed=seed)
    out = []
    for step_acts in acts:
        _, rewards, terminated, _, _ = venv.step(step_acts)
        out.append(rewards)
        if terminated.all():
            break
    return np.array(out)


def test_the_baseline_reward_is_the_reward_less_the_deferring_runs():
    seed, n = 7, 2
    defer = [[5] * n] * 10
    turns = [[actions(200 + t, 1, k=6)[0] for _ in range(n)] for t in range(10)]
    plain = SimVectorEnv(n, duration=30, threads=2, defer=True, **SIM_KW)
    relative = SimVectorEnv(n, duration=30, threads=2, defer=True, baseline=True, **SIM_KW)
    try:
        deferring = rewards_of(plain, seed, defer)
        assert len(deferring) == 10 and np.abs(deferring[:-1]).sum() > 0
        # A policy that always defers flies the variant's run: 0 at every step.
        assert (rewards_of(relative, seed, defer) == 0).all()
        # Any other: its reward less the deferring run's, from the seeds' kept values.
        assert all(s.shadow is None for s in relative._slots)
        got = rewards_of(relative, seed, turns)
        assert all(s.shadow is None for s in relative._slots)
        expected = rewards_of(plain, seed, turns) - deferring
        assert np.abs(expected).sum() > 0
        np.testing.assert_allclose(got, expected, rtol=1e-9, atol=1e-12)
    finally:
        plain.close()
        relative.close()
