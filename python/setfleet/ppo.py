"""Proximal policy optimisation in numpy, for the environments of :mod:`setfleet.gym` and
``setfleet.vector``, and a planner that flies a trained policy in a real run.

**Network** (:class:`Policy`). The observation dict ``{"sets": (4, S, S), "pose": (4,)}``
(:mod:`setfleet.gym`) becomes features: the four set rasters average-pooled to ``(4, P, P)``
(``S`` a multiple of ``P``), flattened, followed by the pose: ``4 P² + 4`` numbers. A
multi-layer perceptron of ``tanh`` layers (``hidden``, two of 64 units by default) feeds two
linear heads: the logits of a softmax policy over ``Discrete(n)`` and a scalar value.
Weights start orthogonal (gain √2 in the trunk, 0.01 on the policy head, 1 on the value
head), biases at zero, drawn from ``numpy.random.default_rng(seed)``; every computation is
float64, the forward and backward passes are written out by hand.

**Algorithm** (:class:`PPO`). Each update collects ``rollout`` steps of each of the
``num_envs`` environments of a :class:`gymnasium.vector.VectorEnv` in next-step autoreset
mode (:attr:`gymnasium.vector.AutoresetMode.NEXT_STEP`): the step after an episode's end
ignores its action and returns the reset observation, so that step is not a transition and
is not stored. A terminated episode's last transition has no future; a truncated one's reward
gets ``γ V(s')`` of its final observation (bootstrapping). Advantages come from GAE(λ) over
each environment's stored transitions, returns are advantages plus values. Then ``epochs``
passes over the batch in shuffled minibatches minimise the clipped surrogate

    L = −E[min(r A, clip(r, 1 − ε, 1 + ε) A)] + c_v · ½ E[(V − R)²] − c_e · E[H(π)]

with advantages normalised over the batch, the gradient's global norm clipped at
``max_grad_norm`` and Adam steps. An update reports the means of its minibatches' policy
loss, value loss, entropy and approximate KL ``E[(r − 1) − log r]``.

**File format** (:meth:`Policy.save`, :meth:`Policy.load`): an uncompressed ``.npz`` holding
``config``, a 0-d string array of JSON ``{"format": "setfleet-ppo", "version": 1, "size": S,
"pool": P, "hidden": [...], "n_actions": n, "increments": [...] or null, "defer": bool}``
(``defer`` absent: false), and one float64
array per parameter, ``param_w{k}`` / ``param_b{k}`` for hidden layer ``k`` (``w`` of shape
``(inputs, outputs)``), ``param_wpi`` / ``param_bpi`` for the policy head and ``param_wv`` /
``param_bv`` for the value head.

:class:`PolicyPlanner` flies a loaded policy through :meth:`setfleet.Run.serve`.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from .gym import Actions, SetsRaster, observe
from .layout import Action, Observation
from .planner import Planner

__all__ = [
    "NetConfig", "Policy", "PPOConfig", "PPO", "Rollout", "Episode", "Adam", "ppo_loss", "gae",
    "env_info", "PolicyPlanner", "FORMAT",
]

#: ``format`` of a saved policy's config.
FORMAT = "setfleet-ppo"
_VERSION = 1


@dataclass(frozen=True)
class NetConfig:
    """The shape of a :class:`Policy`: raster side ``size`` (S), pooled side ``pool`` (P),
    the hidden layers' widths, the number of actions, the actions' yaw increments (rad, for
    information) and whether the last action defers to the UAV's own planner
    (:class:`setfleet.gym.Actions`)."""

    size: int = 64
    pool: int = 8
    hidden: tuple[int, ...] = (64, 64)
    n_actions: int = 5
    increments: tuple[float, ...] | None = None
    defer: bool = False

    def __post_init__(self) -> None:
        if self.pool < 1 or self.size < 1 or self.size % self.pool:
            raise ValueError(f"size ({self.size}) must be a positive multiple of pool ({self.pool})")
        if not self.hidden or min(self.hidden) < 1:
            raise ValueError(f"hidden: at least one layer, each of at least 1 unit, not {self.hidden}")
        if self.n_actions < 1:
            raise ValueError(f"n_actions must be at least 1, not {self.n_actions}")
        if self.increments is not None and len(self.increments) + self.defer != self.n_actions:
            raise ValueError(
                f"{len(self.increments)} increments{' and defer' if self.defer else ''} "
                f"for {self.n_actions} actions"
            )

    @property
    def features(self) -> int:
        """Length of the network's input: ``4 P² + 4``."""
        return 4 * self.pool * self.pool + 4


def _orthogonal(rows: int, cols: int, gain: float, rng: np.random.Generator) -> np.ndarray:
    """A ``(rows, cols)`` matrix with orthonormal rows or columns, times ``gain``."""
    a = rng.standard_normal((max(rows, cols), min(rows, cols)))
    q, r = np.linalg.qr(a)
    q *= np.sign(np.diag(r))
    return gain * (q if rows >= cols else q.T)


def _log_softmax(logits: np.ndarray) -> np.ndarray:
    z = logits - logits.max(axis=1, keepdims=True)
    return z - np.log(np.exp(z).sum(axis=1, keepdims=True))


class Policy:
    """The policy and value network (the module's documentation); ``params`` maps each
    parameter's name to its array."""

    def __init__(self, config: NetConfig, seed: int = 0) -> None:
        rng = np.random.default_rng(seed)
        self.config = config
        self.params: dict[str, np.ndarray] = {}
        widths = (config.features, *config.hidden)
        for k in range(len(config.hidden)):
            self.params[f"w{k}"] = _orthogonal(widths[k], widths[k + 1], math.sqrt(2.0), rng)
            self.params[f"b{k}"] = np.zeros(widths[k + 1])
        self.params["wpi"] = _orthogonal(widths[-1], config.n_actions, 0.01, rng)
        self.params["bpi"] = np.zeros(config.n_actions)
        self.params["wv"] = _orthogonal(widths[-1], 1, 1.0, rng)
        self.params["bv"] = np.zeros(1)

    def features(self, obs: Mapping[str, np.ndarray]) -> np.ndarray:
        """The ``(B, 4 P² + 4)`` float64 features of a batch of observations (``"sets"``
        ``(B, 4, S, S)``, ``"pose"`` ``(B, 4)``)."""
        sets = np.asarray(obs["sets"])
        pose = np.asarray(obs["pose"], dtype=np.float64)
        s, p = self.config.size, self.config.pool
        if sets.ndim != 4 or sets.shape[1:] != (4, s, s):
            raise ValueError(f"sets of shape {sets.shape}: expected (B, 4, {s}, {s})")
        b, k = sets.shape[0], s // p
        pooled = sets.reshape(b, 4, p, k, p, k).mean(axis=(3, 5), dtype=np.float64)
        return np.concatenate([pooled.reshape(b, -1), pose.reshape(b, 4)], axis=1)

    def forward(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
        """Logits ``(B, n)``, values ``(B,)`` and the layers' activations (for
        :meth:`backward`) of features ``x``."""
        acts = [x]
        for k in range(len(self.config.hidden)):
            acts.append(np.tanh(acts[-1] @ self.params[f"w{k}"] + self.params[f"b{k}"]))
        h = acts[-1]
        logits = h @ self.params["wpi"] + self.params["bpi"]
        values = (h @ self.params["wv"] + self.params["bv"])[:, 0]
        return logits, values, acts

    def backward(
        self, acts: list[np.ndarray], dlogits: np.ndarray, dvalues: np.ndarray
    ) -> dict[str, np.ndarray]:
        """The gradient of a loss with respect to every parameter, given the loss's gradient
        with respect to the logits and the values of :meth:`forward` (``acts`` its cache)."""
        h = acts[-1]
        dv = dvalues[:, None]
        grads = {
            "wpi": h.T @ dlogits,
            "bpi": dlogits.sum(axis=0),
            "wv": h.T @ dv,
            "bv": dv.sum(axis=0),
        }
        dh = dlogits @ self.params["wpi"].T + dv @ self.params["wv"].T
        for k in reversed(range(len(self.config.hidden))):
            dz = dh * (1.0 - acts[k + 1] ** 2)
            grads[f"w{k}"] = acts[k].T @ dz
            grads[f"b{k}"] = dz.sum(axis=0)
            dh = dz @ self.params[f"w{k}"].T
        return grads

    def act(
        self, x: np.ndarray, rng: np.random.Generator | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Actions, their log-probabilities and the values for features ``x``: sampled with
        ``rng``, or the most probable actions without one."""
        logits, values, _ = self.forward(x)
        logp = _log_softmax(logits)
        if rng is None:
            actions = logp.argmax(axis=1)
        else:
            u = rng.random(len(x))[:, None]
            actions = np.minimum((np.exp(logp).cumsum(axis=1) < u).sum(axis=1), logp.shape[1] - 1)
        return actions, logp[np.arange(len(x)), actions], values

    def values(self, x: np.ndarray) -> np.ndarray:
        """The value head on features ``x``."""
        return self.forward(x)[1]

    def save(self, path: str | os.PathLike[str]) -> None:
        """Writes the config and the weights to ``path`` (the module's file format)."""
        c = self.config
        meta = {
            "format": FORMAT,
            "version": _VERSION,
            "size": c.size,
            "pool": c.pool,
            "hidden": list(c.hidden),
            "n_actions": c.n_actions,
            "increments": None if c.increments is None else list(c.increments),
            "defer": c.defer,
        }
        arrays = {f"param_{k}": v for k, v in self.params.items()}
        with open(path, "wb") as f:
            np.savez(f, config=np.array(json.dumps(meta)), **arrays)

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> "Policy":
        """A policy saved by :meth:`save`; raises :class:`ValueError` for a file of another
        format or whose weights do not fit its config."""
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(str(z["config"]))
            if meta.get("format") != FORMAT or meta.get("version") != _VERSION:
                raise ValueError(f"{path}: not a {FORMAT} policy of version {_VERSION}")
            incs = meta["increments"]
            config = NetConfig(
                size=int(meta["size"]),
                pool=int(meta["pool"]),
                hidden=tuple(int(h) for h in meta["hidden"]),
                n_actions=int(meta["n_actions"]),
                increments=None if incs is None else tuple(float(u) for u in incs),
                defer=bool(meta.get("defer", False)),
            )
            policy = cls(config)
            for name, old in policy.params.items():
                new = z[f"param_{name}"]
                if new.shape != old.shape:
                    raise ValueError(f"{path}: {name} has shape {new.shape}, expected {old.shape}")
                policy.params[name] = new.astype(np.float64)
        return policy


def ppo_loss(
    policy: Policy,
    x: np.ndarray,
    actions: np.ndarray,
    old_logp: np.ndarray,
    advantages: np.ndarray,
    returns: np.ndarray,
    clip: float,
    vf_coef: float,
    ent_coef: float,
) -> tuple[float, dict[str, np.ndarray], dict[str, float]]:
    """The PPO loss of a minibatch (the module's documentation), its gradient with respect to
    every parameter, and its parts: ``policy_loss``, ``value_loss``, ``entropy``,
    ``approx_kl``."""
    b = len(x)
    rows = np.arange(b)
    logits, values, acts = policy.forward(x)
    logp_all = _log_softmax(logits)
    p = np.exp(logp_all)
    ratio = np.exp(logp_all[rows, actions] - old_logp)
    clipped = np.clip(ratio, 1.0 - clip, 1.0 + clip)
    unclipped_wins = -advantages * ratio >= -advantages * clipped
    policy_loss = float(np.mean(np.maximum(-advantages * ratio, -advantages * clipped)))
    entropy_each = -(p * logp_all).sum(axis=1)
    entropy = float(entropy_each.mean())
    value_loss = float(0.5 * np.mean((values - returns) ** 2))
    loss = policy_loss + vf_coef * value_loss - ent_coef * entropy

    onehot = np.zeros_like(p)
    onehot[rows, actions] = 1.0
    dlogp = np.where(unclipped_wins, -advantages * ratio, 0.0) / b
    dlogits = dlogp[:, None] * (onehot - p)
    dlogits += ent_coef * p * (logp_all + entropy_each[:, None]) / b
    dvalues = vf_coef * (values - returns) / b
    grads = policy.backward(acts, dlogits, dvalues)
    log_ratio = logp_all[rows, actions] - old_logp
    stats = {
        "policy_loss": policy_loss,
        "value_loss": value_loss,
        "entropy": entropy,
        "approx_kl": float(np.mean(np.expm1(log_ratio) - log_ratio)),
    }
    return loss, grads, stats


class Adam:
    """Adam over a dict of parameters, updated in place."""

    def __init__(self, params: Mapping[str, np.ndarray], lr: float, eps: float = 1e-5) -> None:
        self.lr, self.eps, self.beta1, self.beta2 = lr, eps, 0.9, 0.999
        self.m = {k: np.zeros_like(v) for k, v in params.items()}
        self.v = {k: np.zeros_like(v) for k, v in params.items()}
        self.t = 0

    def step(self, params: dict[str, np.ndarray], grads: Mapping[str, np.ndarray]) -> None:
        """One step down ``grads``."""
        self.t += 1
        c1 = 1.0 - self.beta1**self.t
        c2 = 1.0 - self.beta2**self.t
        for k, g in grads.items():
            self.m[k] = self.beta1 * self.m[k] + (1.0 - self.beta1) * g
            self.v[k] = self.beta2 * self.v[k] + (1.0 - self.beta2) * g * g
            params[k] -= self.lr * (self.m[k] / c1) / (np.sqrt(self.v[k] / c2) + self.eps)


def gae(
    rewards: np.ndarray,
    values: np.ndarray,
    dones: np.ndarray,
    valid: np.ndarray,
    last_values: np.ndarray,
    gamma: float,
    lam: float,
) -> np.ndarray:
    """GAE(λ) advantages ``(T, N)`` of ``T`` steps of ``N`` environments: ``dones[t]``
    marks the transitions that end an episode, ``valid`` the stored ones (the others,
    autoreset steps, get 0 and are skipped: each follows a done, which cuts the sum anyway),
    ``last_values`` the values of the states after the last step."""
    adv = np.zeros_like(values)
    running = np.zeros(values.shape[1])
    next_value = np.asarray(last_values, dtype=np.float64)
    for t in reversed(range(len(values))):
        live = 1.0 - dones[t]
        delta = rewards[t] + gamma * next_value * live - values[t]
        step = delta + gamma * lam * live * running
        ok = valid[t]
        adv[t] = np.where(ok, step, 0.0)
        running = np.where(ok, step, running)
        next_value = np.where(ok, values[t], next_value)
    return adv


@dataclass(frozen=True)
class PPOConfig:
    """PPO's hyper-parameters; ``rollout`` is steps per environment per update,
    ``minibatch`` transitions per gradient step; ``pool`` and ``hidden`` shape the network."""

    lr: float = 3e-4
    rollout: int = 128
    epochs: int = 4
    minibatch: int = 64
    gamma: float = 0.99
    gae_lambda: float = 0.95
    clip: float = 0.2
    ent_coef: float = 0.01
    vf_coef: float = 0.5
    max_grad_norm: float = 0.5
    pool: int = 8
    hidden: tuple[int, ...] = (64, 64)
    #: The initial logit bias of the action that defers (environments with ``defer=True``):
    #: at 2, with 5 increments, an untrained policy defers about 3 decisions in 5.
    defer_bias: float = 0.0


@dataclass
class Episode:
    """A finished episode: its undiscounted return, its length in transitions and the info
    of its last step (the vector's infos for its environment, scalars only)."""

    ret: float
    length: int
    info: dict[str, Any]


@dataclass
class Rollout:
    """The stored transitions of one collection, flattened, and the episodes that ended."""

    x: np.ndarray
    actions: np.ndarray
    logp: np.ndarray
    advantages: np.ndarray
    returns: np.ndarray
    episodes: list[Episode]

    @property
    def steps(self) -> int:
        """Stored transitions."""
        return len(self.actions)


def env_info(infos: Mapping[str, Any], i: int, num_envs: int) -> dict[str, Any]:
    """Environment ``i``'s scalar entries of vector ``infos`` (an entry whose mask ``_key``
    is false for ``i`` is absent)."""
    out: dict[str, Any] = {}
    for key, v in infos.items():
        if key.startswith("_") or not isinstance(v, np.ndarray) or v.shape[:1] != (num_envs,):
            continue
        mask = infos.get("_" + key)
        if v.ndim == 1 and (mask is None or bool(mask[i])):
            out[key] = v[i].item() if isinstance(v[i], np.generic) else v[i]
    return out


class PPO:
    """PPO on a vector environment in next-step autoreset mode (the module's documentation).

    The environment owns its seeding: it is reset once here, without a seed. ``seed`` seeds
    the network's weights, the actions' sampling and the minibatches' shuffling.
    ``running_info[i]`` is the last info of environment ``i``'s unfinished episode (empty
    right after an episode ends).
    """

    def __init__(self, env: Any, config: PPOConfig = PPOConfig(), seed: int = 0) -> None:
        mode = env.metadata.get("autoreset_mode", "NextStep")
        if getattr(mode, "value", mode) != "NextStep":
            raise ValueError(f"PPO needs next-step autoreset, not {mode}")
        self.env = env
        self.config = config
        self.num_envs = int(env.num_envs)
        incs = getattr(env, "increments", None)
        defer = bool(getattr(getattr(env, "actions", None), "defer", False))
        net = NetConfig(
            size=int(env.single_observation_space["sets"].shape[-1]),
            pool=config.pool,
            hidden=tuple(config.hidden),
            n_actions=int(env.single_action_space.n),
            increments=None if incs is None else tuple(float(u) for u in incs),
            defer=defer,
        )
        self.policy = Policy(net, seed)
        if defer:
            self.policy.params["bpi"][-1] = config.defer_bias
        self.optimizer = Adam(self.policy.params, config.lr)
        self.rng = np.random.default_rng(seed)
        self._obs, _ = env.reset()
        self._done = np.zeros(self.num_envs, dtype=bool)
        self._ret = np.zeros(self.num_envs)
        self._len = np.zeros(self.num_envs, dtype=np.int64)
        self.running_info: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]

    def collect(self) -> Rollout:
        """Steps the environments ``rollout`` times with sampled actions; the transitions
        with their advantages and returns, and the episodes that ended."""
        c, n, pol = self.config, self.num_envs, self.policy
        t_max = c.rollout
        xs = np.zeros((t_max, n, pol.config.features))
        actions = np.zeros((t_max, n), dtype=np.int64)
        logps, values, rewards = (np.zeros((t_max, n)) for _ in range(3))
        dones = np.zeros((t_max, n))
        valid = np.zeros((t_max, n), dtype=bool)
        episodes: list[Episode] = []
        for t in range(t_max):
            x = pol.features(self._obs)
            a, lp, v = pol.act(x, self.rng)
            obs, r, term, trunc, infos = self.env.step(a)
            live = ~self._done  # the others were autoreset steps: their action was ignored
            done = np.logical_or(term, trunc)
            r = np.asarray(r, dtype=np.float64)
            self._ret[live] += r[live]
            self._len[live] += 1
            boot = live & np.asarray(trunc) & ~np.asarray(term)
            stored_r = r.copy()
            if boot.any():
                final = {k: np.asarray(o)[boot] for k, o in obs.items()}
                stored_r[boot] += c.gamma * pol.values(pol.features(final))
            xs[t], actions[t], logps[t], values[t] = x, a, lp, v
            rewards[t], dones[t], valid[t] = stored_r, done, live
            for i in range(n):
                info = env_info(infos, i, n)
                if live[i] and done[i]:
                    episodes.append(Episode(float(self._ret[i]), int(self._len[i]), info))
                    self._ret[i], self._len[i] = 0.0, 0
                    self.running_info[i] = {}
                else:
                    self.running_info[i] = info
            self._obs, self._done = obs, done
        last_values = pol.values(pol.features(self._obs))
        adv = gae(rewards, values, dones, valid, last_values, c.gamma, c.gae_lambda)
        keep = valid.reshape(-1)
        flat = lambda a: a.reshape(t_max * n, *a.shape[2:])[keep]  # noqa: E731
        return Rollout(
            x=flat(xs),
            actions=flat(actions),
            logp=flat(logps),
            advantages=flat(adv),
            returns=flat(adv + values),
            episodes=episodes,
        )

    def update(self, rollout: Rollout) -> dict[str, float]:
        """``epochs`` passes of minibatch Adam steps on ``rollout``; the means of the
        minibatches' ``policy_loss``, ``value_loss``, ``entropy``, ``approx_kl``."""
        c = self.config
        m = rollout.steps
        adv = rollout.advantages
        adv = (adv - adv.mean()) / (adv.std() + 1e-8)
        totals: dict[str, float] = {}
        count = 0
        for _ in range(c.epochs):
            order = self.rng.permutation(m)
            for start in range(0, m, c.minibatch):
                idx = order[start : start + c.minibatch]
                _, grads, stats = ppo_loss(
                    self.policy, rollout.x[idx], rollout.actions[idx], rollout.logp[idx], adv[idx],
                    rollout.returns[idx], c.clip, c.vf_coef, c.ent_coef,
                )
                norm = math.sqrt(sum(float((g * g).sum()) for g in grads.values()))
                if norm > c.max_grad_norm:
                    grads = {k: g * (c.max_grad_norm / norm) for k, g in grads.items()}
                self.optimizer.step(self.policy.params, grads)
                for k, v in stats.items():
                    totals[k] = totals.get(k, 0.0) + v
                count += 1
        return {k: v / max(count, 1) for k, v in totals.items()}


class PolicyPlanner(Planner):
    """A trained :class:`Policy` as a :class:`setfleet.Planner`: each request becomes the
    environments' observation (:func:`setfleet.gym.observe` at the policy's raster size) and
    the answer is the action's (:class:`setfleet.gym.Actions` over ``obs.increments``: a turn
    by ``obs.increments[action]``, or a deferral for a policy trained with ``defer``), the most
    probable action's (``deterministic``) or a sampled one's (seeded by ``seed``, reseeded at
    each :meth:`reset`).

    ``policy`` is a :class:`Policy` or the path of a saved one. A request whose number of
    increments differs from the policy's actions raises :class:`ValueError`.
    """

    def __init__(
        self,
        policy: Policy | str | os.PathLike[str],
        deterministic: bool = True,
        seed: int = 0,
    ) -> None:
        self.policy = policy if isinstance(policy, Policy) else Policy.load(policy)
        self.deterministic = deterministic
        self.seed = seed
        self.rng = np.random.default_rng(seed)
        self._raster = SetsRaster(self.policy.config.size)
        #: Decisions taken since the last :meth:`reset`, and how many of them deferred.
        self.decisions = self.deferrals = 0

    def reset(self) -> None:
        """Restarts the sampling generator from ``seed`` and the counts of decisions."""
        self.rng = np.random.default_rng(self.seed)
        self.decisions = self.deferrals = 0

    def decide(self, obs: Observation) -> Action:
        """The action the policy picks for request ``obs``."""
        c = self.policy.config
        actions = Actions(obs.increments, c.defer)
        if actions.n != c.n_actions:
            raise ValueError(
                f"the request offers {len(obs.increments)} increments, the policy has "
                f"{c.n_actions} actions{' (one defers)' if c.defer else ''}"
            )
        o = observe(obs, self._raster)
        x = self.policy.features({k: v[None] for k, v in o.items()})
        action, _, _ = self.policy.act(x, None if self.deterministic else self.rng)
        chosen = actions.action(action[0])
        self.decisions += 1
        self.deferrals += chosen.defer
        return chosen

    def __repr__(self) -> str:
        return f"PolicyPlanner({self.policy.config}, deterministic={self.deterministic})"
