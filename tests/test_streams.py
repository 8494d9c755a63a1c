"""Counter-based streams and the radar: the numba kernels give the numpy references' bits."""

import numpy as np
import pytest

from airspace_sim.scenarios.schema import SensorSpec
from airspace_sim.world import streams
from airspace_sim.world.sensors import Radar


def _keys(n, seed=0):
    keys = streams.aircraft_keys(seed, n)
    owner, intruder = np.nonzero(~np.eye(n, dtype=bool))
    return streams.pair_keys(keys, owner, intruder)


@pytest.mark.parametrize("step", [0, 1, 7, 123456])
def test_uniform_and_normal_same_bits(step):
    keys = _keys(60)  # 3540 pairs
    for stream in range(6):
        u = streams.uniform(keys, stream, step)
        assert u.dtype == np.float64
        np.testing.assert_array_equal(u, streams.uniform_numpy(keys, stream, step))
        g = streams.normal(keys, stream, step)
        ref = streams.normal_numpy(keys, stream, step)
        assert np.array_equal(g.view(np.uint64), ref.view(np.uint64))


def test_extreme_keys_same_bits():
    # all-ones, zero and single-bit keys reach the edges of the uniforms' range
    keys = np.array([0, 2**64 - 1, 1, 2**63] + [1 << b for b in range(64)], dtype=np.uint64)
    for step in (0, 3):
        np.testing.assert_array_equal(
            streams.uniform(keys, 2, step), streams.uniform_numpy(keys, 2, step)
        )
        np.testing.assert_array_equal(
            streams.normal(keys, 2, step), streams.normal_numpy(keys, 2, step)
        )


def test_shapes_kept():
    keys = _keys(10).reshape(9, 10)
    assert streams.uniform(keys, 0, 1).shape == (9, 10)
    assert streams.normal(keys, 0, 1).shape == (9, 10)
    assert streams.normal(np.zeros(0, np.uint64), 0, 1).shape == (0,)


def test_normal_is_standard_normal():
    # independent oracle: moments of 40k draws
    g = streams.normal(_keys(200), streams.NOISE_X, 5)
    assert abs(g.mean()) < 0.03 and abs(g.std() - 1.0) < 0.03


@pytest.mark.parametrize("pd,sigma", [(1.0, 0.0), (1.0, 50.0), (0.9, 50.0), (0.5, 0.0)])
def test_radar_measure_same_bits(pd, sigma):
    rng = np.random.default_rng(3)
    n = 40
    positions = rng.uniform(-5e4, 5e4, (n, 2))
    owner, intruder = np.nonzero(~np.eye(n, dtype=bool))
    pk = streams.pair_keys(streams.aircraft_keys(1, n), owner, intruder)
    radar = Radar(SensorSpec(sigma=sigma, detection_probability=pd), 1.0)
    for step in (0, 4):
        z, det = radar.measure(owner, intruder, positions, pk, step)
        # the same draws from the numpy references
        det_ref = np.ones(owner.size, bool)
        if pd < 1.0:
            det_ref = streams.uniform_numpy(pk, streams.DETECT, step) < pd
        z_ref = positions[intruder].copy()
        if sigma > 0:
            z_ref[:, 0] += sigma * streams.normal_numpy(pk, streams.NOISE_X, step)
            z_ref[:, 1] += sigma * streams.normal_numpy(pk, streams.NOISE_Y, step)
        assert z.shape == (owner.size, 2) and det.dtype == bool
        np.testing.assert_array_equal(z, z_ref)
        np.testing.assert_array_equal(det, det_ref)
        if pd < 1.0:
            assert 0 < det.sum() < det.size


@pytest.mark.parametrize("size", [1560, 0, 1, 511, 512, 513, 5000])
def test_add_normals_equals_two_normal_draws(size):
    """The one-pass noise of both axes adds the numbers of two :func:`normal_numpy` draws
    (one pass in key order)."""
    keys = _keys(80)[:size]
    z = np.random.default_rng(2).uniform(-1e5, 1e5, (keys.size, 2))
    ref = z.copy()
    ref[:, 0] += 50.0 * streams.normal_numpy(keys, streams.NOISE_X, 7)
    ref[:, 1] += 50.0 * streams.normal_numpy(keys, streams.NOISE_Y, 7)
    streams.add_normals(z, keys, 50.0, streams.NOISE_X, streams.NOISE_Y, 7)
    np.testing.assert_array_equal(z, ref)
    with pytest.raises(ValueError, match="C-contiguous"):
        streams.add_normals(np.zeros((2, 100)).T, _keys(20)[:100], 1.0, 0, 1, 0)


@pytest.mark.parametrize("n", [0, 1, 2, 30])
def test_directed_pairs_equal_concatenate_mask_and_pair_keys(n):
    rng = np.random.default_rng(n)
    keys = streams.aircraft_keys(4, n)
    i, j = np.triu_indices(n, 1)
    pick = rng.random(i.size) < 0.6
    i, j = i[pick], j[pick]
    owners, present = rng.random(n) < 0.7, rng.random(n) < 0.8
    owner, intruder, pk = streams.directed_pairs(i, j, owners, present, keys)
    # the numpy expression the surveillance phase used to evaluate
    o, t = np.concatenate([i, j]), np.concatenate([j, i])
    keep = owners[o] & present[o] & present[t]
    o, t = o[keep], t[keep]
    np.testing.assert_array_equal(owner, o)
    np.testing.assert_array_equal(intruder, t)
    assert pk.dtype == np.uint64
    np.testing.assert_array_equal(pk, streams.pair_keys(keys, o, t))
    if n == 30:
        assert 0 < owner.size < 2 * i.size
