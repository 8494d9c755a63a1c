"""The world metrics' numba kernels against the numpy expressions they replace."""

from __future__ import annotations

import numpy as np
import pytest

from airspace_sim.world.metrics import _closest_pair_distance


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
    got = _closest_pair_distance(keys.astype(np.int64), n, pos)
    assert got == ref
    assert _closest_pair_distance(np.zeros(0, np.int64), n, pos) == np.inf
