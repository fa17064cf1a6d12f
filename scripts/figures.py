#!/usr/bin/env python3
"""Remake the tables, JSON files and pictures the README and docs/ show.

    python3 scripts/figures.py --list                    # the entries and what made each file
    python3 scripts/figures.py --only frame --dry-run    # the commands, run nothing
    python3 scripts/figures.py --only table,table-sets --jobs 2

The entries, their `fleet` commands and the files they write are in docs/figures.toml. Each
entry runs its commands from the repository's root into a scratch directory of its own
(target/figures/NAME-<UTC time>/); its sweeps share a run cache (target/figures/cache,
`fleet sweep --cache`), so a run that several figures show runs once per build. Only when
every command succeeded are its files copied into
docs/, and docs/manifest.json then records for each file the commands, the commit, the UTC
date and the entry, with "remade": true. The commit is `git rev-parse HEAD` when the script
starts, with "-dirty" if tracked files other than the figures and the manifest had
uncommitted changes then.

Python 3.10 or later and no packages beyond the standard library; docs/figures.toml is read
with tomllib (3.11) or, on 3.10, the tomli package.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
FIGURES = ROOT / "docs" / "figures.toml"
MANIFEST = ROOT / "docs" / "manifest.json"


class FigureError(Exception):
    """A problem with the list, the manifest or an entry's run, said to the user as is."""


def load_figures() -> list[dict]:
    """The entries of docs/figures.toml, checked for what this script relies on."""
    try:
        import tomllib
    except ModuleNotFoundError:
        try:
            import tomli as tomllib  # Python 3.10
        except ModuleNotFoundError:
            raise FigureError(
                "reading docs/figures.toml needs Python 3.11 (tomllib) or the tomli package"
            ) from None
    with FIGURES.open("rb") as f:
        entries = tomllib.load(f).get("figure", [])
    names = set()
    for entry in entries:
        name = entry.get("name", "?")
        for key in ("name", "about", "source", "commands", "copy"):
            if not entry.get(key):
                raise FigureError(f"docs/figures.toml: entry {name!r} has no {key}")
        if name in names:
            raise FigureError(f"docs/figures.toml: two entries are named {name!r}")
        names.add(name)
    return entries


def load_manifest() -> dict:
    if not MANIFEST.exists():
        return {"outputs": {}}
    return json.loads(MANIFEST.read_text())


def save_manifest(manifest: dict) -> None:
    manifest["outputs"] = dict(sorted(manifest["outputs"].items()))
    MANIFEST.write_text(json.dumps(manifest, indent=2, ensure_ascii=False) + "\n")


def outputs(entry: dict) -> list[str]:
    return [c["to"] for c in entry["copy"]]


def git(*args: str) -> str:
    return subprocess.run(
        ["git", *args], cwd=ROOT, check=True, capture_output=True, text=True
    ).stdout


def commit_id(ignored: set[str]) -> str:
    """HEAD, with "-dirty" when a tracked file outside `ignored` has uncommitted changes."""
    head = git("rev-parse", "HEAD").strip()
    changed = {line[3:] for line in git("status", "--porcelain", "--untracked-files=no").splitlines()}
    return head + "-dirty" if changed - ignored else head


def utc_now() -> datetime.datetime:
    return datetime.datetime.now(datetime.timezone.utc).replace(microsecond=0)


def commands(entry: dict, args: argparse.Namespace, out: str) -> list[str]:
    """The entry's commands with `{fleet}`, `{out}`, `{jobs}` and `{cache}` filled in,
    shell-quoted."""
    values = {
        "{fleet}": shlex.quote(args.fleet),
        "{out}": shlex.quote(out),
        "{jobs}": str(args.jobs),
        "{cache}": shlex.quote(args.cache),
    }
    filled = []
    for command in entry["commands"]:
        for key, value in values.items():
            command = command.replace(key, value)
        filled.append(command)
    return filled


def check_output(source: Path, copy: dict) -> None:
    """Fails unless `copy` can be made: its file was written, its `below` line is there."""
    if not source.is_file():
        raise FigureError(f"{os.path.relpath(source, ROOT)}: the commands did not write it")
    marker = copy.get("below")
    target = ROOT / copy["to"]
    if marker is not None and marker + "\n" not in target.read_text():
        raise FigureError(f"{copy['to']}: no line {marker!r} to write below")


def copy_output(source: Path, copy: dict) -> None:
    """Puts the produced file `source` at `copy["to"]`, below its `below` line if it has one."""
    target = ROOT / copy["to"]
    target.parent.mkdir(parents=True, exist_ok=True)
    marker = copy.get("below")
    if marker is None:
        shutil.copyfile(source, target)
        return
    head, _, _ = target.read_text().partition(marker + "\n")
    target.write_text(head + marker + "\n\n" + source.read_text())


def run_entry(entry: dict, args: argparse.Namespace, commit: str, manifest: dict) -> None:
    """Runs one entry's commands, copies its files and records them in the manifest."""
    name = entry["name"]
    stamp = utc_now().strftime("%Y%m%dT%H%M%SZ")
    base = os.path.relpath((ROOT / args.scratch).resolve() / f"{name}-{stamp}", ROOT)
    out, n = base, 1
    while (ROOT / out).exists():  # the same entry again within the second
        n += 1
        out = f"{base}-{n}"
    filled = commands(entry, args, out)
    print(f"==> {name}: {entry['about']}", flush=True)
    for command in filled:
        print(f"    $ {command}", flush=True)
    for copy in entry["copy"]:
        print(f"    {out}/{copy['from']} -> {copy['to']}", flush=True)
    if args.dry_run:
        return
    (ROOT / out).mkdir(parents=True)
    for command in filled:
        status = subprocess.run(shlex.split(command), cwd=ROOT).returncode
        if status != 0:
            raise FigureError(f"{name}: exit code {status} from: {command}")
    for copy in entry["copy"]:
        check_output(ROOT / out / copy["from"], copy)
    for copy in entry["copy"]:
        copy_output(ROOT / out / copy["from"], copy)
    date = utc_now().isoformat().replace("+00:00", "Z")
    # Read again: another entry (another invocation of this script) may have been recorded
    # since this one started, and its records must stay.
    manifest.clear()
    manifest.update(load_manifest())
    for path in outputs(entry):
        manifest["outputs"][path] = {
            "entry": name,
            "commands": filled,
            "commit": commit,
            "date": date,
            "remade": True,
        }
    save_manifest(manifest)


def list_entries(entries: list[dict], manifest: dict) -> None:
    for entry in entries:
        print(f"{entry['name']}: {entry['about']}")
        for path in outputs(entry):
            record = manifest["outputs"].get(path)
            if record is None:
                state = "not in the manifest"
            elif record.get("pending"):
                state = "not made yet"
            else:
                how = "remade" if record.get("remade") else "recorded from history"
                state = f"{how}, {record.get('commit', '?')[:12]} {record.get('date', '?')}"
                if record.get("stale"):
                    state += ", stale"
            print(f"    {path}  ({state})")


def parse_args(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        description="Remake the tables, JSON files and pictures of README.md and docs/ "
        "from docs/figures.toml, and record them in docs/manifest.json. Relative paths are "
        "from the repository's root.",
    )
    parser.add_argument("--list", action="store_true", help="list the entries and their files")
    parser.add_argument("--only", metavar="NAME[,NAME]", help="run these entries only (default: all)")
    parser.add_argument("--dry-run", action="store_true", help="print the commands, run nothing")
    parser.add_argument(
        "--fleet", default="target/release/fleet", metavar="PATH",
        help="the fleet binary, with its sibling binaries (default: target/release/fleet)",
    )
    parser.add_argument("--jobs", type=int, default=2, metavar="N", help="runs at once in each sweep (default: 2)")
    parser.add_argument(
        "--cache", default="target/figures/cache", metavar="DIR",
        help="the sweeps' run cache (`fleet sweep --cache`): a run that an earlier sweep of "
        "the same binaries made is taken from it (default: target/figures/cache)",
    )
    parser.add_argument(
        "--scratch", default="target/figures", metavar="DIR",
        help="where each entry's runs go, in a directory of its own (default: target/figures)",
    )
    args = parser.parse_args(argv)
    if args.jobs < 1:
        parser.error("--jobs: at least 1")
    return args


def main(argv: list[str]) -> int:
    args = parse_args(argv)
    try:
        entries = all_entries = load_figures()
        manifest = load_manifest()
        if args.list:
            list_entries(entries, manifest)
            return 0
        if args.only:
            wanted = args.only.split(",")
            known = {e["name"] for e in entries}
            unknown = [n for n in wanted if n not in known]
            if unknown:
                raise FigureError(f"--only: no entry {', '.join(unknown)}; the entries: {', '.join(sorted(known))}")
            entries = [e for e in entries if e["name"] in wanted]
        if not args.dry_run and not os.access(ROOT / args.fleet, os.X_OK):
            raise FigureError(f"--fleet {args.fleet}: not an executable; build it with `cargo build --release`")
        ignored = {path for e in all_entries for path in outputs(e)} | {"docs/manifest.json"}
        commit = commit_id(ignored)
    except FigureError as e:
        print(f"figures: {e}", file=sys.stderr)
        return 2
    failed = []
    for entry in entries:
        try:
            run_entry(entry, args, commit, manifest)
        except FigureError as e:
            print(f"figures: {e}; its files were left as they were", file=sys.stderr)
            failed.append(entry["name"])
    if failed:
        print(f"figures: failed: {', '.join(failed)}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
