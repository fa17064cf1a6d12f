#!/usr/bin/env python3
"""A stand-in for ``fleet run`` that speaks the agents' side of ``docs/python.md`` in pure
Python, so that :class:`setfleet.Run`, the environments and the examples can be tested without
the Rust binaries (the end-to-end tests run the real ``fleet`` when it supports ``--planner``).

It accepts the flags :class:`setfleet.Run` passes, writes ``scenario.toml`` and
``config/iceoryx2.toml`` as the real run does, creates the plan services and events, then
steps a toy world in lockstep: every UAV flies the real flight model, the undetected set is
a count raster cleared around each camera footprint, two cars' sets sit still. At each
guidance step every UAV decides in token order; a UAV of ``--planner external:...`` sends a
request (:func:`setfleet.layout.encode_request`), wakes the planners, waits up to
``timing.external_planner_ms`` for the answer, checks it (:func:`setfleet.decode_answer`) and
falls back on a built-in planner when it is late, malformed (logged in ``logs/agent-{i}.log``)
or absent. The outputs are ``summary.json`` (with ``external_decisions`` and
``external_fallbacks`` per agent), ``timeseries.csv``, ``tracks.csv`` and the logs.

Toy values are not the real run's; only the protocol is meant to be faithful.
"""

from __future__ import annotations

import argparse
import ctypes
import json
import math
import signal
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import iceoryx2 as iox2  # noqa: E402

from setfleet.flight import advance, footprint_centre  # noqa: E402
from setfleet.layout import (  # noqa: E402
    DEFAULT_INCREMENTS,
    LayoutError,
    decode_answer,
    encode_request,
)

TEMPLATE = Path(__file__).with_name("iceoryx2_template.toml")
STOP = False


def _on_term(signum, frame):  # noqa: ANN001
    global STOP
    STOP = True


def parse(argv: list[str]) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="fleet")
    sub = p.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run", help="run the (fake) fleet once")
    r.add_argument("--out", required=True)
    r.add_argument("--run-id", required=True)
    r.add_argument("--seed", type=int, default=1)
    r.add_argument("--duration", type=float, default=300.0)
    r.add_argument("--variant", default="paper")
    r.add_argument("--planner", default=None, help="external:0,2 or external:all")
    r.add_argument("--scenario", default=None)
    r.add_argument("--set", action="append", default=[])
    r.add_argument("--uavs", type=int, default=None)
    r.add_argument("--strict", action="store_true")
    r.add_argument("--mode", default="lockstep")
    return p.parse_args(argv)


class Agent:
    """One fake agent's IPC and counters."""

    def __init__(self, node, run: str, uav: int, external: bool, log: Path) -> None:  # noqa: ANN001
        self.uav = uav
        self.external = external
        self.log = open(log, "a", encoding="utf-8")
        self.decisions = 0
        self.external_decisions = 0
        self.external_fallbacks = 0
        self.reasons: dict[str, int] = {"late": 0, "malformed": 0, "absent": 0}
        wake = node.service_builder(iox2.ServiceName.new(f"{run}/uav/{uav}/wake")).event().open_or_create()
        self.wake_service = wake
        self.listener = wake.listener_builder().create()
        if external:
            u8 = iox2.Slice[ctypes.c_uint8]
            self.plan = (
                node.service_builder(iox2.ServiceName.new(f"{run}/uav/{uav}/plan"))
                .request_response(u8, u8)
                .open_or_create()
            )
            self.client = (
                self.plan.client_builder()
                .initial_max_slice_len(256 * 1024)
                .allocation_strategy(iox2.AllocationStrategy.PowerOfTwo)
                .create()
            )
            pw = node.service_builder(iox2.ServiceName.new(f"{run}/planner/wake")).event().open_or_create()
            self.planner_wake = pw
            self.notifier = pw.notifier_builder().create()

    def say(self, text: str) -> None:
        self.log.write(f"{time.strftime('%Y-%m-%dT%H:%M:%SZ', time.gmtime())}  {text}\n")
        self.log.flush()

    def has_server(self) -> bool:
        return self.plan.dynamic_config.number_of_servers > 0

    def ask(self, payload: bytes):  # noqa: ANN201
        if not self.has_server():
            return None
        req = self.client.loan_slice_uninit(len(payload))
        ctypes.memmove(req.payload_ptr, payload, len(payload))
        pending = req.assume_init().send()
        self.notifier.notify_with_custom_event_id(iox2.EventId.new(self.uav))
        return pending

    def await_answer(self, pending, step: int, deadline_ms: int, node):  # noqa: ANN001, ANN201
        """The decoded answer, or the fallback's reason."""
        if pending is None:
            return "absent"
        until = time.monotonic() + deadline_ms / 1000
        while True:
            resp = pending.receive()
            if resp is not None:
                data = bytes(resp.payload().as_memory_view())
                try:
                    return decode_answer(data, step=step, uav=self.uav)
                except LayoutError as e:
                    self.say(f"WARN external planner's answer refused uav={self.uav} error={e}")
                    return "malformed"
            if not pending.is_connected or not self.has_server():
                return "absent"
            left = until - time.monotonic()
            if left <= 0 or STOP:
                node.try_cleanup_dead_nodes()
                return "late"
            self.listener.timed_wait(iox2.Duration.from_secs_f64(min(left, 0.05)))

    def count(self, result) -> bool:  # noqa: ANN001
        self.decisions += 1
        if isinstance(result, str):
            self.external_fallbacks += 1
            if self.reasons[result] == 0:
                self.say(f"WARN no usable answer from the external planner: reason={result}")
            self.reasons[result] += 1
            return False
        self.external_decisions += 1
        return True


def main(argv: list[str]) -> int:
    a = parse(argv)
    signal.signal(signal.SIGTERM, _on_term)
    sets = dict(s.split("=", 1) for s in a.set)
    half = float(sets.get("region.half_extent_m", 150.0))
    n_uavs = a.uavs if a.uavs is not None else int(sets.get("uavs.count", 4))
    deadline_ms = int(sets.get("timing.external_planner_ms", 1000))
    round_start = sets.get("guidance.external_request", "turn").strip('"') == "round_start"
    dt, spp, speed, rate, tilt = 0.5, 6, 10.0, 1.0, math.pi / 4
    total = int(round(a.duration / dt))
    if a.planner is None:
        external: set[int] = set()
    elif a.planner == "external:all":
        external = set(range(n_uavs))
    else:
        external = {int(u) for u in a.planner.split(":", 1)[1].split(",")}

    out = Path(a.out)
    (out / "logs").mkdir(parents=True, exist_ok=True)
    (out / "config").mkdir(parents=True, exist_ok=True)
    (out / "scenario.toml").write_text(
        f"seed = {a.seed}\nduration_s = {a.duration}\n\n[region]\nhalf_extent_m = {half}\n\n"
        f"[uavs]\ncount = {n_uavs}\nspeed_mps = {speed}\nmax_yaw_rate_rps = {rate}\n\n"
        f"[timing]\ncvs_period_s = {dt}\nguidance_period_s = {dt * spp}\n"
        f"external_planner_ms = {deadline_ms}\n"
    )
    prefix = f"iox2_sf_{a.run_id}_"
    config = out / "config" / "iceoryx2.toml"
    config.write_text(TEMPLATE.read_text().replace("@PREFIX@", prefix))
    cfg = iox2.config.from_file(iox2.FilePath.new(str(config)))
    node = iox2.NodeBuilder.new().config(cfg).create(iox2.ServiceType.Ipc)
    agents = [Agent(node, a.run_id, i, i in external, out / "logs" / f"agent-{i}.log") for i in range(n_uavs)]

    # Planners started with the run get 20 s to come.
    until = time.monotonic() + 20
    while any(ag.external and not ag.has_server() for ag in agents) and time.monotonic() < until and not STOP:
        time.sleep(0.02)

    rng = np.random.default_rng(a.seed)
    cell, count_m2, factor = 2.5, 0.25, 5
    n = int(math.ceil(2 * half / cell))
    und = np.full((n, n), factor * factor, dtype=np.uint16)
    xs = -half + (np.arange(n) + 0.5) * cell
    cx, cy = np.meshgrid(xs, xs)
    cars = []
    for j in range(2):
        x0, y0 = (int(v) for v in rng.integers(0, n - 4, size=2))
        cars.append([j + 1, x0, y0, np.full((4, 4), 25, dtype=np.uint16)])
    poses = []
    for i in range(n_uavs):
        x, y = rng.uniform(-half / 2, half / 2, size=2)
        poses.append([float(x), float(y), 60.0 + 10 * i, float(rng.uniform(-math.pi, math.pi))])
    yaw_refs = [p[3] for p in poses]

    def fallback(i: int) -> float:
        best, best_score = 0.0, -math.inf
        x, y, z, yaw = poses[i]
        for u in DEFAULT_INCREMENTS:
            px, py, pyaw = advance(x, y, yaw, yaw + u, dt * spp, speed, rate)
            if abs(px) > half or abs(py) > half:
                score = -1e9 - math.hypot(px, py)
            else:
                fx, fy = footprint_centre(px, py, z, pyaw, tilt)
                score = float(und[(cx - fx) ** 2 + (cy - fy) ** 2 < 30.0**2].sum())
            if score > best_score:
                best, best_score = u, score
        return yaw + best

    def request(i: int, step: int, others: list, flags_round_start: bool) -> bytes:
        return encode_request(
            undetected=und,
            step=step,
            total_steps=total,
            uav=i,
            fleet_size=n_uavs,
            steps_per_period=spp,
            deadline_ms=deadline_ms,
            round_start=flags_round_start,
            run_id=a.run_id,
            dt_s=dt,
            speed_mps=speed,
            max_yaw_rate_rps=rate,
            pose=poses[i],
            plan_cell_m=cell,
            count_cell_m2=count_m2,
            border_half_m=half,
            targets=[(c[0], c[1], c[2], c[3]) for c in cars],
            others=[] if flags_round_start else others,
            fleet=list(range(n_uavs)),
        )

    series, tracks = [], []
    area = float(und.size * factor * factor)
    step = 0
    for step in range(total):
        if STOP:
            break
        if step % spp == 0:
            plans: list = []
            pendings = {}
            if round_start:
                for i in range(n_uavs):
                    if agents[i].external:
                        pendings[i] = agents[i].ask(request(i, step, [], True))
            for i in range(n_uavs):
                ag = agents[i]
                yaw_ref = None
                if ag.external:
                    pending = pendings[i] if round_start else ag.ask(request(i, step, plans, False))
                    result = ag.await_answer(pending, step, deadline_ms, node)
                    if ag.count(result):
                        yaw_ref = result.yaw_reference(poses[i][3])
                        if result.views.shape[0]:
                            plans.append((i, result.views))
                else:
                    ag.decisions += 1
                if yaw_ref is None:
                    yaw_ref = fallback(i)
                yaw_refs[i] = yaw_ref
                plans.append((i, np.array([poses[i]])))
        for i in range(n_uavs):
            x, y, z, yaw = poses[i]
            x, y, yaw = advance(x, y, yaw, yaw_refs[i], dt, speed, rate)
            poses[i] = [x, y, z, yaw]
            fx, fy = footprint_centre(x, y, z, yaw, tilt)
            seen = (cx - fx) ** 2 + (cy - fy) ** 2 < 25.0**2
            und[seen] = 0
            for c in cars:
                box = seen[c[2] : c[2] + 4, c[1] : c[1] + 4]
                c[3][box] = 0
            tracks.append((step, step * dt, i, x, y, z, yaw))
        ua = float(und.sum()) / area
        series.append((step, step * dt, n_uavs, n_uavs, round(1 - ua, 6), round(ua, 6), 0))

    with open(out / "timeseries.csv", "w", encoding="utf-8") as f:
        f.write("step,time_s,live_agents,estimates,explored,ua,violations\n")
        for r in series:
            f.write(",".join(str(v) for v in r) + "\n")
    with open(out / "tracks.csv", "w", encoding="utf-8") as f:
        f.write("step,time_s,uav,x,y,z,yaw\n")
        for r in tracks:
            f.write(f"{r[0]},{r[1]},{r[2]},{r[3]!r},{r[4]!r},{r[5]!r},{r[6]!r}\n")
    for ag in agents:
        report = {"decisions": ag.decisions, "end": "EndOfRun" if not STOP else "Shutdown"}
        if ag.external:
            report["external"] = {"answered": ag.external_decisions, **ag.reasons}
        ag.log.write(json.dumps(report) + "\n")
        ag.log.close()
    summary = {
        "seed": a.seed,
        "variant": a.variant,
        "uavs": n_uavs,
        "steps": len(series),
        "interrupted": STOP,
        "violations": 0,
        "ua_final": series[-1][5] if series else None,
        "agents": [
            {
                "uav": ag.uav,
                "decisions": ag.decisions,
                "external_decisions": ag.external_decisions,
                "external_fallbacks": ag.external_fallbacks,
            }
            for ag in agents
        ],
        "timing": {"run_id": a.run_id},
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    del agents
    del node
    return 130 if STOP else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
