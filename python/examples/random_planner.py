#!/usr/bin/env python3
"""A random planner: each decision, one of the scenario's yaw increments at random (seeded,
so a run is reproducible).

    python python/examples/random_planner.py --seed 1 --duration 30 --out runs/random

flies UAV 0 with this planner and the others with the paper's MPC, leaves the run's outputs
in --out and prints the final undetected area and the violations. The planner's generator is
seeded with the run's --seed (--planner-seed to choose another).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

try:
    import setfleet
except ImportError:  # run from a checkout without installing the package
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    import setfleet

from setfleet.cli import run_example


class RandomPlanner(setfleet.Planner):
    """A uniformly drawn increment per decision; the generator restarts from ``seed`` at
    each run (:meth:`reset`)."""

    def __init__(self, seed: int = 0) -> None:
        self.seed = seed
        self.rng = np.random.default_rng(seed)

    def reset(self) -> None:
        self.rng = np.random.default_rng(self.seed)

    def decide(self, obs: setfleet.Observation) -> float:
        return float(self.rng.choice(obs.increments))


def main(argv: list[str] | None = None) -> int:
    def add(parser: argparse.ArgumentParser) -> None:
        parser.add_argument("--planner-seed", type=int, default=None,
                            help="seed of the planner's generator (default: --seed)")

    return run_example(
        lambda args: RandomPlanner(args.seed if args.planner_seed is None else args.planner_seed),
        argv,
        description=__doc__.splitlines()[0],
        add_arguments=add,
    )


if __name__ == "__main__":
    sys.exit(main())
