"""The CDA policy's side commitment (world/policy.py): the row-by-row kernel against the
numpy statement of the same rule (commit_reference) on random inputs of every case, and the
route side (``route_side_off_course_deg``) against its definition."""

import numpy as np
import pytest

from airspace_sim.world.policy import _commit_kernel, commit_reference


@pytest.mark.parametrize("preference", ["right", "nearest"])
@pytest.mark.parametrize("with_best", [False, True])
@pytest.mark.parametrize("with_route", [False, True])
def test_commit_kernel_matches_the_numpy_rule(preference, with_best, with_route):
    rng = np.random.default_rng(11)
    n, c = 400, 9
    cand = rng.uniform(-0.5, 0.5, (n, c))
    cand[:, 0] = 0.0
    psi = rng.choice([-0.3, -0.0, 0.0, 0.2, np.nan], n) * rng.uniform(0.5, 1.5, n)
    conflict = rng.random(n) < 0.7
    side = rng.choice([-1.0, 0.0, 1.0], n)
    first_clear = rng.integers(-1, c, (n, 3))
    best = rng.integers(-1, c, (n, 2)) if with_best else None
    toward = rng.choice([-1.0, 0.0, 1.0], n) if with_route else None
    want_psi, want_side = commit_reference(
        preference, psi, conflict, side, cand, first_clear, best, toward
    )
    got_psi, got_side = _commit_kernel(
        psi,
        conflict,
        side,
        cand,
        first_clear,
        best if with_best else np.zeros((n, 2), np.int64),
        with_best,
        preference == "right",
        np.zeros(n) if toward is None else toward,
    )
    assert got_psi.tobytes() == want_psi.tobytes()  # bit for bit, signed zeros included
    np.testing.assert_array_equal(got_side, want_side)
    np.testing.assert_array_equal(np.signbit(got_side), np.signbit(want_side))
    # every case is reached: fresh, kept, flipped back, blocked
    assert (conflict & (side == 0)).any() and (conflict & (side > 0)).any()
    assert (first_clear < 0).any(axis=0).all()


@pytest.mark.parametrize("preference", ["right", "nearest"])
def test_route_side_takes_the_first_clear_heading_toward_the_route(preference):
    # the definition, row by row: in conflict with a route side that has a clear heading,
    # that side's first clear candidate and the route side committed; else the rule without it
    rng = np.random.default_rng(5)
    n, c = 400, 9
    cand = rng.uniform(-0.5, 0.5, (n, c))
    psi = rng.uniform(-0.3, 0.3, n)
    conflict = rng.random(n) < 0.7
    side = rng.choice([-1.0, 0.0, 1.0], n)
    first_clear = rng.integers(-1, c, (n, 3))
    best = rng.integers(-1, c, (n, 2))
    toward = rng.choice([-1.0, 0.0, 1.0], n)
    got_psi, got_side = commit_reference(
        preference, psi, conflict, side, cand, first_clear, best, toward
    )
    plain_psi, plain_side = commit_reference(
        preference, psi, conflict, side, cand, first_clear, best
    )
    taken = 0
    for r in range(n):
        at = first_clear[r, 0] if toward[r] < 0 else first_clear[r, 1]
        if conflict[r] and toward[r] != 0 and at >= 0:
            assert (got_psi[r], got_side[r]) == (cand[r, at], toward[r])
            taken += 1
        else:
            assert (got_psi[r], got_side[r]) == (plain_psi[r], plain_side[r])
    assert taken > n // 4
    # the route side overrides a committed side that points away from the route
    assert (conflict & (toward * side < 0) & (got_side == toward)).any()
