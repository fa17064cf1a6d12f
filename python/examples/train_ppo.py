#!/usr/bin/env python3
"""The reference PPO trainer: one learning UAV (UAV 0) in the in-process fleet, then an
evaluation on the real distributed fleet against the paper's and setfleet's planners.

    python python/examples/train_ppo.py --steps 200000 --out runs/ppo

trains :mod:`setfleet.ppo` on ``--envs`` environments of ``setfleet.vector.SimVectorEnv``
(the scenario ``--scenario``, by default ``scenarios/training.toml`` of the repository, with
``--set`` overrides; the environments draw their episodes' seeds from 1..1000) until
``--steps`` transitions or ``--max-hours`` of wall time, and writes into ``--out``:

- ``curve.csv``, one row per update (:data:`CURVE_COLUMNS`), and ``curve.png`` (return and
  final undetected area against environment steps, when matplotlib is installed);
- ``policy.npz``, the policy (:meth:`setfleet.ppo.Policy.save`);
- ``train.json``: the configuration, the totals and ``violations``, the guarantee violations
  summed over every training episode (unfinished ones included).

Then, unless ``--no-eval``, every held-out seed of ``--eval-seeds`` (default 1001..1030)
runs three times with ``fleet run`` (``--eval-scenario``, default the paper's): the policy
flying UAV 0 (:class:`setfleet.ppo.PolicyPlanner`, greedy; with ``--eval-sampled`` its
actions sampled, seeded by the run's seed) with the paper's planner on the others, and the
``paper`` and ``setfleet`` variants alone. ``eval.csv`` holds each run's final UA and
violations (and for the policy's runs the share of its decisions that deferred),
``eval.json`` the paired differences learned − baseline of the final UA with their 95 %
Student's t intervals and the counts of seeds where the policy was lower, higher or equal
(lower UA is better), the mean share of deferred decisions and the violations of all
evaluation runs. With ``--eval-every N`` the policy is also saved every N updates
(``checkpoints/``) and flown alone on the held-out seeds (``eval_curve.csv``).

With ``--defer`` the learner has one more action, the last, that defers the decision to its
own planner (the paper's, :class:`setfleet.gym.Actions`): the policy learns where to step in.
``--defer-bias`` is that action's initial logit bias (at 2 an untrained policy defers about 3
decisions in 5). With ``--baseline`` the rewards are relative to the paper's own run of each
seed (``SimVectorEnv(baseline=True)``): an episode's return is what the learner gained over
the paper's planner, the seed's luck cancelled out. The reference run uses both
(docs/python.md, "The reference trainer").

"Environment steps" count transitions: the autoreset steps of the vector environment are
not counted. A baseline run already in ``OUT/eval`` (its ``summary.json``) is read instead
of flown again: an interrupted evaluation resumes, and a second policy evaluated into the
same directory reuses the baselines.
"""

from __future__ import annotations

import os

# numpy's BLAS threads would spin beside the fleet's threads on small matrices: one is enough.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import csv
import json
import math
import sys
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

try:
    import setfleet
except ImportError:  # run from a checkout without installing the package
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    import setfleet

from setfleet.ppo import PPO, Policy, PolicyPlanner, PPOConfig

REPO = Path(__file__).resolve().parents[2]
#: Seeds the training environments draw their episodes from; held-out seeds lie outside.
TRAIN_SEEDS = range(1, 1001)
#: The columns of ``curve.csv``.
CURVE_COLUMNS = (
    "env_steps",
    "episodes",
    "mean_return",
    "mean_final_ua",
    "violations",
    "wall_s",
    "steps_per_s",
    "defer_share",
    "policy_loss",
    "value_loss",
    "entropy",
    "approx_kl",
)
#: The evaluation's variants: the learned policy, then the baselines.
EVAL_VARIANTS = ("learned", "paper", "setfleet")
#: Two-sided 95 % quantiles of Student's t for 1 to 60 degrees of freedom.
_T975 = (
    12.7062, 4.3027, 3.1824, 2.7764, 2.5706, 2.4469, 2.3646, 2.306, 2.2622, 2.2281,
    2.201, 2.1788, 2.1604, 2.1448, 2.1314, 2.1199, 2.1098, 2.1009, 2.093, 2.086,
    2.0796, 2.0739, 2.0687, 2.0639, 2.0595, 2.0555, 2.0518, 2.0484, 2.0452, 2.0423,
    2.0395, 2.0369, 2.0345, 2.0322, 2.0301, 2.0281, 2.0262, 2.0244, 2.0227, 2.0211,
    2.0195, 2.0181, 2.0167, 2.0154, 2.0141, 2.0129, 2.0117, 2.0106, 2.0096, 2.0086,
    2.0076, 2.0066, 2.0057, 2.0049, 2.004, 2.0032, 2.0025, 2.0017, 2.001, 2.0003,
)
_Z975 = 1.959964


@dataclass
class TrainConfig:
    """Everything a training and its evaluation depend on (the command line's options)."""

    steps: int
    out: str
    envs: int = 4
    scenario: str | None = str(REPO / "scenarios" / "training.toml")
    overrides: list[str] = field(default_factory=list)
    seed: int = 1
    size: int = 64
    defer: bool = False
    baseline: bool = False
    w_ua: float = 1.0
    w_targets: float = 1.0
    eval_seeds: list[int] = field(default_factory=lambda: list(range(1001, 1031)))
    eval_scenario: str | None = None
    eval_overrides: list[str] = field(default_factory=list)
    no_eval: bool = False
    eval_only: bool = False
    eval_sampled: bool = False
    eval_every: int | None = None
    fleet: str | None = None
    max_hours: float | None = None
    ppo: PPOConfig = field(default_factory=PPOConfig)


# --------------------------------------------------------------------------------------------
# Command line


def parse_seeds(text: str) -> list[int]:
    """Seeds written as ``a..b`` ranges (inclusive) and single seeds, comma-separated."""
    seeds: list[int] = []
    for part in text.split(","):
        lo, sep, hi = part.strip().partition("..")
        seeds += list(range(int(lo), int(hi) + 1)) if sep else [int(lo)]
    if not seeds or len(set(seeds)) != len(seeds):
        raise argparse.ArgumentTypeError(f"{text!r}: at least one seed, none twice")
    return seeds


def _scenario_path(text: str) -> str:
    """A scenario path as given if it exists from here, else from the repository's root."""
    p = Path(text)
    return str(p.resolve() if p.is_absolute() or p.exists() else REPO / p)


def parse_args(argv: Sequence[str] | None = None) -> TrainConfig:
    """The command line as a :class:`TrainConfig` (``--help`` lists the options)."""
    d, dp = TrainConfig(steps=0, out=""), PPOConfig()
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0].replace("\n", " "))
    p.add_argument("--steps", type=int, default=None,
                   help="environment steps to train for (required unless --eval-only)")
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument("--envs", type=int, default=d.envs, help="environments in the vector")
    p.add_argument("--scenario", default="scenarios/training.toml",
                   help="training scenario (relative paths: from here, else the repository)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="training scenario override (repeatable)")
    p.add_argument("--seed", type=int, default=d.seed, help="seed of the environments and of PPO")
    p.add_argument("--defer", action=argparse.BooleanOptionalAction, default=d.defer,
                   help="one more action: defer to the UAV's own planner (the paper's)")
    p.add_argument("--defer-bias", type=float, default=dp.defer_bias,
                   help="initial logit bias of the deferring action")
    p.add_argument("--baseline", action=argparse.BooleanOptionalAction, default=d.baseline,
                   help="rewards relative to the paper's own run of the same seed")
    p.add_argument("--w-ua", type=float, default=d.w_ua, help="reward weight of the decrease of X̄")
    p.add_argument("--w-targets", type=float, default=d.w_targets,
                   help="reward weight of the decrease of the cars' sets")
    p.add_argument("--eval-seeds", type=parse_seeds, default=d.eval_seeds,
                   help="held-out seeds, e.g. 1001..1030 (default)")
    p.add_argument("--eval-scenario", default=None, help="evaluation scenario (default: the paper's)")
    p.add_argument("--eval-set", dest="eval_overrides", action="append", default=[],
                   metavar="KEY=VALUE", help="evaluation scenario override (repeatable)")
    p.add_argument("--no-eval", action="store_true", help="skip the evaluation")
    p.add_argument("--eval-only", action="store_true",
                   help="no training: evaluate the policy already in --out (policy.npz)")
    p.add_argument("--eval-sampled", action="store_true",
                   help="evaluate the policy's sampled actions (seeded by each run's seed), "
                        "not its most probable ones")
    p.add_argument("--eval-every", type=int, default=None, metavar="N",
                   help="also save and evaluate the policy alone every N updates")
    p.add_argument("--fleet", default=None, help="the fleet binary for the evaluation")
    p.add_argument("--max-hours", type=float, default=None, help="stop training after this wall time")
    p.add_argument("--lr", type=float, default=dp.lr)
    p.add_argument("--rollout", type=int, default=dp.rollout, help="steps per environment per update")
    p.add_argument("--epochs", type=int, default=dp.epochs)
    p.add_argument("--minibatch", type=int, default=dp.minibatch, help="transitions per gradient step")
    p.add_argument("--gamma", type=float, default=dp.gamma)
    p.add_argument("--gae-lambda", type=float, default=dp.gae_lambda)
    p.add_argument("--clip", type=float, default=dp.clip)
    p.add_argument("--ent-coef", type=float, default=dp.ent_coef)
    p.add_argument("--hidden", default=",".join(map(str, dp.hidden)), help="hidden layers' widths")
    p.add_argument("--pool", type=int, default=dp.pool, help="side of the pooled set rasters")
    a = p.parse_args(argv)
    if a.eval_only and a.no_eval:
        p.error("--eval-only and --no-eval exclude each other")
    if a.steps is None:
        if not a.eval_only:
            p.error("--steps is required (unless --eval-only)")
        a.steps = 1
    if a.steps < 1 or a.envs < 1 or a.rollout < 1 or a.epochs < 1 or a.minibatch < 1:
        p.error("--steps, --envs, --rollout, --epochs and --minibatch must be at least 1")
    if a.eval_every is not None and a.eval_every < 1:
        p.error("--eval-every must be at least 1")
    if set(a.eval_seeds) & set(TRAIN_SEEDS):
        print(f"warning: held-out seeds in {TRAIN_SEEDS.start}..{TRAIN_SEEDS.stop - 1} may also "
              "be training seeds", file=sys.stderr)
    ppo = replace(dp, lr=a.lr, rollout=a.rollout, epochs=a.epochs, minibatch=a.minibatch,
                  gamma=a.gamma, gae_lambda=a.gae_lambda, clip=a.clip, ent_coef=a.ent_coef,
                  hidden=tuple(int(h) for h in a.hidden.split(",")), pool=a.pool,
                  defer_bias=a.defer_bias)
    return TrainConfig(
        steps=a.steps, out=a.out, envs=a.envs, scenario=_scenario_path(a.scenario),
        overrides=a.overrides, seed=a.seed, defer=a.defer, baseline=a.baseline,
        w_ua=a.w_ua, w_targets=a.w_targets,
        eval_seeds=a.eval_seeds,
        eval_scenario=None if a.eval_scenario is None else _scenario_path(a.eval_scenario),
        eval_overrides=a.eval_overrides, no_eval=a.no_eval, eval_only=a.eval_only,
        eval_sampled=a.eval_sampled,
        eval_every=a.eval_every,
        fleet=a.fleet, max_hours=a.max_hours, ppo=ppo,
    )


# --------------------------------------------------------------------------------------------
# Training


def make_sim_env(config: TrainConfig) -> Any:
    """The training vector environment: ``SimVectorEnv`` with UAV 0 learning."""
    from setfleet.vector import SimVectorEnv

    return SimVectorEnv(num_envs=config.envs, scenario=config.scenario, overrides=config.overrides,
                        variant="paper", learner=0, size=config.size, seed=config.seed,
                        seed_range=(TRAIN_SEEDS.start, TRAIN_SEEDS.stop - 1),
                        defer=config.defer, baseline=config.baseline,
                        w_ua=config.w_ua, w_targets=config.w_targets)


def _mean(values: Sequence[float]) -> float | None:
    return float(np.mean(values)) if len(values) else None


def _cell(v: Any) -> Any:
    """A CSV cell: empty for ``None``, floats to 6 significant digits."""
    if v is None:
        return ""
    return f"{v:.6g}" if isinstance(v, float) else v


def train(config: TrainConfig, make_env: Callable[[TrainConfig], Any] = make_sim_env) -> dict[str, Any]:
    """Trains on ``make_env(config)`` until ``config.steps`` transitions or
    ``config.max_hours``; writes ``curve.csv``, ``curve.png``, ``policy.npz`` and
    ``train.json`` into ``config.out`` and returns ``train.json``'s content."""
    out = Path(config.out)
    out.mkdir(parents=True, exist_ok=True)
    env = make_env(config)
    rows: list[dict[str, Any]] = []
    try:
        ppo = PPO(env, config.ppo, seed=config.seed)
        start = time.monotonic()
        steps = episodes = updates = 0
        finished_violations = 0
        stopped = "steps"
        with open(out / "curve.csv", "w", newline="") as f:
            writer = csv.writer(f)
            writer.writerow(CURVE_COLUMNS)
            while steps < config.steps:
                if config.max_hours is not None and time.monotonic() - start >= config.max_hours * 3600:
                    stopped = "max_hours"
                    break
                t0 = time.monotonic()
                rollout = ppo.collect()
                stats = ppo.update(rollout)
                updates += 1
                steps += rollout.steps
                episodes += len(rollout.episodes)
                finished_violations += sum(int(e.info.get("violations", 0)) for e in rollout.episodes)
                running = sum(int(i.get("violations", 0)) for i in ppo.running_info)
                now = time.monotonic()
                row = {
                    "env_steps": steps,
                    "episodes": episodes,
                    "mean_return": _mean([e.ret for e in rollout.episodes]),
                    "mean_final_ua": _mean([e.info["ua"] for e in rollout.episodes if "ua" in e.info]),
                    "violations": finished_violations + running,
                    "wall_s": now - start,
                    "steps_per_s": rollout.steps / max(now - t0, 1e-9),
                    "defer_share": (float(np.mean(rollout.actions == ppo.policy.config.n_actions - 1))
                                    if ppo.policy.config.defer else None),
                    **stats,
                }
                rows.append(row)
                writer.writerow([_cell(row[c]) for c in CURVE_COLUMNS])
                f.flush()
                print(f"update {updates}: {steps} steps, return {_cell(row['mean_return'])}, "
                      f"UA {_cell(row['mean_final_ua'])}, defer {_cell(row['defer_share'])}, "
                      f"{row['steps_per_s']:.1f} steps/s", flush=True)
                if config.eval_every and updates % config.eval_every == 0:
                    checkpoint_eval(config, ppo.policy, steps)
        ppo.policy.save(out / "policy.npz")
    finally:
        env.close()
    summary = {
        "config": asdict(config),
        "env_steps": steps,
        "episodes": episodes,
        "updates": updates,
        "wall_s": time.monotonic() - start,
        "stopped_by": stopped,
        "violations": rows[-1]["violations"] if rows else 0,
        "policy": str(out / "policy.npz"),
    }
    (out / "train.json").write_text(json.dumps(summary, indent=1))
    plot_curve(rows, out / "curve.png")
    return summary


def plot_curve(rows: Sequence[dict[str, Any]], path: Path) -> None:
    """Return and final UA against environment steps, as a PNG (skipped, with a note,
    without matplotlib)."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print(f"matplotlib is not installed: no {path.name}")
        return
    fig, (ax_r, ax_u) = plt.subplots(2, 1, sharex=True, figsize=(7, 6))
    for ax, key, label in ((ax_r, "mean_return", "mean episode return"),
                           (ax_u, "mean_final_ua", "mean final UA (lower is better)")):
        pts = [(r["env_steps"], r[key]) for r in rows if r[key] is not None]
        if pts:
            ax.plot(*zip(*pts), marker=".")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    ax_u.set_xlabel("environment steps")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


# --------------------------------------------------------------------------------------------
# Evaluation


def t_quantile_975(df: int) -> float:
    """The 97.5 % quantile of Student's t with ``df`` degrees of freedom: scipy's when it
    is installed, else a table up to 60 and the normal's beyond."""
    try:
        from scipy.stats import t
    except ImportError:
        return _T975[df - 1] if df <= len(_T975) else _Z975
    return float(t.ppf(0.975, df))


def paired_interval(a: Sequence[float | None], b: Sequence[float | None]) -> dict[str, Any]:
    """The paired differences ``a − b`` over the pairs where both are known: their count,
    mean, 95 % Student's t interval (``None`` with fewer than two pairs) and the counts of
    pairs with ``a`` lower, higher and equal."""
    d = np.array([x - y for x, y in zip(a, b) if x is not None and y is not None], dtype=float)
    n = len(d)
    result: dict[str, Any] = {
        "n": n,
        "mean_diff": float(d.mean()) if n else None,
        "ci95_low": None,
        "ci95_high": None,
        "lower": int((d < 0).sum()),
        "higher": int((d > 0).sum()),
        "tie": int((d == 0).sum()),
    }
    if n >= 2:
        half = t_quantile_975(n - 1) * float(d.std(ddof=1)) / math.sqrt(n)
        result["ci95_low"], result["ci95_high"] = result["mean_diff"] - half, result["mean_diff"] + half
    return result


def fly(config: TrainConfig, seed: int, variant: str, policy: Policy | None, out: Path) -> dict[str, Any]:
    """One evaluation run of ``seed``: ``policy`` flying UAV 0 over the paper's planner
    (variant ``learned``), or ``variant`` alone; its final UA and violations (``None`` for
    a run that failed, with the reason printed)."""
    row: dict[str, Any] = {"seed": seed, "variant": variant, "ua_final": None, "violations": None,
                           "deferred": None}
    learned = policy is not None
    if not learned and (out / "summary.json").exists():
        # A baseline does not depend on the policy: one flown before (an evaluation resumed,
        # or another policy evaluated into the same directory) is read back.
        try:
            summary = setfleet.read_summary(out)
            row["ua_final"], row["violations"] = summary["ua_final"], summary["violations"]
            return row
        except (OSError, ValueError, KeyError) as e:
            print(f"seed {seed}, {variant}: {out}/summary.json unreadable ({e}): flown again",
                  file=sys.stderr)
    try:
        with setfleet.Run(scenario=config.eval_scenario, seed=seed,
                          variant="paper" if learned else variant, external=[0] if learned else None,
                          out=out, overrides=config.eval_overrides, fleet=config.fleet) as run:
            planner = (PolicyPlanner(policy, deterministic=not config.eval_sampled, seed=seed)
                       if learned else None)
            result = run.serve(planner) if planner is not None else run.wait()
    except Exception as e:  # noqa: BLE001 - one failed run must not lose the others
        print(f"seed {seed}, {variant}: the run failed: {e}", file=sys.stderr)
        return row
    if result.summary is None:
        print(f"seed {seed}, {variant}: no summary (exit code {result.exit_code}), see {out}",
              file=sys.stderr)
    row["ua_final"], row["violations"] = result.ua_final, result.violations
    if planner is not None and planner.decisions:
        row["deferred"] = planner.deferrals / planner.decisions
    return row


def evaluate(config: TrainConfig, policy: Policy) -> dict[str, Any]:
    """Every held-out seed flown by the policy and by both baselines; writes ``eval.csv``
    and ``eval.json`` into ``config.out``, prints a summary and returns ``eval.json``'s
    content."""
    out = Path(config.out)
    rows = []
    for seed in config.eval_seeds:
        for variant in EVAL_VARIANTS:
            rows.append(fly(config, seed, variant, policy if variant == "learned" else None,
                            out / "eval" / f"seed-{seed}" / variant))
    with open(out / "eval.csv", "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(("seed", "variant", "ua_final", "violations", "deferred"))
        writer.writerows((r["seed"], r["variant"], _cell(r["ua_final"]), _cell(r["violations"]),
                          _cell(r["deferred"])) for r in rows)
    ua = {v: [r["ua_final"] for r in rows if r["variant"] == v] for v in EVAL_VARIANTS}
    report = {
        "scenario": config.eval_scenario,
        "overrides": config.eval_overrides,
        "sampled": config.eval_sampled,
        "seeds": config.eval_seeds,
        "mean_ua_final": {v: _mean([u for u in ua[v] if u is not None]) for v in EVAL_VARIANTS},
        "learned-paper": paired_interval(ua["learned"], ua["paper"]),
        "learned-setfleet": paired_interval(ua["learned"], ua["setfleet"]),
        "learned_deferred": _mean([r["deferred"] for r in rows if r["deferred"] is not None]),
        "violations": sum(r["violations"] or 0 for r in rows),
        "failed_runs": sum(r["ua_final"] is None for r in rows),
    }
    (out / "eval.json").write_text(json.dumps(report, indent=1))
    print(f"evaluation on {len(config.eval_seeds)} held-out seeds (final UA, lower is better):")
    for v in EVAL_VARIANTS:
        print(f"  {v}: mean {_cell(report['mean_ua_final'][v])}")
    for key in ("learned-paper", "learned-setfleet"):
        c = report[key]
        print(f"  {key}: {_cell(c['mean_diff'])} [{_cell(c['ci95_low'])}, {_cell(c['ci95_high'])}], "
              f"lower on {c['lower']}, higher on {c['higher']}, tied on {c['tie']} of {c['n']}")
    print(f"  decisions deferred by the policy: {_cell(report['learned_deferred'])}")
    print(f"  violations: {report['violations']}; failed runs: {report['failed_runs']}")
    return report


def checkpoint_eval(config: TrainConfig, policy: Policy, steps: int) -> None:
    """Saves ``checkpoints/policy-{steps}.npz`` and appends the policy's mean final UA and
    violations over the held-out seeds to ``eval_curve.csv``."""
    out = Path(config.out)
    (out / "checkpoints").mkdir(exist_ok=True)
    policy.save(out / "checkpoints" / f"policy-{steps:09d}.npz")
    rows = [fly(config, s, "learned", policy, out / "checkpoints" / f"eval-{steps:09d}" / f"seed-{s}")
            for s in config.eval_seeds]
    path = out / "eval_curve.csv"
    new = not path.exists()
    with open(path, "a", newline="") as f:
        writer = csv.writer(f)
        if new:
            writer.writerow(("env_steps", "mean_ua_final", "violations", "failed_runs"))
        ua = [r["ua_final"] for r in rows if r["ua_final"] is not None]
        writer.writerow((steps, _cell(_mean(ua)), sum(r["violations"] or 0 for r in rows),
                         len(rows) - len(ua)))


def main(argv: Sequence[str] | None = None) -> int:
    """Trains (unless ``--eval-only``), then evaluates unless ``--no-eval``; 0 when no
    evaluation run failed."""
    config = parse_args(argv)
    if not config.eval_only:
        train(config)
    if config.no_eval:
        return 0
    report = evaluate(config, Policy.load(Path(config.out) / "policy.npz"))
    return 0 if report["failed_runs"] == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
