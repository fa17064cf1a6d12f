"""End to end: real runs with planners in Python.

Every test runs twice (the ``fleet`` fixture): against ``fake_fleet.py``, the pure-Python
stand-in, and against the real ``fleet`` binary (``conftest.real_fleet_or_skip``).
Runs are small (a 300 m square, 2 or 3 UAVs) and short.
"""

from __future__ import annotations

import importlib.util
import json
import queue
import signal
import struct
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from conftest import SMALL, SMALL_UAVS, check_search_env
from setfleet import Run, RunEnded, read_summary, read_timeseries, read_tracks
from setfleet.layout import ANSWER_MAGIC, encode_answer_for
from setfleet.results import track_of

pytestmark = pytest.mark.e2e

PYDIR = Path(__file__).resolve().parents[1]
EXAMPLES = PYDIR / "examples"
RUN_TIMEOUT = 150.0
#: The tests whose outcome needs every answer in time (reproducibility, refusals) give the
#: planner 2 s, far beyond its millisecond, so that a loaded machine never makes one late.
PATIENT = SMALL + ["timing.external_planner_ms=2000"]


def load_example(name: str):
    spec = importlib.util.spec_from_file_location(f"example_{name}", EXAMPLES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    assert spec.loader is not None
    spec.loader.exec_module(module)
    return module


def small_run(fleet: Path, out: Path, run_id: str, **kw) -> Run:
    args = dict(seed=3, duration=30, uavs=SMALL_UAVS, overrides=SMALL, external=[0])
    args.update(kw)
    return Run(fleet=fleet, out=out, run_id=run_id, **args)


def set_args(overrides: list[str]) -> list[str]:
    return [a for o in overrides for a in ("--set", o)]


def last_json_line(log: Path) -> dict:
    for line in reversed(log.read_text().splitlines()):
        line = line.strip()
        if line.startswith("{"):
            return json.loads(line)
    raise AssertionError(f"no report line in {log}")


def test_greedy_example_completes_and_flies_its_own_way(fleet, tmp_path, run_id):
    out = tmp_path / "greedy"
    cmd = [
        sys.executable, str(EXAMPLES / "greedy.py"), "--seed", "3", "--duration", "30",
        "--out", str(out), "--uavs", str(SMALL_UAVS), *set_args(SMALL),
        "--fleet", str(fleet), "--run-id", run_id("greedy"),
    ]
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=RUN_TIMEOUT)
    assert p.returncode == 0, p.stdout + p.stderr
    assert "violations: 0 (OK)" in p.stdout and "UA (final)" in p.stdout
    summary = read_summary(out)
    assert summary["violations"] == 0
    assert summary["agents"][0]["external_decisions"] > 0
    assert (out / "timeseries.csv").is_file()

    with small_run(fleet, tmp_path / "paper", run_id("paper"), external=None) as run:
        paper = run.wait(timeout=RUN_TIMEOUT)
    assert paper.exit_code == 0 and paper.violations == 0
    mine, theirs = track_of(read_tracks(out), 0), track_of(paper.tracks(), 0)
    assert len(mine) == len(theirs) > 0
    assert not np.allclose(np.c_[mine["x"], mine["y"]], np.c_[theirs["x"], theirs["y"]])


def test_the_same_seed_twice_gives_the_same_timeseries(fleet, tmp_path, run_id):
    greedy = load_example("greedy")
    outs = []
    for k in range(2):
        out = tmp_path / f"run{k}"
        with small_run(fleet, out, run_id(f"same{k}"), seed=6, overrides=PATIENT) as run:
            result = run.serve(greedy.GreedyPlanner(), timeout=RUN_TIMEOUT)
        assert result.exit_code == 0 and result.violations == 0
        assert result.decisions > 0 and result.latency is not None
        outs.append(out)
    a, b = ((o / "timeseries.csv").read_bytes() for o in outs)
    assert a == b
    assert len(read_timeseries(outs[0])) == 60


ATTACHED_PLANNER = r"""
import sys
sys.path.insert(0, sys.argv[1])
from setfleet import Run, RunEnded
run = Run.attach(sys.argv[2], [0], run_id=sys.argv[3])
while True:
    try:
        req = run.next_request()
    except RunEnded:
        break
    run.answer(req.handle, 0.0)
    print("answered", req.obs.step, flush=True)
"""


def _lines(pipe) -> "queue.Queue[str | None]":
    q: queue.Queue[str | None] = queue.Queue()

    def pump() -> None:
        for line in pipe:
            q.put(line)
        q.put(None)

    threading.Thread(target=pump, daemon=True).start()
    return q


def test_a_killed_planner_leaves_the_run_to_the_fallback(fleet, tmp_path, run_id):
    out = tmp_path / "run"
    rid = run_id("kill")
    cmd = [
        str(fleet), "run", "--out", str(out), "--run-id", rid, "--seed", "4",
        "--duration", "30", "--uavs", str(SMALL_UAVS), *set_args(SMALL),
        "--planner", "external:0",
    ]
    out.mkdir()
    with open(out / "fleet.log", "wb") as log:
        proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
    planner = subprocess.Popen(
        [sys.executable, "-c", ATTACHED_PLANNER, str(PYDIR), str(out), rid],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        lines = _lines(planner.stdout)
        for _ in range(3):
            line = lines.get(timeout=RUN_TIMEOUT)
            assert line is not None and line.startswith("answered"), planner.stderr.read()
        planner.send_signal(signal.SIGKILL)
        planner.wait(timeout=30)
        assert proc.wait(timeout=RUN_TIMEOUT) == 0
    finally:
        for p in (planner, proc):
            if p.poll() is None:
                p.kill()
                p.wait()
    summary = read_summary(out)
    agent = summary["agents"][0]
    assert agent["external_decisions"] >= 1
    assert agent["external_fallbacks"] > 0
    assert summary["violations"] == 0
    assert last_json_line(out / "logs" / "agent-0.log")["end"] == "EndOfRun"


def test_malformed_answers_are_refused_and_fall_back(fleet, tmp_path, run_id):
    out = tmp_path / "run"
    sent = 0
    with small_run(fleet, out, run_id("bad"), seed=5, overrides=PATIENT) as run:
        while True:
            try:
                req = run.next_request(timeout=RUN_TIMEOUT)
            except RunEnded:
                break
            assert req is not None
            step, uav = req.obs.step, req.uav
            if sent == 0:  # garbage
                run.answer_bytes(req.handle, b"\xde\xad\xbe\xef" * 20)
            elif sent == 1:  # the answer to another step
                run.answer_bytes(req.handle, encode_answer_for(step + 1, uav, 0.0))
            elif sent == 2:  # a well-formed header with an increment beyond pi
                data = bytearray(encode_answer_for(step, uav, 0.0))
                data[48:56] = struct.pack("<d", 4.0)
                run.answer_bytes(req.handle, bytes(data))
            elif sent == 3:  # a length its counts do not give
                run.answer_bytes(req.handle, encode_answer_for(step, uav, [0.1, 0.2])[:-8])
            else:
                run.answer(req.handle, 0.0)
            sent += 1
        result = run.wait(timeout=RUN_TIMEOUT)
    assert sent >= 5
    assert result.exit_code == 0 and result.violations == 0
    agent = result.agent(0)
    assert agent["external_fallbacks"] >= 4
    log = (out / "logs" / "agent-0.log").read_text()
    assert log.count("refused") >= 4, log
    assert last_json_line(out / "logs" / "agent-0.log")["end"] == "EndOfRun"
    assert struct.unpack("<I", b"SFPA")[0] == ANSWER_MAGIC


def test_a_planner_exception_stops_the_run_and_is_raised(fleet, tmp_path, run_id):
    run = small_run(fleet, tmp_path / "run", run_id("raise"))
    with pytest.raises(ZeroDivisionError):
        run.serve(lambda obs: 1 / 0)
    assert run.process is not None and run.process.poll() is not None
    run.close()


def test_on_error_fallback_lets_the_run_finish(fleet, tmp_path, run_id):
    calls = []

    def flaky(obs):
        calls.append(obs.step)
        if len(calls) % 2:
            raise RuntimeError("planner bug")
        return 0.0

    overrides = SMALL + ["timing.external_planner_ms=100"]
    with small_run(fleet, tmp_path / "run", run_id("flaky"), overrides=overrides) as run:
        result = run.serve(flaky, on_error="fallback", timeout=RUN_TIMEOUT)
    assert result.exit_code == 0 and result.violations == 0
    assert result.errors == (len(calls) + 1) // 2 and result.errors > 0
    assert result.agent(0)["external_fallbacks"] >= result.errors


ENV_KW = dict(uavs=SMALL_UAVS, overrides=SMALL, size=32, deadline_ms=2000)


def test_search_env_passes_check_env(fleet):
    from setfleet.gym import SearchEnv

    check_search_env(SearchEnv(duration=12, fleet=fleet, **ENV_KW))


def test_parallel_env_passes_the_api_test(fleet):
    from pettingzoo.test import parallel_api_test

    from setfleet.gym import ParallelSearchEnv

    env = ParallelSearchEnv(
        learners=(0, 2), uavs=3, duration=12, overrides=SMALL, size=16, fleet=fleet,
        deadline_ms=2000,
    )
    try:
        parallel_api_test(env, num_cycles=8)
    finally:
        env.close()


def test_an_episode_of_20_steps(fleet, tmp_path):
    from setfleet.gym import SearchEnv

    env = SearchEnv(duration=60, fleet=fleet, out_dir=tmp_path / "episodes", **ENV_KW)
    try:
        obs, info = env.reset(seed=7)
        assert obs in env.observation_space and info["step"] == 0
        env.action_space.seed(7)
        steps, total = 0, 0.0
        terminated = False
        while not terminated:
            obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
            assert obs in env.observation_space and not truncated
            assert np.isfinite(reward)
            steps += 1
            total += reward
            assert steps <= 20
        assert steps == 20
        assert info["step"] == 19 * 6
        result = env.last_result
        assert result is not None and result.exit_code == 0 and result.violations == 0
        assert result.agent(0)["external_decisions"] > 0
        assert (env.run_dir / "tracks.csv").is_file()
    finally:
        env.close()
