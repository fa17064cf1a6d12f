#!/usr/bin/env python3
"""A greedy planner: turn toward the most undetected ground within reach.

For each yaw increment of the scenario, predict where the UAV is one guidance period later
(the flight model: constant speed, bounded yaw rate), and score the undetected ground X̄ (and,
weighted, the cars' sets) around the centre of the camera's footprint ahead of it there.
Plans that would take the UAV within one period of travel of the border lose to those that
do not.

    python python/examples/greedy.py --seed 1 --duration 30 --out runs/greedy

flies UAV 0 with this planner and the others with the paper's MPC, leaves the run's outputs
in --out and prints the final undetected area and the violations.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

try:
    import setfleet
except ImportError:  # run from a checkout without installing the package
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    import setfleet

from setfleet.cli import run_example
from setfleet.flight import advance, footprint_centre


class GreedyPlanner(setfleet.Planner):
    """One period ahead: the increment whose footprint centre sees the most X̄."""

    def __init__(self, target_weight: float = 4.0) -> None:
        self.target_weight = target_weight

    def decide(self, obs: setfleet.Observation) -> float:
        period, b, g = obs.guidance_period_s, obs.border_half_m, obs.plan
        value = obs.undetected.astype(np.float32)
        if obs.targets:
            value += self.target_weight * obs.targets_dense()
        # Footprint half-width at the optical axis: slant range times tan(aperture / 2).
        slant = obs.z / max(math.sin(obs.camera.tilt_rad), 1e-3)
        r = max(slant * math.tan(obs.camera.aperture_rad / 2), g.cell_m)
        inner = b - obs.speed_mps * period  # one period of travel from the border
        best, best_key = 0.0, None
        for u in obs.increments:
            x, y, yaw = advance(obs.x, obs.y, obs.yaw, obs.yaw + u, period,
                                obs.speed_mps, obs.max_yaw_rate_rps)
            outside = max(abs(x) - inner, 0.0) + max(abs(y) - inner, 0.0)
            fx, fy = footprint_centre(x, y, obs.z, yaw, obs.camera.tilt_rad)
            (x0, y0), (x1, y1) = g.cell_of(fx - r, fy - r), g.cell_of(fx + r, fy + r)
            x0, y0 = max(x0, 0), max(y0, 0)
            x1, y1 = min(x1 + 1, g.nx), min(y1 + 1, g.ny)
            score = 0.0
            if x0 < x1 and y0 < y1:
                cx, cy = g.centre(np.arange(x0, x1), np.arange(y0, y1))
                disc = (cx[None, :] - fx) ** 2 + (cy[:, None] - fy) ** 2 <= r * r
                score = float(value[y0:y1, x0:x1][disc].sum())
            key = (-outside, score, -abs(u))  # inside first, then most to see, then straightest
            if best_key is None or key > best_key:
                best, best_key = float(u), key
        return best


if __name__ == "__main__":
    sys.exit(run_example(GreedyPlanner(), description=__doc__.splitlines()[0]))
