"""The wire layout: requests decode into zero-copy views, answers round-trip, bad messages
are refused with a reason."""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest

from setfleet import Action, ActionError, LayoutError, Observation, as_action
from setfleet.flight import advance, wrap_angle
from setfleet.layout import (
    ANSWER_HEADER,
    ANSWER_MAGIC,
    ARRAY_NAMES,
    OTHER_ROW,
    REQUEST_HEADER,
    REQUEST_MAGIC,
    TARGET_ROW,
    decode_answer,
    encode_answer,
    encode_answer_for,
    encode_request,
    run_tag,
)


def sample_request(**kw) -> bytes:
    und = np.arange(5 * 7, dtype=np.uint16).reshape(5, 7) % 26
    args = dict(
        undetected=und,
        unseen=np.full((5, 7), 3, dtype=np.uint16),
        recently_hidden=np.eye(5, 7, dtype=np.uint16) * 25,
        obstacle_neighbourhood=np.ones((5, 7), dtype=np.uint16),
        targets=[
            (11, 1, 2, np.array([[1, 2, 3], [4, 5, 6]], dtype=np.uint16)),
            (12, 5, 0, np.array([[25], [25], [7]], dtype=np.uint16), 14.25),
        ],
        others=[(2, np.arange(8.0).reshape(2, 4)), (0, np.ones((1, 4)))],
        fleet=[2, 0, 1],
        fleet_size=3,
        uav=1,
        step=18,
        total_steps=60,
        run_id="abc-1",
        pose=(10.0, -20.0, 70.0, 0.5),
        oem_height=np.full((3, 4), 12.5, dtype=np.float32),
        oem_status=np.full((3, 4), 2, dtype=np.uint8),
    )
    args.update(kw)
    return encode_request(**args)


def test_dtypes_match_the_tables():
    assert REQUEST_HEADER.itemsize == 512
    offsets = {name: REQUEST_HEADER.fields[name][1] for name in REQUEST_HEADER.names}
    assert offsets["magic"] == 0 and offsets["version"] == 4 and offsets["header_bytes"] == 6
    assert offsets["step"] == 16 and offsets["uav"] == 40 and offsets["flags"] == 60
    assert offsets["time_s"] == 64 and offsets["yaw"] == 120
    assert offsets["camera_rows"] == 144 and offsets["plan_origin_x"] == 152
    assert offsets["plan_nx"] == 176 and offsets["count_cell_m2"] == 184
    assert offsets["oem_nx"] == 216 and offsets["border_half_m"] == 224
    assert offsets["targets_m2"] == 240 and offsets["n_increments"] == 248
    assert offsets["n_target_counts"] == 268 and offsets["arrays"] == 272
    assert REQUEST_HEADER.fields["arrays"][0].itemsize == 12 * 16
    assert ANSWER_HEADER.itemsize == 48 and ANSWER_HEADER.fields["planner_ns"][1] == 40
    assert TARGET_ROW.itemsize == 32 and OTHER_ROW.itemsize == 16
    assert len(ARRAY_NAMES) == 12
    assert struct.unpack("<I", b"SFPQ")[0] == REQUEST_MAGIC
    assert struct.unpack("<I", b"SFPA")[0] == ANSWER_MAGIC


def test_run_tag_is_fnv1a():
    assert run_tag("") == 0xCBF29CE484222325
    assert run_tag("a") == 0xAF63DC4C8601EC8C


def test_a_request_decodes_into_views_not_copies():
    buf = bytearray(sample_request())
    obs = Observation(buf)
    whole = np.frombuffer(buf, dtype=np.uint8)
    arrays = [
        obs.increments, obs.undetected, obs.obstacle_neighbourhood, obs.unseen,
        obs.recently_hidden, obs.target_table, obs.target_counts, obs.oem_height,
        obs.oem_status, obs.others_table, obs.poses, obs.fleet,
        obs.targets[0].counts, obs.others[0].poses,
    ]
    for a in arrays:
        assert np.shares_memory(a, whole), a
        assert not a.flags.writeable
    # The views see the bytes: change the payload, the observation changes.
    off = int(obs.header["arrays"][1, 0])
    buf[off : off + 2] = (999).to_bytes(2, "little")
    assert obs.undetected[0, 0] == 999
    # Arrays start at multiples of 8 after the header.
    for off, length in obs.header["arrays"].tolist():
        assert off % 8 == 0 and off >= 512


def test_a_request_decodes_to_what_was_encoded():
    obs = Observation(sample_request())
    assert (obs.step, obs.round, obs.total_steps, obs.uav, obs.fleet_size) == (18, 3, 60, 1, 3)
    assert obs.run_tag == run_tag("abc-1")
    assert obs.pose == (10.0, -20.0, 70.0, 0.5)
    assert obs.time_s == 9.0 and obs.guidance_period_s == 3.0
    assert obs.undetected.shape == (5, 7) and obs.undetected[4, 6] == 34 % 26
    assert obs.plan.nx == 7 and obs.plan.ny == 5 and obs.plan.factor == 5
    assert obs.oem.shape == (3, 4) and obs.oem_height[2, 3] == 12.5 and obs.oem_status[0, 0] == 2
    np.testing.assert_allclose(obs.increments, [-math.pi / 3, -math.pi / 6, 0, math.pi / 6, math.pi / 3])
    t0, t1 = obs.targets
    assert (t0.id, t0.box) == (11, (1, 2, 3, 2))
    assert t0.counts.tolist() == [[1, 2, 3], [4, 5, 6]]
    assert t0.area_m2 == 21 * 0.25 and t1.area_m2 == 14.25
    assert obs.targets_m2 == t0.area_m2 + t1.area_m2
    dense = t0.dense()
    assert dense.shape == (5, 7) and dense[2, 1] == 1 and dense[3, 3] == 6 and dense.sum() == 21
    union = obs.targets_dense()
    assert union[0, 5] == 25 and union[2, 5] == 7 and union[2, 1] == 1
    assert [o.uav for o in obs.others] == [2, 0]
    assert obs.others[0].poses.tolist() == [[0, 1, 2, 3], [4, 5, 6, 7]]
    assert obs.fleet.tolist() == [2, 0, 1]
    assert obs.undetected_m2 == pytest.approx(float(obs.undetected.sum()) * 0.25)
    assert not obs.round_start and not obs.is_last_decision
    assert Observation(sample_request(step=54)).is_last_decision
    assert Observation(sample_request(round_start=True, others=[])).round_start


def test_grid_geometry():
    obs = Observation(sample_request())
    g = obs.plan
    assert (g.origin_x, g.origin_y) == (-8.75, -8.75)
    assert g.centre(0, 0) == (-7.5, -7.5)
    assert g.cell_of(-7.5, -7.5) == (0, 0)
    assert g.cell_of(-8.75, -8.76) == (0, -1) and not g.contains(0, -1)
    xs, ys = g.cell_centres()
    assert xs.shape == (7,) and ys.shape == (5,)
    ix, iy = g.cell_of(xs, ys[:, None].repeat(7, 1)[:, 0])
    assert ix.tolist() == list(range(7)) and iy.tolist() == list(range(5))
    assert obs.fraction(obs.undetected).dtype == np.float32
    assert obs.fraction(np.full((5, 7), 25)).max() == 1.0


def test_copy_owns_its_bytes():
    buf = bytearray(sample_request())
    obs = Observation(buf)
    kept = obs.copy()
    buf[:] = bytes(len(buf))
    assert kept.undetected[4, 6] == 34 % 26 and kept.step == 18
    assert not np.shares_memory(kept.undetected, np.frombuffer(buf, np.uint8))


@pytest.mark.parametrize(
    "mutate, reason",
    [
        (lambda b: b.__setitem__(slice(0, 4), b"XXXX"), "magic"),
        (lambda b: b.__setitem__(slice(4, 6), (2).to_bytes(2, "little")), "version"),
        (lambda b: b.__setitem__(slice(6, 8), (256).to_bytes(2, "little")), "header_bytes"),
        (lambda b: b.__setitem__(slice(176, 180), (8).to_bytes(4, "little")), "undetected"),
        (lambda b: b.__setitem__(slice(272 + 16, 280 + 16), (516).to_bytes(8, "little")), "multiple of 8"),
        (lambda b: b.__setitem__(slice(272, 280), ((len(b) + 15) // 8 * 8).to_bytes(8, "little")), "past"),
        (lambda b: b.__setitem__(slice(272, 280), (8).to_bytes(8, "little")), "inside the header"),
        (lambda b: b.__setitem__(slice(268, 272), (3).to_bytes(4, "little")), "target_counts"),
    ],
)
def test_a_bad_request_is_refused_with_its_reason(mutate, reason):
    buf = bytearray(sample_request())
    mutate(buf)
    with pytest.raises(LayoutError, match=reason):
        Observation(buf)


def test_a_short_request_and_a_bad_table_entry_are_refused():
    with pytest.raises(LayoutError, match="shorter"):
        Observation(b"SFPQ" + bytes(100))
    buf = bytearray(sample_request())
    obs = Observation(buf)
    # Target 11's box widened past the grid.
    off = int(obs.header["arrays"][5, 0])
    buf[off + 4 : off + 8] = (6).to_bytes(4, "little")
    with pytest.raises(LayoutError, match="outside"):
        Observation(buf)
    buf = bytearray(sample_request())
    # Target 12's counts moved past the end of the counts.
    buf[off + 32 + 20 : off + 32 + 24] = (100).to_bytes(4, "little")
    with pytest.raises(LayoutError, match="past"):
        Observation(buf)
    buf = bytearray(sample_request())
    off = int(obs.header["arrays"][9, 0])
    buf[off + 8 : off + 12] = (7).to_bytes(4, "little")
    with pytest.raises(LayoutError, match="poses"):
        Observation(buf)


def test_empty_tables_decode():
    obs = Observation(encode_request(undetected=np.zeros((2, 3), np.uint16), increments=[0.0]))
    assert obs.targets == () and obs.others == () and obs.poses.shape == (0, 4)
    assert obs.target_counts.size == 0 and obs.targets_dense().sum() == 0


def test_answers_round_trip():
    obs = Observation(sample_request())
    views = np.arange(12.0).reshape(3, 4)
    data = encode_answer(obs, Action(increments=[0.5, -0.25], views=views), planner_ns=1234)
    assert len(data) == 48 + 16 + 96
    a = decode_answer(data, step=18, uav=1)
    assert (a.kind, a.step, a.uav, a.planner_ns) == (0, 18, 1, 1234)
    assert a.increments.tolist() == [0.5, -0.25] and a.views.tolist() == views.tolist()
    assert a.yaw_reference(1.0) == 1.5
    a = decode_answer(encode_answer(obs, Action.heading(2.5)), step=18, uav=1)
    assert (a.kind, a.yaw_ref, a.increments.size, a.views.shape) == (1, 2.5, 0, (0, 4))
    a = decode_answer(encode_answer(obs, Action(yaw_ref=-1.0, increments=[0.1])), step=18, uav=1)
    assert a.kind == 1 and a.increments.tolist() == [0.1]


def test_planner_results_are_normalised():
    assert as_action(0.25).increments.tolist() == [0.25]
    assert as_action(np.float32(0.5)).increments.tolist() == [0.5]
    assert as_action(np.array(1)).increments.tolist() == [1.0]
    assert as_action([0.1, 0.2]).increments.tolist() == [0.1, 0.2]
    assert as_action(np.array([0.3])).increments.tolist() == [0.3]
    assert as_action((0.3,)).kind == 0
    act = Action.turn(0.2)
    assert as_action(act) is act
    for bad in (None, True, "left", {"a": 1}):
        with pytest.raises(ActionError):
            as_action(bad)


@pytest.mark.parametrize(
    "action, reason",
    [
        (Action(increments=[]), "1 to 64"),
        (Action(increments=np.zeros(65)), "1 to 64"),
        (Action(increments=[4.0]), "outside"),
        (Action(increments=[math.nan]), "finite"),
        (Action(yaw_ref=math.inf), "finite"),
        (Action(increments=[0.0], views=np.zeros((257, 4))), "256"),
        (Action(increments=[0.0], views=[[0, 0, math.nan, 0]]), "finite"),
    ],
)
def test_an_action_the_agent_would_refuse_is_not_encoded(action, reason):
    with pytest.raises(ActionError, match=reason):
        encode_answer_for(0, 0, action)


def _answer(**fields) -> bytearray:
    data = bytearray(encode_answer_for(6, 2, Action(increments=[0.5, 0.1], views=[[1, 2, 3, 4]])))
    h = np.frombuffer(data, dtype=ANSWER_HEADER, count=1).reshape(())
    for k, v in fields.items():
        h[k] = v
    return data


@pytest.mark.parametrize(
    "data, reason",
    [
        (bytes(20), "shorter"),
        (_answer(magic=0x51504653), "magic"),
        (_answer(version=3), "version"),
        (_answer(kind=3), "kind"),
        (_answer(step=7), "step"),
        (_answer(uav=0), "UAV"),
        (_answer(n_increments=0), "increments"),
        (_answer(n_increments=65), "increments"),
        (_answer(n_poses=1025), "views"),
        (_answer(n_poses=0), "counts give"),
        (_answer()[:-8], "counts give"),
        (_answer(kind=1, yaw_ref=math.nan), "yaw_ref"),
    ],
)
def test_a_malformed_answer_is_refused_with_its_reason(data, reason):
    with pytest.raises(LayoutError, match=reason):
        decode_answer(data, step=6, uav=2)


def test_nonfinite_or_wide_numbers_in_an_answer_are_refused():
    data = _answer()
    data[48:56] = struct.pack("<d", math.inf)
    with pytest.raises(LayoutError, match="finite"):
        decode_answer(data, step=6, uav=2)
    data = _answer()
    data[56:64] = struct.pack("<d", -3.2)
    with pytest.raises(LayoutError, match="outside"):
        decode_answer(data, step=6, uav=2)
    data = _answer()
    data[64 + 16 : 64 + 24] = struct.pack("<d", math.nan)
    with pytest.raises(LayoutError, match="view"):
        decode_answer(data, step=6, uav=2)


def test_flight_model():
    # Straight ahead at 10 m/s for 0.5 s.
    assert advance(0, 0, 0, 0, 0.5, 10, 1) == pytest.approx((5, 0, 0))
    # A full-rate quarter turn is a quarter circle of radius v / rate.
    x, y, yaw = advance(1, 2, 0, math.pi / 2, math.pi / 2, 10, 1)
    assert (x, y, yaw) == pytest.approx((11, 12, math.pi / 2))
    # The yaw stops on the reference, the opposite reference turns counter-clockwise.
    assert advance(0, 0, 0, 0.3, 0.5, 10, 1)[2] == 0.3
    assert advance(0, 0, 0, math.pi, 0.5, 10, 1)[2] == pytest.approx(0.5)
    assert advance(0, 0, 3.0, -3.0, 0.1, 10, 1)[2] == pytest.approx(3.1)
    assert wrap_angle(math.pi) == math.pi and wrap_angle(-math.pi) == math.pi
    assert wrap_angle(0.3) == 0.3 and wrap_angle(-0.3) == pytest.approx(-0.3)
    # Splitting a period does not change where it ends.
    s = (0.0, 0.0, 0.2)
    for _ in range(50):
        s = advance(*s, -1.0, 0.01, 10, 1)
    assert s == pytest.approx(advance(0, 0, 0.2, -1.0, 0.5, 10, 1), abs=1e-9)
