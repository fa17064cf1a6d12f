"""Run's helpers and the results readers, without a run."""

from __future__ import annotations

import numpy as np
import pytest

from setfleet import read_summary, read_timeseries, read_tracks
from setfleet.results import track_of
from setfleet.run import (
    FLEET_ENV,
    RUN_ID_RE,
    Latency,
    _external_arg,
    _override_args,
    find_fleet,
    fleet_supports_planner,
    new_run_id,
    run_id_of_prefix,
)


def test_run_ids():
    ids = {new_run_id() for _ in range(50)}
    assert len(ids) == 50 and all(RUN_ID_RE.match(i) for i in ids)
    assert run_id_of_prefix("iox2_sf_r1796426935-13666-0_") == "r1796426935-13666-0"
    assert run_id_of_prefix("iox2_sf_a_b_") == "a_b"
    assert run_id_of_prefix("iox2_sf_demo.h2_") == "demo"
    with pytest.raises(ValueError):
        run_id_of_prefix("iox2_other_")


def test_command_line_pieces():
    assert _external_arg([2, 0, 2]) == "external:0,2"
    assert _external_arg(1) == "external:1"
    assert _external_arg("all") == "external:all"
    assert _external_arg([]) is None and _external_arg(None) is None
    with pytest.raises(ValueError):
        _external_arg("some")
    assert _override_args(["a.b=1"]) == ["--set", "a.b=1"]
    assert _override_args({"x.y": True, "z": 2}) == ["--set", "x.y=true", "--set", "z=2"]
    with pytest.raises(ValueError):
        _override_args(["nokey"])


def test_find_fleet_prefers_the_environment(monkeypatch, tmp_path):
    fake = tmp_path / "fleet"
    monkeypatch.setenv(FLEET_ENV, str(fake))
    assert find_fleet() == fake
    assert find_fleet(tmp_path / "other") == tmp_path / "other"
    assert not fleet_supports_planner(fake)  # does not exist


def test_latency_quantiles():
    lat = Latency.of_ns(np.arange(1, 201) * 1_000_000)
    assert (lat.count, lat.median_ms, lat.p99_ms, lat.max_ms) == (200, 100.0, 198.0, 200.0)
    assert Latency.of_ns([]) is None


def test_results_readers(tmp_path):
    (tmp_path / "summary.json").write_text('{"violations": 0, "agents": [{"uav": 0}]}')
    (tmp_path / "timeseries.csv").write_text("step,time_s,ua,loc_error_m\n0,0,0.5,\n1,0.5,0.25,1.5\n")
    (tmp_path / "tracks.csv").write_text(
        "step,time_s,uav,x,y,z,yaw\n1,0.5,0,1.0,2.0,60.0,0.1\n0,0,0,0.5,1.0,60.0,0.0\n0,0,1,9,9,70,1\n"
    )
    assert read_summary(tmp_path)["violations"] == 0
    ts = read_timeseries(tmp_path)
    assert ts.dtype["step"] == np.int64 and ts.dtype["ua"] == np.float64
    assert ts["ua"].tolist() == [0.5, 0.25] and np.isnan(ts["loc_error_m"][0])
    tracks = read_tracks(tmp_path)
    mine = track_of(tracks, 0)
    assert mine["step"].tolist() == [0, 1] and mine["x"].tolist() == [0.5, 1.0]


def test_results_as_pandas(tmp_path):
    pd = pytest.importorskip("pandas")
    (tmp_path / "timeseries.csv").write_text("step,ua\n0,0.5\n")
    df = read_timeseries(tmp_path, pandas=True)
    assert isinstance(df, pd.DataFrame) and df["ua"].tolist() == [0.5]
