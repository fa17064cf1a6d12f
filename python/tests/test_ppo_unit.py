"""The numpy PPO without a fleet: the network's gradient against finite differences, the
collection under next-step autoreset, learning on a toy task, saving and loading, the planner
on a real request, and the reference trainer on a stand-in vector environment."""

from __future__ import annotations

import csv
import importlib.util
import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest

gymnasium = pytest.importorskip("gymnasium")

from gymnasium import spaces  # noqa: E402
from gymnasium.vector import AutoresetMode, SyncVectorEnv  # noqa: E402

from setfleet import Action, Observation, decode_answer, encode_answer, encode_request  # noqa: E402
from setfleet.ppo import (  # noqa: E402
    PPO,
    NetConfig,
    Policy,
    PolicyPlanner,
    PPOConfig,
    gae,
    ppo_loss,
)

TRAINER = Path(__file__).resolve().parents[1] / "examples" / "train_ppo.py"


class FakeSearch(gymnasium.Env):
    """The fleet environment's spaces on a toy task: reward 1 for action ``good``, else 0;
    episodes of ``length`` steps, terminated (or truncated). The info carries ``ua``
    (``1 − t / length``) and ``violations`` (1 from the episode's step 2 on);
    ``violation_episodes`` counts the episodes that reported one."""

    def __init__(self, size: int = 8, n: int = 3, length: int = 6, good: int = 1,
                 truncate: bool = False, seed: int = 0) -> None:
        self.observation_space = spaces.Dict({
            "sets": spaces.Box(0.0, 1.0, (4, size, size), np.float32),
            "pose": spaces.Box(-np.inf, np.inf, (4,), np.float32),
        })
        self.action_space = spaces.Discrete(n)
        self.size, self.length, self.good, self.truncate = size, length, good, truncate
        self.rng = np.random.default_rng(seed)
        self.t = 0
        self.violation_episodes = 0

    def _obs(self) -> dict[str, np.ndarray]:
        sets = self.rng.random((4, self.size, self.size)).astype(np.float32)
        pose = np.array([self.t / self.length, 0.0, 1.0, 0.0], dtype=np.float32)
        return {"sets": sets, "pose": pose}

    def _info(self) -> dict[str, float | int]:
        return {"ua": 1.0 - self.t / self.length, "violations": int(self.t >= 2)}

    def reset(self, *, seed=None, options=None):  # noqa: ANN001, ANN201
        super().reset(seed=seed)
        self.t = 0
        return self._obs(), self._info()

    def step(self, action):  # noqa: ANN001, ANN201
        self.t += 1
        if self.t == 2:
            self.violation_episodes += 1
        end = self.t >= self.length
        reward = float(int(action) == self.good)
        return self._obs(), reward, end and not self.truncate, end and self.truncate, self._info()


class FakeVector(SyncVectorEnv):
    """``FakeSearch`` environments in a vector with the fleet vector's ``increments``."""

    increments = (-0.5, 0.0, 0.5)


def fake_vector(num_envs: int = 4, **kw) -> FakeVector:
    return FakeVector([lambda i=i: FakeSearch(seed=i, **kw) for i in range(num_envs)])


# --------------------------------------------------------------------------------------------
# The network and the loss


def test_the_loss_gradient_matches_finite_differences():
    rng = np.random.default_rng(3)
    policy = Policy(NetConfig(size=4, pool=2, hidden=(5, 3), n_actions=3), seed=7)
    for k, v in policy.params.items():  # away from the init's near-zero head and biases
        policy.params[k] = v + 0.3 * rng.standard_normal(v.shape)
    b = 9
    x = rng.standard_normal((b, policy.config.features))
    actions = rng.integers(0, 3, b)
    logits, _, _ = policy.forward(x)
    logp = logits[np.arange(b), actions] - np.log(np.exp(logits).sum(axis=1))
    old_logp = logp + rng.normal(0.0, 0.4, b)  # ratios on both sides of the clip range
    ratio = np.exp(logp - old_logp)
    assert (np.abs(ratio - 0.8) > 1e-3).all() and (np.abs(ratio - 1.2) > 1e-3).all()
    assert ((ratio < 0.8) | (ratio > 1.2)).any() and ((ratio > 0.8) & (ratio < 1.2)).any()
    adv, ret = rng.standard_normal(b), rng.standard_normal(b)
    args = (x, actions, old_logp, adv, ret, 0.2, 0.5, 0.1)

    _, grads, _ = ppo_loss(policy, *args)
    eps = 1e-6
    for name, p in policy.params.items():
        numeric = np.zeros_like(p)
        for i in np.ndindex(p.shape):
            keep = p[i]
            p[i] = keep + eps
            up = ppo_loss(policy, *args)[0]
            p[i] = keep - eps
            down = ppo_loss(policy, *args)[0]
            p[i] = keep
            numeric[i] = (up - down) / (2 * eps)
        np.testing.assert_allclose(grads[name], numeric, rtol=1e-5, atol=1e-8, err_msg=name)


def test_features_average_pool_the_sets_and_append_the_pose():
    policy = Policy(NetConfig(size=4, pool=2, n_actions=2))
    sets = np.zeros((1, 4, 4, 4), np.float32)
    sets[0, 2, :2, 2:] = 1.0  # channel 2, rows 0-1, columns 2-3: pooled pixel (0, 1)
    sets[0, 0, 3, 3] = 1.0
    x = policy.features({"sets": sets, "pose": np.array([[0.1, -0.2, 1.0, 0.0]], np.float32)})
    pooled = x[0, :16].reshape(4, 2, 2)
    assert pooled[2, 0, 1] == 1.0 and pooled[0, 1, 1] == 0.25 and pooled.sum() == 1.25
    np.testing.assert_allclose(x[0, 16:], [0.1, -0.2, 1.0, 0.0], rtol=1e-6)


def test_gae_follows_each_environment_and_stops_at_a_done():
    # One environment: a 2-step episode, an autoreset step (not stored), one more step.
    rewards = np.array([[1.0], [2.0], [99.0], [3.0]])
    values = np.array([[0.5], [0.25], [99.0], [1.0]])
    dones = np.array([[0.0], [1.0], [0.0], [0.0]])
    valid = np.array([[True], [True], [False], [True]])
    g, lam = 0.9, 0.8
    adv = gae(rewards, values, dones, valid, np.array([2.0]), g, lam)
    d1 = 2.0 - 0.25
    d0 = 1.0 + g * 0.25 - 0.5
    assert adv[:, 0] == pytest.approx([d0 + g * lam * d1, d1, 0.0, 3.0 + g * 2.0 - 1.0])


# --------------------------------------------------------------------------------------------
# Collection and learning


def small_ppo(env, **kw) -> PPO:  # noqa: ANN001
    config = dict(rollout=8, minibatch=16, epochs=4, pool=4, hidden=(16, 16), lr=3e-3)
    config.update(kw)
    return PPO(env, PPOConfig(**config), seed=0)


def test_autoreset_steps_are_not_stored():
    env = fake_vector(1, length=3)
    try:
        ppo = small_ppo(env)
        rollout = ppo.collect()
    finally:
        env.close()
    # Steps 0-2 an episode, step 3 the autoreset, steps 4-6 an episode, step 7 the autoreset.
    assert rollout.steps == 6
    assert [e.length for e in rollout.episodes] == [3, 3]
    assert all(e.info["ua"] == 0.0 and e.info["violations"] == 1 for e in rollout.episodes)
    assert ppo.running_info == [{"ua": 1.0, "violations": 0}]  # the next episode's reset


@pytest.mark.parametrize("truncate", [False, True])
def test_a_truncated_episode_is_bootstrapped_a_terminated_one_is_not(truncate):
    env = fake_vector(1, length=3, good=-1, truncate=truncate)  # reward always 0
    try:
        ppo = small_ppo(env, gamma=0.9)
        p = ppo.policy.params
        p["wv"][:] = 0.0
        p["bv"][:] = 5.0  # V = 5 everywhere
        rollout = ppo.collect()
    finally:
        env.close()
    last = rollout.returns[[2, 5]]  # the episodes' last transitions
    assert last == pytest.approx([0.9 * 5.0] * 2 if truncate else [0.0, 0.0])


def test_ppo_learns_to_pick_the_rewarded_action():
    env = fake_vector(4, length=6, good=1)
    try:
        ppo = small_ppo(env, rollout=24, minibatch=32)
        returns = []
        for _ in range(12):
            rollout = ppo.collect()
            ppo.update(rollout)
            returns.append(np.mean([e.ret for e in rollout.episodes]))
    finally:
        env.close()
    assert returns[0] < 3.5  # about a third of the 6 steps at random
    assert np.mean(returns[-3:]) > 5.0


def test_ppo_refuses_same_step_autoreset():
    env = FakeVector([lambda: FakeSearch()], autoreset_mode=AutoresetMode.SAME_STEP)
    try:
        with pytest.raises(ValueError, match="next-step"):
            small_ppo(env)
    finally:
        env.close()


def test_a_run_is_deterministic_given_its_seeds():
    def train_once() -> dict[str, np.ndarray]:
        env = fake_vector(2)
        try:
            ppo = small_ppo(env)
            for _ in range(2):
                ppo.update(ppo.collect())
            return {k: v.copy() for k, v in ppo.policy.params.items()}
        finally:
            env.close()

    a, b = train_once(), train_once()
    assert all(np.array_equal(a[k], b[k]) for k in a)


# --------------------------------------------------------------------------------------------
# Saving, loading, planning


def test_save_and_load_give_the_same_actions(tmp_path):
    config = NetConfig(size=16, pool=4, hidden=(12, 7), n_actions=3, increments=(-0.5, 0.0, 0.5))
    policy = Policy(config, seed=4)
    rng = np.random.default_rng(0)
    for k, v in policy.params.items():
        policy.params[k] = v + rng.standard_normal(v.shape)
    policy.save(tmp_path / "p.npz")
    loaded = Policy.load(tmp_path / "p.npz")
    assert loaded.config == config
    x = rng.standard_normal((50, config.features))
    a0, lp0, v0 = policy.act(x)
    a1, lp1, v1 = loaded.act(x)
    assert np.array_equal(a0, a1) and np.array_equal(lp0, lp1) and np.array_equal(v0, v1)
    assert len(set(a0.tolist())) > 1  # the comparison is not trivial


def test_load_refuses_another_file(tmp_path):
    np.savez(tmp_path / "other.npz", config=np.array(json.dumps({"format": "else"})))
    with pytest.raises(ValueError, match="setfleet-ppo"):
        Policy.load(tmp_path / "other.npz")


def request(increments=(-0.4, 0.0, 0.4)) -> Observation:  # noqa: ANN001
    und = np.random.default_rng(1).integers(0, 26, size=(40, 40)).astype(np.uint16)
    return Observation(encode_request(undetected=und, increments=increments, pose=(20.0, -10.0, 80.0, 0.3),
                                      targets=[(1, 3, 4, np.full((2, 2), 25))]))


def test_the_planner_answers_one_of_the_increments():
    obs = request()
    policy = Policy(NetConfig(size=16, pool=4, n_actions=3), seed=2)
    greedy = PolicyPlanner(policy)
    a = greedy.decide(obs)
    assert isinstance(a, Action) and a.kind == 0 and a.increments.size == 1
    u = float(a.increments[0])
    assert u in obs.increments.tolist()
    assert greedy(obs).increments.tolist() == [u]

    sampling = PolicyPlanner(policy, deterministic=False, seed=5)
    first = [float(sampling.decide(obs).increments[0]) for _ in range(20)]
    sampling.reset()
    assert [float(sampling.decide(obs).increments[0]) for _ in range(20)] == first
    assert set(first) <= set(obs.increments.tolist())


def test_a_policy_with_defer_defers_with_its_last_action(tmp_path):
    config = NetConfig(size=16, pool=4, n_actions=4, increments=(-0.4, 0.0, 0.4), defer=True)
    policy = Policy(config, seed=2)
    policy.params["bpi"][-1] = 50.0  # the last action always wins
    policy.save(tmp_path / "p.npz")
    loaded = Policy.load(tmp_path / "p.npz")
    assert loaded.config == config
    action = PolicyPlanner(loaded).decide(request())
    assert action.defer and action.kind == 2
    decoded = decode_answer(encode_answer(request(), action))
    assert decoded.kind == 2 and decoded.yaw_reference(0.3) is None
    policy.params["bpi"][-1] = -50.0
    assert PolicyPlanner(policy).decide(request()).kind == 0
    with pytest.raises(ValueError, match="one defers"):
        PolicyPlanner(policy).decide(request(increments=(-0.5, 0.5)))
    with pytest.raises(ValueError, match="and defer"):
        NetConfig(n_actions=3, increments=(-0.4, 0.0, 0.4), defer=True)


def test_the_planner_loads_a_file_and_checks_the_increments(tmp_path):
    Policy(NetConfig(size=16, pool=4, n_actions=3)).save(tmp_path / "p.npz")
    planner = PolicyPlanner(tmp_path / "p.npz")
    assert float(planner.decide(request()).increments[0]) in (-0.4, 0.0, 0.4)
    with pytest.raises(ValueError, match="5 increments"):
        planner.decide(request(increments=(-1.0, -0.5, 0.0, 0.5, 1.0)))


# --------------------------------------------------------------------------------------------
# The trainer


@pytest.fixture(scope="module")
def trainer():
    spec = importlib.util.spec_from_file_location("train_ppo", TRAINER)
    module = importlib.util.module_from_spec(spec)
    sys.modules["train_ppo"] = module  # its dataclasses look their module up
    spec.loader.exec_module(module)
    return module


def test_the_trainer_writes_its_outputs_and_counts_violations(trainer, tmp_path):
    config = trainer.parse_args([
        "--steps", "200", "--out", str(tmp_path), "--no-eval", "--envs", "2", "--rollout", "16",
        "--minibatch", "16", "--pool", "4", "--hidden", "8,8", "--seed", "3",
    ])
    made = []

    def make_env(cfg):  # noqa: ANN001, ANN202
        assert cfg is config
        made.append(fake_vector(cfg.envs, length=5))
        return made[-1]

    summary = trainer.train(config, make_env)
    with open(tmp_path / "curve.csv") as f:
        rows = list(csv.DictReader(f))
    assert tuple(rows[0]) == trainer.CURVE_COLUMNS
    assert len(rows) == summary["updates"] and int(rows[-1]["env_steps"]) == summary["env_steps"] >= 200
    assert all(float(r["mean_final_ua"]) == 0.0 for r in rows if r["mean_final_ua"])
    truth = sum(e.violation_episodes for e in made[0].envs)
    assert truth > 0 and summary["violations"] == truth == int(rows[-1]["violations"])
    saved = json.loads((tmp_path / "train.json").read_text())
    assert saved["violations"] == truth and saved["config"]["ppo"]["rollout"] == 16
    policy = Policy.load(tmp_path / "policy.npz")
    assert policy.config.size == 8 and policy.config.increments == FakeVector.increments
    if importlib.util.find_spec("matplotlib") is not None:
        assert (tmp_path / "curve.png").stat().st_size > 0


def test_the_trainer_parses_its_command_line(trainer, tmp_path):
    config = trainer.parse_args(["--steps", "10", "--out", str(tmp_path), "--set", "a=1", "--set", "b=2"])
    assert config.eval_seeds == list(range(1001, 1031)) and config.envs == 4
    assert config.overrides == ["a=1", "b=2"] and config.eval_scenario is None
    assert config.scenario == str(trainer.REPO / "scenarios" / "training.toml")
    assert trainer.parse_seeds("5..7,20") == [5, 6, 7, 20]


def test_the_paired_interval_of_a_hand_made_example(trainer):
    # Differences -1, 2, 3, 4 (the None pair is dropped): mean 2, s = sqrt(14 / 3),
    # t(0.975, 3) = 3.1824, half width 3.1824 * s / 2 = 3.4374.
    got = trainer.paired_interval([0.0, 2.0, 3.0, 4.0, None, 1.0], [1.0, 0.0, 0.0, 0.0, 1.0, 1.0])
    assert got["n"] == 5 and (got["lower"], got["higher"], got["tie"]) == (1, 3, 1)
    # With the tie: differences -1, 2, 3, 4, 0: mean 1.6, s = sqrt(17.2 / 4), t(4) = 2.7764.
    half = 2.7764 * math.sqrt(17.2 / 4) / math.sqrt(5)
    assert got["mean_diff"] == pytest.approx(1.6)
    assert got["ci95_low"] == pytest.approx(1.6 - half, abs=1e-3)
    assert got["ci95_high"] == pytest.approx(1.6 + half, abs=1e-3)
    four = trainer.paired_interval([0.0, 2.0, 3.0, 4.0], [1.0, 0.0, 0.0, 0.0])
    assert (four["ci95_low"], four["ci95_high"]) == pytest.approx((2 - 3.4374, 2 + 3.4374), abs=1e-3)
    assert trainer.paired_interval([1.0], [0.0])["ci95_low"] is None
    assert trainer.t_quantile_975(100) == pytest.approx(1.96, abs=0.02)


def test_a_baseline_flown_before_is_read_back(trainer, tmp_path):
    config = trainer.parse_args(["--eval-only", "--out", str(tmp_path), "--eval-seeds", "1..2",
                                 "--fleet", str(tmp_path / "no-such-fleet")])
    done = tmp_path / "eval" / "seed-1" / "paper"
    done.mkdir(parents=True)
    (done / "summary.json").write_text(json.dumps({"ua_final": 0.5, "violations": 0}))
    # Read back, so the missing fleet binary is never started.
    assert trainer.fly(config, 1, "paper", None, done) == {
        "seed": 1, "variant": "paper", "ua_final": 0.5, "violations": 0, "deferred": None}


def test_the_evaluation_pairs_each_seeds_runs(trainer, tmp_path, monkeypatch):
    config = trainer.parse_args(["--eval-only", "--out", str(tmp_path), "--eval-seeds", "1..4"])
    base = {"learned": 0.40, "paper": 0.45, "setfleet": 0.30}

    def fake_fly(cfg, seed, variant, policy, out):  # noqa: ANN001, ANN202
        assert (policy is not None) == (variant == "learned")
        return {"seed": seed, "variant": variant, "ua_final": base[variant] + 0.01 * seed * (variant == "learned"),
                "violations": 0, "deferred": 0.25 * seed if variant == "learned" else None}

    monkeypatch.setattr(trainer, "fly", fake_fly)
    report = trainer.evaluate(config, Policy(NetConfig(size=16, pool=4, n_actions=3)))
    # learned − paper: −0.04, −0.03, −0.02, −0.01.
    paper = report["learned-paper"]
    assert paper["n"] == 4 and paper["lower"] == 4 and math.isclose(paper["mean_diff"], -0.025)
    assert paper["ci95_low"] < -0.025 < paper["ci95_high"] < 0
    assert report["learned-setfleet"]["higher"] == 4
    assert math.isclose(report["learned_deferred"], 0.625) and report["violations"] == 0
    with open(tmp_path / "eval.csv") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 12 and rows[0]["deferred"] == "0.25" and rows[1]["deferred"] == ""
