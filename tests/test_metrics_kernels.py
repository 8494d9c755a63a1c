"""The world metrics' numba kernels against the numpy expressions they replace."""

from __future__ import annotations

import numpy as np
import pytest

from airspace_sim.world.metrics import WorldMetrics, _closest_pair_distance, _track_errors


@pytest.mark.parametrize("seed", range(4))
def test_closest_pair_distance_equals_the_numpy_minimum(seed):
    rng = np.random.default_rng(seed)
    n = 300
    pos = rng.uniform(-4e4, 4e4, (n, 2))
    # near-ties: pairs at almost the same distance, in either order, and coincident points
    pos[1] = pos[0] + [3000.0, 0.0]
    pos[2] = pos[3] + [0.0, np.nextafter(3000.0, 0.0)]
    pos[4] = pos[5] + [1000.0 * np.sqrt(4.5), 1000.0 * np.sqrt(4.5)]
    if seed == 3:
        pos[7] = pos[8]
    i, j = np.triu_indices(n, 1)
    keys = np.sort(rng.choice(i * n + j, 5000, replace=False))
    keys = np.concatenate([keys, [0 * n + 1, 2 * n + 3, 4 * n + 5, 7 * n + 8]])
    rng.shuffle(keys)
    a, b = keys // n, keys % n
    ref = np.hypot(*(pos[a] - pos[b]).T).min()
    got = _closest_pair_distance(a.astype(np.int64), b.astype(np.int64), pos)
    assert got == ref
    none = np.zeros(0, np.int64)
    assert _closest_pair_distance(none, none, pos) == np.inf


@pytest.mark.parametrize("p", [0, 1, 7, 45_000])
def test_track_errors_equal_the_numpy_differences_and_their_sum(p):
    """:meth:`WorldMetrics.track_states` adds what :meth:`WorldMetrics.tracking` of
    ``x[:, 0:3:2]`` and the gathered true positions adds, bit for bit."""
    rng = np.random.default_rng(p)
    n = 1000
    positions = rng.uniform(-1e5, 1e5, (n, 2))
    intruder = rng.integers(0, n, p)
    x = rng.normal(0.0, 50.0, (p, 5))
    x[:, 0] += positions[intruder, 0]
    x[:, 2] += positions[intruder, 1]
    if p:
        e = _track_errors(x, intruder, positions)
        np.testing.assert_array_equal(e, x[:, 0:3:2] - positions[intruder])
        assert e.flags.c_contiguous
    a, b = WorldMetrics(n, 3000.0, 152.4, 1.0), WorldMetrics(n, 3000.0, 152.4, 1.0)
    for _ in range(2):
        a.tracking(x[:, 0:3:2], np.take(positions, intruder, axis=0))
        b.track_states(x, intruder, positions)
    assert a.sq_err == b.sq_err and a.track_samples == b.track_samples == 2 * p


def test_contacts_with_the_range_pairs_aircraft_equal_contacts_from_the_keys():
    from airspace_sim.world.bodies import LOS, NMAC, RANGE

    rng = np.random.default_rng(9)
    n = 200
    pos = rng.uniform(-2e4, 2e4, (n, 2))
    i, j = np.triu_indices(n, 1)
    keep = np.hypot(*(pos[i] - pos[j]).T) < 8000.0
    i, j = i[keep], j[keep]
    pairs = {LOS: np.zeros(0, np.int64), NMAC: np.zeros(0, np.int64), RANGE: i * n + j}
    began = {t: np.zeros((0, 2), np.int64) for t in (LOS, NMAC, RANGE)}
    a, b = WorldMetrics(n, 3000.0, 152.4, 1.0), WorldMetrics(n, 3000.0, 152.4, 1.0)
    a.contacts(pos, pairs, began)
    b.contacts(pos, pairs, began, (i, j))
    assert np.isfinite(a.min_sep) and a.min_sep == b.min_sep
