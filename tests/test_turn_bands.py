"""The turn-aware band search ("bands-turns", avoidance/turn_bands.py): "bands" where the turn
test finds nothing, the first turn-clear candidate against turn_paths' numpy reference, and a
scene whose choice is known in closed form."""

import math

import numpy as np
import pytest

from airspace_sim import registry
from airspace_sim.avoidance.resolvers import BandsResolver
from airspace_sim.avoidance.turn_bands import (
    TurnAwareBandsResolver,
    first_turn_clear,
    tiered_sides,
)
from airspace_sim.avoidance.turn_paths import turned_path_min_ratio_numpy

RATE = math.radians(3.0)


def _random_scene(seed, n=120, k=5, lookahead_gap=3300.0):
    rng = np.random.default_rng(seed)
    vo = rng.normal(size=(n, 2))
    vo *= rng.uniform(180, 260, (n, 1)) / np.linalg.norm(vo, axis=1, keepdims=True)
    r = rng.uniform(-15000, 15000, (n, k, 2))
    vi = rng.normal(size=(n, k, 2))
    vi *= rng.uniform(180, 260, (n, k, 1)) / np.linalg.norm(vi, axis=-1, keepdims=True)
    valid = (rng.random((n, k)) < 0.85) & (np.hypot(r[..., 0], r[..., 1]) > lookahead_gap)
    return vo, r, vi - vo[:, None], valid, np.full(n, math.pi / 2)


def test_registered():
    assert registry.get("resolver", "bands-turns") is TurnAwareBandsResolver


@pytest.mark.parametrize("seed", [0, 1])
def test_no_turn_is_bands(seed):
    """turn_s = 0: the turning paths are the straight ones, which every clear candidate
    already clears by r_safe·(1 + margin) ≥ r_safe, so the choice and sides are "bands"'."""
    vo, r, v, valid, mx = _random_scene(seed)
    rate = np.full(vo.shape[0], RATE)
    b = BandsResolver(BandsResolver.Params(lookahead_s=45.0))
    t = TurnAwareBandsResolver(TurnAwareBandsResolver.Params(lookahead_s=45.0, turn_s=0.0))
    ob = b.resolve(vo, r, v, valid, mx, turn_rate=rate)
    ot = t.resolve(vo, r, v, valid, mx, turn_rate=rate)
    assert ob.conflict.any()
    np.testing.assert_array_equal(ot.heading_change, ob.heading_change)
    np.testing.assert_array_equal(ot.first_clear, ob.first_clear)
    np.testing.assert_array_equal(ot.conflict, ob.conflict)


@pytest.mark.parametrize("turn_s", [15.0, 30.0])
def test_first_turn_clear_against_reference(turn_s):
    """The kernel's first turn-clear candidate per side is the first clear candidate whose
    left- and right-turning paths (turn_paths' numpy reference, same samples) all stay
    outside the radius; a candidate within 1e-9 of the radius is left out of the check."""
    vo, r, v, valid, mx = _random_scene(2)
    out = TurnAwareBandsResolver(TurnAwareBandsResolver.Params(lookahead_s=45.0)).resolve(
        vo, r, v, valid, mx, turn_rate=np.full(vo.shape[0], RATE)
    )
    cand, clear = out.candidates, out.band
    got = first_turn_clear(vo, r, v, valid, cand, clear, 3000.0, RATE, turn_s, 45.0)
    ref = turned_path_min_ratio_numpy(
        vo, r, v, valid, np.nan_to_num(cand), 3000.0, 45.0, RATE, turn_s
    )
    turned = ref[:, :, 1:, :].min(axis=(1, 2))  # (N, C): left and right hypotheses
    near = np.abs(turned - 1.0) < 1e-9
    assert not near[clear].any()
    ok = clear & (turned >= 1.0)
    found = 0
    for col, mask in enumerate((cand <= 0, cand >= 0, cand < 0)):
        want = np.where((ok & mask).any(axis=1), np.argmax(ok & mask, axis=1), -1)
        np.testing.assert_array_equal(got[:, col], want)
        found += int((want >= 0).sum())
    assert found > 0 and (got < 0).any()  # both outcomes are exercised


def _closed_form_scene():
    """Ownship east at 230 m/s; A stationary 15 km dead ahead; B 3 km ahead and 8 km to the
    right, flying the ownship's velocity (no relative motion)."""
    speed, dist = 230.0, 15000.0
    vo = np.array([[speed, 0.0]])
    r = np.array([[[dist, 0.0], [3000.0, -8000.0]]])
    vi = np.array([[[0.0, 0.0], [speed, 0.0]]])
    return vo, r, vi - vo[:, None], np.ones((1, 2), bool), np.array([math.pi / 2]), dist


def test_closed_form_scene_turns_away_from_the_neighbour_that_may_turn():
    """A stationary intruder at distance D dead ahead is missed by exactly R0 = r_safe·1.1
    at the heading changes ψ = ±asin(R0/D) (miss distance D·|sin ψ|, closest point at
    D·cos ψ/|v| = 64 s < 120 s). "bands" takes the right one (ties go right); B, abeam on
    the right at 8 km with no relative motion, does not block it flying straight but would
    reach the ownship's right-turned path if it began a 3°/s left turn now, so
    "bands-turns" takes the left tangent, on whose side the left one is its first
    turn-clear candidate, and reports a larger right turn as its right side's first."""
    vo, r, v, valid, mx, dist = _closed_form_scene()
    psi_star = math.asin(3300.0 / dist)
    rate = np.array([RATE])
    ob = BandsResolver(BandsResolver.Params()).resolve(vo, r, v, valid, mx, turn_rate=rate)
    assert ob.heading_change[0] == pytest.approx(-psi_star, abs=1e-12)
    for ssf in (False, True):
        res = TurnAwareBandsResolver(TurnAwareBandsResolver.Params(strong_side_first=ssf))
        ot = res.resolve(vo, r, v, valid, mx, turn_rate=rate)
        assert ot.heading_change[0] == pytest.approx(psi_star, abs=1e-12)
        # the right side's first is a turn-clear right turn well past the tangent
        assert ot.candidates[0, ot.first_clear[0, 0]] < -psi_star - math.radians(5)
    # the verdicts behind it, from turn_paths' reference: B's left turn reaches the right
    # tangent's path, not the left one's
    both = np.array([[-psi_star, psi_star]])
    ref = turned_path_min_ratio_numpy(vo, r, v, valid, both, 3000.0, 120.0, RATE, 30.0)
    assert ref[0, 1, 1, 0] < 1.0 < ref[0, 1, 1, 1]
    assert ref[0, 1, 0].min() > 1.1  # straight, B is clear of both


def test_tiered_sides():
    """Columns (ψ ≤ 0, ψ ≥ 0, ψ < 0): a turn-clear index replaces "bands"' one; with
    strong_side_first a side with only clear candidates, when the other side has a
    turn-clear one, is reported blocked and its best blocked is its first clear one."""
    first = np.array([[3, 4, 3], [3, 4, 3], [-1, 4, -1]])
    turn = np.array([[-1, 8, -1], [5, 9, 5], [-1, -1, -1]])
    best = np.array([[-1, -1], [-1, -1], [2, -1]])
    f, b = tiered_sides(first, turn, best)
    np.testing.assert_array_equal(f, [[3, 8, 3], [5, 9, 5], [-1, 4, -1]])
    np.testing.assert_array_equal(b, best)
    f, b = tiered_sides(first, turn, best, strong_side_first=True)
    np.testing.assert_array_equal(f, [[-1, 8, -1], [5, 9, 5], [-1, 4, -1]])
    np.testing.assert_array_equal(b, [[3, -1], [-1, -1], [2, -1]])
