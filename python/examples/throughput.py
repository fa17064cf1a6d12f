#!/usr/bin/env python3
"""Environment steps per second of the in-process backend: one ``SearchEnv(backend="sim")``,
then ``SimVectorEnv`` of each ``--envs`` size, random actions, on one scenario.

    python python/examples/throughput.py --scenario scenarios/training.toml --envs 1,2,4,8

Each measurement takes ``--steps`` environment steps (summed over the vector) after one
warm-up step, ``--repeats`` times; the table gives the median steps per second and the
ratio to one environment. Set ``OPENBLAS_NUM_THREADS=1`` (this script does when it is not
set): numpy's BLAS threads otherwise spin beside the fleet's.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

try:
    import setfleet  # noqa: F401
except ImportError:  # run from a checkout without installing the package
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from setfleet.gym import SearchEnv  # noqa: E402
from setfleet.vector import SimVectorEnv  # noqa: E402


def single(args: argparse.Namespace) -> float:
    """Steps per second of one environment."""
    env = SearchEnv(backend="sim", scenario=args.scenario, overrides=args.set, size=args.size)
    rng = np.random.default_rng(args.seed)
    try:
        env.reset(seed=args.seed)
        env.step(0)
        start, n = time.perf_counter(), 0
        while n < args.steps:
            _, _, terminated, _, _ = env.step(int(rng.integers(env.action_space.n)))
            n += 1
            if terminated:
                env.reset(seed=args.seed + n)
        return n / (time.perf_counter() - start)
    finally:
        env.close()


def vector(args: argparse.Namespace, envs: int) -> float:
    """Steps per second summed over a vector of ``envs`` environments."""
    venv = SimVectorEnv(envs, scenario=args.scenario, overrides=args.set, size=args.size,
                        threads=args.threads, seed=args.seed)
    rng = np.random.default_rng(args.seed)
    try:
        venv.reset(seed=args.seed)
        venv.step(np.zeros(envs, dtype=np.int64))
        start, n = time.perf_counter(), 0
        while n < args.steps:
            venv.step(rng.integers(venv.single_action_space.n, size=envs))
            n += envs
        return n / (time.perf_counter() - start)
    finally:
        venv.close()


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenario", default=None, help="scenario file (default: the default scenario)")
    p.add_argument("--set", action="append", default=[], help="KEY=VALUE override (repeatable)")
    p.add_argument("--envs", default="1,2,4", help="vector sizes, comma-separated")
    p.add_argument("--steps", type=int, default=60, help="environment steps per measurement")
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--threads", type=int, default=None, help="threads of the vector (default: CPUs)")
    p.add_argument("--size", type=int, default=64, help="side of the observation's rasters")
    p.add_argument("--seed", type=int, default=101)
    p.add_argument("--json", type=Path, default=None, help="also write the results here")
    args = p.parse_args(argv)
    rows = [("SearchEnv", 1, [single(args) for _ in range(args.repeats)])]
    for n in (int(v) for v in args.envs.split(",")):
        rows.append(("SimVectorEnv", n, [vector(args, n) for _ in range(args.repeats)]))
    base = statistics.median(rows[0][2])
    print(f"scenario {args.scenario or 'default'} {' '.join(args.set)}; {os.cpu_count()} CPUs")
    print("| environment | N | steps/s (median) | runs | vs one SearchEnv |")
    print("|---|---:|---:|---|---:|")
    out = []
    for name, n, rates in rows:
        med = statistics.median(rates)
        runs = ", ".join(f"{r:.1f}" for r in rates)
        print(f"| {name} | {n} | {med:.1f} | {runs} | {med / base:.2f}x |")
        out.append({"env": name, "n": n, "steps_per_s": rates, "median": med})
    if args.json is not None:
        args.json.write_text(json.dumps({"scenario": args.scenario, "set": args.set, "rows": out}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
