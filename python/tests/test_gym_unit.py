"""The environments' observation without a run: area-preserving resampling, spaces."""

from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip("gymnasium")

from setfleet import Observation, encode_request  # noqa: E402
from setfleet.gym import SearchEnv, SetsRaster, observe  # noqa: E402


def request(nx: int = 50, ny: int = 50, **kw) -> Observation:
    rng = np.random.default_rng(1)
    und = rng.integers(0, 26, size=(ny, nx)).astype(np.uint16)
    return Observation(encode_request(undetected=und, **kw))


@pytest.mark.parametrize("size", [16, 64, 37])
def test_resampling_keeps_areas(size):
    obs = request(nx=50, ny=50)
    raster = SetsRaster(size)
    frac = obs.fraction(obs.undetected)
    out = raster(frac, obs.plan)
    x0, x1, y0, y1 = obs.plan.extent
    pixel = (x1 - x0) / size * (y1 - y0) / size
    assert out.dtype == np.float32 and out.shape == (size, size)
    assert float(out.sum()) * pixel == pytest.approx(float(frac.sum()) * obs.plan.cell_area_m2, rel=1e-4)
    full = raster(np.ones((50, 50), np.float32), obs.plan)
    assert np.allclose(full, 1.0) and full.max() <= 1.0


def test_the_south_west_corner_stays_at_row_0_column_0():
    und = np.zeros((40, 40), np.uint16)
    und[:4, :4] = 25
    obs = Observation(encode_request(undetected=und))
    out = SetsRaster(10)(obs.fraction(obs.undetected), obs.plan)
    assert out[0, 0] == pytest.approx(1.0) and out[1:, :].sum() == 0 and out[:, 1:].sum() == 0


def test_observation_fits_the_space():
    obs = request(
        targets=[(1, 3, 4, np.full((2, 2), 25)), (2, 4, 4, np.full((2, 2), 25))],
        pose=(30.0, -40.0, 70.0, math.pi / 2),
        border_half_m=50.0,
    )
    env = SearchEnv(size=32)
    try:
        o = observe(obs, SetsRaster(32))
        assert o in env.observation_space
        assert o["pose"].tolist() == pytest.approx([0.6, -0.8, 0.0, 1.0], abs=1e-6)
        # The overlapping cars' counts add up but never past a full cell.
        assert obs.targets_dense().max() == 25 and obs.targets_dense().sum() == 25 * 6
        assert o["sets"][1].sum() > 0
        assert env.action_space.n == 5
    finally:
        env.close()
