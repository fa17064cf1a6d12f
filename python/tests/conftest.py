"""Shared fixtures: the fleet binaries (the real one, skipped when there is none, and
the pure-Python stand-in ``fake_fleet.py``), unique run ids, small scenarios, and the removal
of the iceoryx2 files of this session's runs."""

from __future__ import annotations

import itertools
import os
import shutil
import stat
import sys
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

from setfleet.run import find_fleet, fleet_supports_planner  # noqa: E402

#: Overrides of a small, fast scenario: a 300 m square, 4 cars (with ``uavs=2``).
SMALL = ["region.half_extent_m=150", "targets.count=4"]
SMALL_UAVS = 2

_ids = itertools.count()
RUN_ID_PREFIX = f"t{os.getpid()}"


@pytest.fixture
def run_id():
    """A factory of run ids unique to this test session: ``t{pid}-{n}-{tag}``."""

    def make(tag: str = "") -> str:
        rid = f"{RUN_ID_PREFIX}-{next(_ids)}" + (f"-{tag}" if tag else "")
        return rid[:40]

    return make


@pytest.fixture(scope="session")
def fake_fleet_bin(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An executable ``fleet`` that runs ``tests/fake_fleet.py`` with this interpreter."""
    d = tmp_path_factory.mktemp("fakebin")
    script = d / "fleet"
    script.write_text(f'#!/bin/sh\nexec "{sys.executable}" "{HERE / "fake_fleet.py"}" "$@"\n')
    script.chmod(script.stat().st_mode | stat.S_IXUSR | stat.S_IXGRP | stat.S_IXOTH)
    return script


def real_fleet_or_skip() -> Path:
    """The real ``fleet`` binary. Without one the test is skipped, saying why; but when
    ``$SETFLEET_FLEET`` names one (as ``.ci/run`` does), a missing binary or one without
    ``fleet run --planner`` fails the test: CI never passes by skipping."""
    required = bool(os.environ.get("SETFLEET_FLEET"))
    try:
        fleet = find_fleet()
    except FileNotFoundError as e:
        if required:
            pytest.fail(f"no fleet binary: {e}")
        pytest.skip(f"no fleet binary: {e}")
    if not fleet_supports_planner(fleet):
        why = f"{fleet} has no `fleet run --planner` (build the workspace of this checkout)"
        if required:
            pytest.fail(why)
        pytest.skip(why)
    return fleet


@pytest.fixture(params=["fake", "real"])
def fleet(request: pytest.FixtureRequest, fake_fleet_bin: Path) -> Path:
    """Each end-to-end test runs twice: against ``fake_fleet.py`` and against the real
    ``fleet`` (:func:`real_fleet_or_skip`)."""
    if request.param == "fake":
        return fake_fleet_bin
    return real_fleet_or_skip()


def _remove_session_files() -> None:
    # This session's run ids: the tests' own and those setfleet.run.new_run_id made here.
    prefixes = [f"iox2_sf_{RUN_ID_PREFIX}-", f"iox2_sf_py{os.getpid()}-"]
    roots = [Path("/dev/shm"), Path("/tmp/iceoryx2")]
    for root, prefix in itertools.product(roots, prefixes):
        if not root.is_dir():
            continue
        for path in root.rglob(f"{prefix}*"):
            try:
                if path.is_dir():
                    shutil.rmtree(path, ignore_errors=True)
                else:
                    path.unlink()
            except OSError:
                pass


@pytest.fixture(scope="session", autouse=True)
def _iceoryx2_files():
    """Removes the iceoryx2 files this session's runs left (the real fleet removes its own;
    the stand-in and killed processes may leave some)."""
    yield
    _remove_session_files()


def check_search_env(env) -> None:
    """Gymnasium's ``check_env`` on ``env`` (closed after), without the warnings the
    environments earn by design (an unbounded pose, no rendering)."""
    import warnings

    from gymnasium.utils.env_checker import check_env

    try:
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message=".*infinity.*")
            warnings.filterwarnings("ignore", message=".*render.*")
            check_env(env, skip_render_check=True)
    finally:
        env.close()
