"""Minimum distance with the ownship and each intruder turning (avoidance/cpa_intruder_turning.py)
against a brute-force oracle (both closed-form paths sampled every 10 ms), the straight closed
form, and the ownship-only turning kernel; and the turn-aware band search built on it."""

import math

import numpy as np
import pytest
from _flight import arc_path

from airspace_sim import registry
from airspace_sim.avoidance.cpa import cpa_min_ratio
from airspace_sim.avoidance.cpa_intruder_turning import cpa_min_ratio_intruder_turning
from airspace_sim.avoidance.cpa_turning import cpa_min_ratio_turning
from airspace_sim.avoidance.flown_bands import FlownBandsResolver, TurnAwareFlownBandsResolver

RATE = math.radians(3.0)
RADIUS = 3300.0


def _scene(seed, n=12, k=5, c=13):
    rng = np.random.default_rng(seed)
    vo = rng.normal(size=(n, 2))
    vo *= rng.uniform(180, 260, (n, 1)) / np.linalg.norm(vo, axis=1, keepdims=True)
    r = rng.uniform(-15000, 15000, (n, k, 2))
    vi = rng.normal(size=(n, k, 2))
    vi *= rng.uniform(180, 260, (n, k, 1)) / np.linalg.norm(vi, axis=-1, keepdims=True)
    valid = rng.random((n, k)) < 0.8
    cand = np.radians(rng.uniform(-90, 90, (n, c)))
    omega = rng.uniform(-1, 1, (n, k)) * RATE
    return vo, r, vi - vo[:, None], valid, cand, omega


def _oracle(vo, r, v, valid, cand, omega, turn_s, lookahead, rate=None):
    """Brute force; ``turn_s`` scalar or (n, k) s, ``rate`` (n,) rad/s the ownships' (default
    RATE; not finite: the heading change at once)."""
    t = np.linspace(0.0, lookahead, int(lookahead * 100) + 1)
    turn_s = np.broadcast_to(turn_s, valid.shape)
    rate = np.full(vo.shape[0], RATE) if rate is None else rate
    out = np.full(cand.shape, np.inf)
    for i in range(cand.shape[0]):
        speed, h0 = np.hypot(*vo[i]), math.atan2(vo[i, 1], vo[i, 0])
        for j, psi in enumerate(cand[i]):
            if np.isfinite(rate[i]):
                ox, oy = arc_path(speed, h0, math.copysign(rate[i], psi), abs(psi) / rate[i], t)
            else:
                ox, oy = arc_path(speed, h0 + psi, 0.0, 0.0, t)
            for q in np.flatnonzero(valid[i]):
                vi = v[i, q] + vo[i]
                ix, iy = arc_path(
                    np.hypot(*vi), math.atan2(vi[1], vi[0]), omega[i, q], turn_s[i, q], t
                )
                d = np.hypot(r[i, q, 0] + ix - ox, r[i, q, 1] + iy - oy).min() / RADIUS
                out[i, j] = min(out[i, j], d)
    return out


@pytest.mark.parametrize("seed, turn_s", [(0, 20.0), (1, 60.0), (2, 200.0)])
def test_matches_the_sampled_oracle(seed, turn_s):
    vo, r, v, valid, cand, omega = _scene(seed)
    rate = np.full(vo.shape[0], RATE)
    got = cpa_min_ratio_intruder_turning(vo, r, v, valid, cand, RADIUS, 120.0, rate, omega, turn_s)
    want = _oracle(vo, r, v, valid, cand, omega, turn_s, 120.0)
    # one-second chords of 3°/s arcs at up to 260 m/s depart from them by under 2 m
    np.testing.assert_allclose(got, want, atol=3.0 / RADIUS, rtol=0)


def test_mixed_turn_durations_and_rates_match_the_sampled_oracle():
    """Turns of different lengths in one row (0, short, longer than any candidate's own turn,
    beyond the look-ahead), intruders straight among them, and ownships that take the heading
    change at once: the kernel evaluates both paths only up to the end of both turns and at
    the look-ahead, which must not change the minimum."""
    vo, r, v, valid, cand, omega = _scene(7, n=10, k=6, c=15)
    rng = np.random.default_rng(7)
    turn_s = rng.choice([0.0, 4.0, 45.0, 300.0], size=valid.shape)
    omega[:, 0] = 0.0
    rate = np.where(np.arange(vo.shape[0]) % 3 == 0, np.inf, RATE)
    got = cpa_min_ratio_intruder_turning(vo, r, v, valid, cand, RADIUS, 90.0, rate, omega, turn_s)
    want = _oracle(vo, r, v, valid, cand, omega, turn_s, 90.0, rate)
    np.testing.assert_allclose(got, want, atol=3.0 / RADIUS, rtol=0)


def test_straight_paths_are_the_closed_form_cpa():
    """Both flying straight (the heading change at once, no intruder turn): the relative track
    is one straight line, so the sampled minimum is the closed-form CPA."""
    vo, r, v, valid, cand, omega = _scene(3)
    n = vo.shape[0]
    got = cpa_min_ratio_intruder_turning(
        vo, r, v, valid, cand, RADIUS, 120.0, np.full(n, np.inf), omega, 0.0
    )
    np.testing.assert_allclose(got, cpa_min_ratio(vo, r, v, valid, cand, RADIUS, 120.0), atol=1e-9)


def test_straight_intruders_are_the_ownship_turning_kernel():
    """Intruders straight: cpa_min_ratio_turning's numbers, up to its 15° chords (≈ 40 m)."""
    vo, r, v, valid, cand, omega = _scene(4)
    rate = np.full(vo.shape[0], RATE)
    got = cpa_min_ratio_intruder_turning(vo, r, v, valid, cand, RADIUS, 120.0, rate, omega, 0.0)
    want = cpa_min_ratio_turning(vo, r, v, valid, cand, RADIUS, 120.0, rate)
    np.testing.assert_allclose(got, want, atol=45.0 / RADIUS, rtol=0)


def test_nan_candidates_and_no_intruders():
    vo, r, v, valid, cand, omega = _scene(5, n=3)
    cand[0, 0] = np.nan
    rate = np.full(3, RATE)
    got = cpa_min_ratio_intruder_turning(vo, r, v, valid, cand, RADIUS, 60.0, rate, omega, 20.0)
    assert np.isnan(got[0, 0]) and np.isfinite(got[0, 1:]).all()
    none = cpa_min_ratio_intruder_turning(
        vo, r[:, :0], v[:, :0], valid[:, :0], cand, RADIUS, 60.0, rate, omega[:, :0], 20.0
    )
    assert np.isinf(none).all()


def _crossing_turner():
    """Ownship east at 230 m/s, turn limit ±90°; an intruder 9 km ahead and 6 km to the left,
    also flying east at 230 m/s (straight, it stays 6 km away: no conflict):
    ``(vo, r, v, valid, mx, rate)``."""
    vo = np.array([[230.0, 0.0]])
    r = np.array([[[9000.0, 6000.0]]])
    v = np.array([[[0.0, 0.0]]])
    return vo, r, v, np.ones((1, 1), bool), np.array([math.pi / 2]), np.array([RATE])


def test_turn_aware_search_sees_the_turning_intruder():
    """The straight prediction keeps the intruder 6 km away (no conflict); its estimated turn
    (−3°/s for 60 s) brings it across: the turn-aware search flags the conflict, and the
    heading it flies clears the turning intruder in the brute-force oracle."""
    vo, r, v, valid, mx, rate = _crossing_turner()
    omega = np.array([[-RATE]])
    plain = FlownBandsResolver().resolve(vo, r, v, valid, mx, turn_rate=rate)
    assert not plain.conflict[0]
    params = TurnAwareFlownBandsResolver.Params(intruder_turn_s=60.0)
    out = TurnAwareFlownBandsResolver(params).resolve(
        vo, r, v, valid, mx, turn_rate=rate, intruder_turn_rate=omega
    )
    assert out.conflict[0]
    psi = np.array([[out.heading_change[0]]])
    flown = _oracle(vo, r, v, valid, psi, omega, 60.0, 120.0)[0, 0]
    ahead = _oracle(vo, r, v, valid, np.zeros((1, 1)), omega, 60.0, 120.0)[0, 0]
    assert ahead < 1.0 <= flown + 1e-3
    # turning the other way (left) the intruder stays clear: no conflict
    out = TurnAwareFlownBandsResolver(params).resolve(
        vo, r, v, valid, mx, turn_rate=rate, intruder_turn_rate=-omega
    )
    assert not out.conflict[0]


def test_turn_aware_search_without_turns_is_bands_flown():
    """With intruder_turn_s = 0, or no turn rates given, the output is bands-flown's."""
    vo, r, v, valid, cand, omega = _scene(6, n=200, k=6)
    mx, rate = np.full(vo.shape[0], math.pi / 2), np.full(vo.shape[0], RATE)
    want = FlownBandsResolver().resolve(vo, r, v, valid, mx, turn_rate=rate)
    for params, turns in ((dict(intruder_turn_s=0.0), omega), ({}, None)):
        got = TurnAwareFlownBandsResolver(TurnAwareFlownBandsResolver.Params(**params)).resolve(
            vo, r, v, valid, mx, turn_rate=rate, intruder_turn_rate=turns
        )
        np.testing.assert_array_equal(got.heading_change, want.heading_change)
        np.testing.assert_array_equal(got.conflict, want.conflict)


def test_registered_with_its_capabilities():
    cls = registry.get("resolver", "bands-flown-turns")
    assert cls is TurnAwareFlownBandsResolver
    assert cls.uses_intruder_turn_rate and not cls.prefilter
    assert FlownBandsResolver.prefilter and not FlownBandsResolver.uses_intruder_turn_rate


def test_policy_hands_each_track_turn_rate_to_the_resolver():
    """The CDA policy gives a resolver with uses_intruder_turn_rate the Ω of each gathered
    track's state (0 in empty slots), slot for slot."""
    from airspace_sim.scenarios import load
    from airspace_sim.world import World

    sc = load("dense_random", ['resolver.kind="bands-flown-turns"', "traffic.count=20"])
    world = World(sc, seed=0)
    policy, given = world.policy, []
    resolve = policy.resolver.resolve

    def spy(*args, **kw):
        given.append(kw["intruder_turn_rate"].copy())
        return resolve(*args, **kw)

    policy.resolver.resolve = spy
    turning = 0
    for _ in range(60):
        given.clear()
        world.step()
        if not given:
            continue
        rows = policy._encounters.rows
        x = world.tracks.view().x
        want = np.where(rows >= 0, x[np.maximum(rows, 0), 4], 0.0)
        np.testing.assert_array_equal(given[0], want)
        turning += int((np.abs(given[0]) > math.radians(0.5)).sum())
    assert turning > 0
