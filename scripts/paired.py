#!/usr/bin/env python3
"""Paired differences between two sweeps of the same seeds, seed by seed.

    python3 scripts/paired.py BASE OTHER [--variant paper] [--metric ua_final ...]

BASE and OTHER are `fleet sweep --out` directories (or one value's directory of an
`--axis` sweep, e.g. `runs/x/timing.cvs_period_s=1.5`); the runs of `--variant` in each
(`VARIANT/seed-N/summary.json`) are paired by seed. For each metric it prints a Markdown row:
the means, the mean difference OTHER - BASE with its 95 % Student's t interval, and on how
many seeds OTHER was lower, higher or equal. `fleet sweep` pairs variants within a sweep;
this pairs two sweeps whose scenarios differ in more than one key (a profile against the
scenario it simplifies).
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
from pathlib import Path

#: Two-sided 95 % quantiles of Student's t, 1 to 40 degrees of freedom; 1.96 beyond.
T975 = (
    12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228, 2.201, 2.179, 2.160,
    2.145, 2.131, 2.120, 2.110, 2.101, 2.093, 2.086, 2.080, 2.074, 2.069, 2.064, 2.060, 2.056,
    2.052, 2.048, 2.045, 2.042, 2.040, 2.037, 2.035, 2.032, 2.030, 2.028, 2.026, 2.024, 2.023,
    2.021,
)

DEFAULT_METRICS = ("ua_final", "oa_final", "explored_final", "target_set_area_mean",
                   "loc_error_mean_m", "identified_final", "violations")


def runs(sweep: Path, variant: str) -> dict[int, dict]:
    """The summaries of `variant`'s runs in `sweep`, by seed."""
    out = {}
    for path in sorted((sweep / variant).glob("seed-*/summary.json")):
        summary = json.loads(path.read_text())
        out[int(summary["seed"])] = summary
    if not out:
        sys.exit(f"no runs of {variant} under {sweep}")
    return out


def row(metric: str, base: dict[int, dict], other: dict[int, dict], seeds: list[int]) -> str:
    pairs = [(base[s].get(metric), other[s].get(metric)) for s in seeds]
    pairs = [(a, b) for a, b in pairs if a is not None and b is not None]
    if not pairs:
        return f"| {metric} | - | - | - | - |"
    d = [b - a for a, b in pairs]
    n = len(d)
    mean = statistics.fmean(d)
    half = (T975[n - 2] if n - 1 <= len(T975) else 1.96) * statistics.stdev(d) / math.sqrt(n) if n > 1 else math.nan
    lower = sum(x < 0 for x in d)
    higher = sum(x > 0 for x in d)
    return (f"| {metric} | {statistics.fmean(a for a, _ in pairs):.4g} | "
            f"{statistics.fmean(b for _, b in pairs):.4g} | {mean:+.4g} [{mean - half:+.4g}, "
            f"{mean + half:+.4g}] | {lower} / {higher} / {n - lower - higher} |")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("base", type=Path)
    p.add_argument("other", type=Path)
    p.add_argument("--variant", default="paper")
    p.add_argument("--metric", action="append", default=None,
                   help=f"summary.json key (repeatable; default: {', '.join(DEFAULT_METRICS)})")
    a = p.parse_args(argv)
    base, other = runs(a.base, a.variant), runs(a.other, a.variant)
    seeds = sorted(set(base) & set(other))
    print(f"{a.variant}, seeds {seeds[0]}..{seeds[-1]} ({len(seeds)} paired): {a.other} against {a.base}")
    print()
    print("| metric | base | other | other - base, 95 % interval | lower / higher / equal |")
    print("|---|---:|---:|---:|---:|")
    for metric in a.metric or DEFAULT_METRICS:
        print(row(metric, base, other, seeds))
    return 0


if __name__ == "__main__":
    sys.exit(main())
