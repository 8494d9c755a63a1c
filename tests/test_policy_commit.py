"""The CDA policy's side commitment (world/policy.py): the row-by-row kernel against the
numpy statement of the same rule (commit_reference) on random inputs of every case."""

import numpy as np
import pytest

from airspace_sim.world.policy import _commit_kernel, commit_reference


@pytest.mark.parametrize("preference", ["right", "nearest"])
@pytest.mark.parametrize("with_best", [False, True])
def test_commit_kernel_matches_the_numpy_rule(preference, with_best):
    rng = np.random.default_rng(11)
    n, c = 400, 9
    cand = rng.uniform(-0.5, 0.5, (n, c))
    cand[:, 0] = 0.0
    psi = rng.choice([-0.3, -0.0, 0.0, 0.2, np.nan], n) * rng.uniform(0.5, 1.5, n)
    conflict = rng.random(n) < 0.7
    side = rng.choice([-1.0, 0.0, 1.0], n)
    first_clear = rng.integers(-1, c, (n, 3))
    best = rng.integers(-1, c, (n, 2)) if with_best else None
    want_psi, want_side = commit_reference(preference, psi, conflict, side, cand, first_clear, best)
    got_psi, got_side = _commit_kernel(
        psi,
        conflict,
        side,
        cand,
        first_clear,
        best if with_best else np.zeros((n, 2), np.int64),
        with_best,
        preference == "right",
    )
    assert got_psi.tobytes() == want_psi.tobytes()  # bit for bit, signed zeros included
    np.testing.assert_array_equal(got_side, want_side)
    np.testing.assert_array_equal(np.signbit(got_side), np.signbit(want_side))
    # every case is reached: fresh, kept, flipped back, blocked
    assert (conflict & (side == 0)).any() and (conflict & (side > 0)).any()
    assert (first_clear < 0).any(axis=0).all()
