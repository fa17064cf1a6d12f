#!/usr/bin/env python3
"""Scores `paper` sweeps against the five figures the paper gives for its method.

    python3 scripts/fit.py DIR[=LABEL] ...

Each DIR is a `fleet sweep` output (its `table.json`) that ran the `paper` variant. For each
one it prints the five figures' means and standard deviations over the sweep's seeds, the
candidate's miss (the sum over the five of ((mean - paper) / paper's spread)^2) and on how
many of the five the mean lies within the paper's spread. docs/results/calibration.md says
which figure is read how and why.

Standard library only, so that it runs wherever `fleet` does.
"""

import json
import sys
from pathlib import Path

# (label, table.json key, scale to the paper's unit, the paper's value, its spread)
FIGURES = [
    ("UA (%)", "ua_final", 100.0, 19.1, 2.6),
    ("OA (%)", "oa_final", 100.0, 11.2, 1.8),
    ("target-set area, 100-300 s (%)", "target_set_area_window", 100.0, 0.23, 0.14),
    ("error, 100-300 s (m)", "loc_error_m_window", 1.0, 1.0, 0.3),
    # The paper gives no spread for the explored ground; 1 pp is its precision.
    ("explored (%)", "explored_final", 100.0, 94.0, 1.0),
]


def score(table: dict) -> tuple[list[tuple[float, float]], float, int]:
    """The figures' (mean, sd), the miss and how many lie within the paper's spread."""
    metrics = table["metrics"]["paper"]
    stats, miss, within = [], 0.0, 0
    for _, key, scale, paper, spread in FIGURES:
        m = metrics[key]
        mean, sd = m["mean"] * scale, m["sd"] * scale
        stats.append((mean, sd))
        miss += ((mean - paper) / spread) ** 2
        within += abs(mean - paper) <= spread
    return stats, miss, within


def main(argv: list[str]) -> int:
    if not argv or argv[0] in ("-h", "--help"):
        print(__doc__.strip())
        return 0 if argv else 2
    head = ["candidate", "seeds"] + [f[0] for f in FIGURES] + ["miss", "within", "violations"]
    print("| " + " | ".join(head) + " |")
    print("|---|" + "---:|" * (len(head) - 1))
    print("| the paper | | " + " | ".join(f"{f[3]} ± {f[4]}" for f in FIGURES) + " | | | 0 |")
    status = 0
    for arg in argv:
        path, _, label = arg.partition("=")
        file = Path(path) / "table.json"
        try:
            table = json.loads(file.read_text())
            stats, miss, within = score(table)
        except (OSError, ValueError, KeyError) as e:
            print(f"fit.py: {file}: not a paper sweep's table ({e})", file=sys.stderr)
            status = 1
            continue
        seeds = table["seeds"]
        violations = sum(table["metrics"]["paper"]["violations"]["values"])
        cells = [f"{m:.2f} ± {s:.2f}" for m, s in stats]
        print(
            f"| {label or path} | {seeds[0]}-{seeds[-1]} | "
            + " | ".join(cells)
            + f" | {miss:.1f} | {within} / 5 | {violations:g} |"
        )
    return status


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
