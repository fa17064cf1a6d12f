"""The command line shared by the examples: fly UAV 0 with a planner, the others with a
variant, and report the run."""

from __future__ import annotations

import argparse
import sys
from typing import Callable, Sequence

from .planner import Planner
from .run import Run, RunResult

__all__ = ["example_parser", "run_example", "report"]


def example_parser(description: str) -> argparse.ArgumentParser:
    """``--seed --duration --out --variant --set --uavs --scenario --fleet --run-id
    --external``."""
    p = argparse.ArgumentParser(description=description)
    p.add_argument("--seed", type=int, default=1, help="the run's seed")
    p.add_argument("--duration", type=float, default=None, help="simulated seconds")
    p.add_argument("--out", default=None, help="output directory (default: a temporary one)")
    p.add_argument("--variant", default="paper", help="planner of the other UAVs and fallback")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="scenario override (repeatable)")
    p.add_argument("--uavs", type=int, default=None, help="uavs.count")
    p.add_argument("--scenario", default=None, help="scenario TOML file")
    p.add_argument("--fleet", default=None, help="the fleet binary")
    p.add_argument("--run-id", default=None, help="run id (default: a fresh one)")
    p.add_argument("--external", default="0",
                   help="UAVs this planner flies: a comma-separated list or 'all' (default: 0)")
    return p


def report(result: RunResult, uavs: Sequence[int], out=sys.stdout) -> bool:  # noqa: ANN001
    """Prints the run's UA, violations and the served agents' decisions; whether the run
    completed with 0 violations."""
    s = result.summary
    if s is None:
        print(f"the run wrote no summary (exit code {result.exit_code}); see {result.out}", file=out)
        return False
    print(f"output: {result.out}", file=out)
    print(f"UA (final): {s.get('ua_final')}", file=out)
    for u in uavs:
        try:
            a = result.agent(u)
        except KeyError:
            continue
        print(f"UAV {u}: {a.get('external_decisions')} decisions from this planner, "
              f"{a.get('external_fallbacks')} fallbacks", file=out)
    lat = result.latency
    if lat is not None:
        print(f"planner time per decision: median {lat.median_ms:.3f} ms, p99 {lat.p99_ms:.3f} ms, "
              f"max {lat.max_ms:.3f} ms ({lat.count} decisions)", file=out)
    ok = s.get("violations") == 0 and result.exit_code == 0
    print(f"violations: {s.get('violations')} ({'OK' if ok else 'FAILED'})", file=out)
    return ok


def run_example(
    planner: Planner | Callable[[argparse.Namespace], Planner],
    argv: Sequence[str] | None = None,
    description: str = "",
    add_arguments: Callable[[argparse.ArgumentParser], None] | None = None,
) -> int:
    """Parses the example's command line (:func:`example_parser`, plus ``add_arguments``),
    runs with ``planner`` (or ``planner(args)``), reports; the process's exit code (0 when
    the run completed with 0 violations)."""
    parser = example_parser(description)
    if add_arguments is not None:
        add_arguments(parser)
    args = parser.parse_args(argv)
    if not isinstance(planner, Planner):
        planner = planner(args)
    external = "all" if args.external == "all" else [int(u) for u in args.external.split(",")]
    with Run(
        scenario=args.scenario,
        seed=args.seed,
        variant=args.variant,
        external=external,
        duration=args.duration,
        out=args.out,
        overrides=args.overrides,
        uavs=args.uavs,
        run_id=args.run_id,
        fleet=args.fleet,
    ) as run:
        result = run.serve(planner)
    return 0 if report(result, run.uavs) else 1
