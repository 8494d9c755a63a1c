"""Boxed pairs resolved together ("bands-flown-paired", avoidance/paired_bands.py): the two
aircraft's minimum distance with both turning against a brute-force oracle, the pairing, the
joint pick, and the resolver on crowds judged by that oracle."""

import math

import numpy as np
import pytest
from _flight import K1, arc_path

from airspace_sim import registry
from airspace_sim.avoidance.cpa import cpa_pair_ratios
from airspace_sim.avoidance.flown_bands import FlownBandsResolver
from airspace_sim.avoidance.paired_bands import (
    PairedFlownBandsResolver,
    mutual_pairs,
    mutual_ratio,
    pair_choice,
)

RATE = math.radians(3.0)
RADIUS = 3300.0


def _path(speed, heading, psi, t):
    """A path that turns at RATE to ``heading + psi``, then flies straight (:func:`arc_path`)."""
    return arc_path(speed, heading, math.copysign(RATE, psi), abs(psi) / RATE, t)


def _oracle_distance(p0, v0, psi0, p1, v1, psi1, lookahead=120.0):
    """Minimum distance (m) of two aircraft flying ``psi0`` and ``psi1`` as flown, both paths
    sampled every 10 ms (``psi1 = None``: the second flies straight)."""
    t = np.linspace(0.0, lookahead, int(lookahead * 100) + 1)
    ax, ay = _path(np.hypot(*v0), math.atan2(v0[1], v0[0]), psi0, t)
    bx, by = _path(np.hypot(*v1), math.atan2(v1[1], v1[0]), psi1 or 0.0, t)
    return np.hypot(p1[0] + bx - p0[0] - ax, p1[1] + by - p0[1] - ay).min()


def test_registered():
    assert registry.get("resolver", "bands-flown-paired") is PairedFlownBandsResolver
    assert PairedFlownBandsResolver.uses_aircraft_ids
    assert not FlownBandsResolver.uses_aircraft_ids


def _one_pair_ratio(v0, r, v, own, other, radius, lookahead, rate0, rate1):
    """:func:`mutual_ratio` of one pair, (A, B)."""
    return mutual_ratio(
        v0[None], r[None], v[None], own[None], other[None], np.array([radius]), lookahead,
        np.array([rate0]), np.array([rate1]),
    )[0]  # fmt: skip


def _one_choice(others_i, others_j, mutual, own, other):
    """:func:`pair_choice` of one pair: ``(a, b, score)``."""
    a, b, score = pair_choice(others_i[None], others_j[None], mutual[None], own[None], other[None])
    return int(a[0]), int(b[0]), float(score[0])


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_mutual_ratio_matches_the_sampled_oracle(seed):
    rng = np.random.default_rng(seed)
    v0 = rng.normal(size=2)
    v0 *= rng.uniform(180, 260) / np.linalg.norm(v0)
    v1 = rng.normal(size=2)
    v1 *= rng.uniform(180, 260) / np.linalg.norm(v1)
    r = rng.uniform(-12000, 12000, 2)
    own = np.radians(rng.uniform(-90, 90, 7))
    other = np.radians(np.r_[rng.uniform(-90, 90, 5), 0.0])
    got = _one_pair_ratio(v0, r, v1 - v0, own, other, RADIUS, 120.0, RATE, RATE)
    assert got.shape == (7, 6)
    want = np.array(
        [[_oracle_distance(np.zeros(2), v0, a, r, v1, b) / RADIUS for b in other] for a in own]
    )
    # one-second chords of 3°/s arcs at up to 260 m/s depart from them by under 2 m
    np.testing.assert_allclose(got, want, atol=4.0 / RADIUS, rtol=0)


def test_mutual_ratio_nan_candidates():
    got = _one_pair_ratio(
        np.array([230.0, 0.0]),
        np.array([9000.0, 0.0]),
        np.array([-460.0, 0.0]),
        np.array([0.1, np.nan]),
        np.array([np.nan, -0.2]),
        RADIUS,
        120.0,
        RATE,
        RATE,
    )
    assert np.isnan(got[1]).all() and np.isnan(got[:, 0]).all() and np.isfinite(got[0, 1])


def test_pairs_batched_are_the_pairs_one_at_a_time():
    """P pairs in one call of mutual_ratio and pair_choice give each pair's own numbers."""
    rng = np.random.default_rng(5)
    p = 4
    v0 = rng.normal(0, 160, (p, 2))
    v1 = rng.normal(0, 160, (p, 2))
    r = rng.uniform(-9000, 9000, (p, 2))
    own = np.radians(rng.uniform(-90, 90, (p, 6)))
    other = np.radians(rng.uniform(-90, 90, (p, 5)))
    radius = rng.uniform(3000, 3600, p)
    rate0, rate1 = rng.uniform(0.02, 0.06, p), rng.uniform(0.02, 0.06, p)
    got = mutual_ratio(v0, r, v1 - v0, own, other, radius, 90.0, rate0, rate1)
    others_i, others_j = rng.uniform(0.5, 1.5, (p, 6)), rng.uniform(0.5, 1.5, (p, 5))
    a, b, score = pair_choice(others_i, others_j, got, own, other)
    for q in range(p):
        one = _one_pair_ratio(
            v0[q], r[q], v1[q] - v0[q], own[q], other[q], radius[q], 90.0, rate0[q], rate1[q]
        )
        np.testing.assert_array_equal(got[q], one)
        assert (a[q], b[q], score[q]) == _one_choice(
            others_i[q], others_j[q], one, own[q], other[q]
        )


def test_mutual_pairs_only_rows_that_track_each_other_once_most_urgent_first():
    # rows 0..4 are aircraft 10..14; row 3 is not eligible
    ids = np.array([10, 11, 12, 13, 14])
    intruder = np.array(
        [
            [11, 12, -1],  # 10 tracks 11 and 12
            [10, 12, -1],  # 11 tracks 10 and 12
            [10, 11, 13],  # 12 tracks 10, 11, 13
            [12, -1, -1],  # 13 tracks 12 (but is not eligible)
            [99, -1, -1],  # 14 tracks an aircraft with no row; nobody tracks 14
        ]
    )
    valid = intruder >= 0
    rows = np.array([True, True, True, False, True])
    urgency = np.full((5, 3), 1.0)
    urgency[1, 1] = 0.2  # 11-12 most urgent, then 10-12, then 10-11
    urgency[0, 1] = 0.5
    i, k, j, l = mutual_pairs(rows, ids, intruder, valid, urgency)
    assert list(zip(i, j)) == [(1, 2)]  # 10 is then left without a free partner
    assert intruder[1, k[0]] == 12 and intruder[2, l[0]] == 11
    urgency[1, 1] = 0.9
    i, k, j, l = mutual_pairs(rows, ids, intruder, valid, urgency)
    assert list(zip(i, j)) == [(0, 2)]
    # an invalid slot does not count as tracking: 10-12 is no pair, 11-12 (0.9) comes first
    valid[2, 0] = False
    i, _, j, _ = mutual_pairs(rows, ids, intruder, valid, urgency)
    assert list(zip(i, j)) == [(1, 2)]
    valid[2, 1] = False
    i, _, j, _ = mutual_pairs(rows, ids, intruder, valid, urgency)
    assert list(zip(i, j)) == [(0, 1)]
    none = mutual_pairs(np.zeros(5, bool), ids, intruder, valid, urgency)
    assert all(a.size == 0 for a in none)


def test_pair_choice_smallest_joint_turn_among_clear_else_largest_score():
    own = np.array([0.0, -0.1, 0.2])
    other = np.array([0.0, 0.3])
    others_i = np.array([0.9, 1.2, 1.5])
    others_j = np.array([1.3, 1.4])
    mutual = np.array([[0.5, 1.1], [1.0, 2.0], [0.8, 1.6]])
    # clear: (0,1)? others_i 0.9 no; (1,0) min(1.2,1.3,1.0)=1.0 turn 0.1; (1,1) turn 0.4;
    # (2,1) turn 0.5
    assert _one_choice(others_i, others_j, mutual, own, other) == (1, 0, 1.0)
    mutual[1, 0] = 0.7
    assert _one_choice(others_i, others_j, mutual, own, other)[:2] == (1, 1)
    # nothing clear: the largest score
    mutual = np.minimum(mutual, 0.95)
    mutual[2, 1] = np.nan
    assert _one_choice(others_i, others_j, mutual, own, other) == (1, 1, 0.95)


def _crowd(seed, side=6, spacing=4000.0):
    """``side²`` aircraft at 230 m/s, random headings, on a square grid ``spacing`` m apart
    with ±300 m of jitter; every aircraft is a row whose intruders are all the others.
    ``(pos (n, 2), vel (n, 2), rows)`` with rows ``(vo, r, v, valid, mx, ids, intruder)``."""
    rng = np.random.default_rng(seed)
    n = side * side
    grid = np.stack(np.meshgrid(np.arange(side), np.arange(side)), axis=-1).reshape(n, 2)
    pos = grid * spacing + rng.uniform(-300.0, 300.0, (n, 2))
    h = rng.uniform(-math.pi, math.pi, n)
    vel = 230.0 * np.stack([np.cos(h), np.sin(h)], axis=1)
    intruder = np.array([[j for j in range(n) if j != i] for i in range(n)])
    r = pos[intruder] - pos[:, None]
    v = vel[intruder] - vel[:, None]
    valid = np.ones(intruder.shape, bool)
    return pos, vel, (vel, r, v, valid, np.full(n, math.pi / 2), np.arange(n), intruder)


def _resolve(cls, rows, side, ids=True, **params):
    vo, r, v, valid, mx, own_ids, intruder = rows
    extra = dict(aircraft_ids=own_ids, intruder_ids=intruder) if ids else {}
    return cls(cls.Params(**params)).resolve(
        vo, r, v, valid, mx, turn_rate=np.full(vo.shape[0], RATE), committed_side=side, **extra
    )


@pytest.mark.parametrize("seed", [0, 1])
def test_without_boxed_pairs_it_is_bands_flown(seed):
    """Without ids, or with every row fresh (no committed side: nobody is boxed in the
    policy's sense), the output is bands-flown's, bit for bit."""
    _, _, rows = _crowd(seed)
    n = rows[0].shape[0]
    side = np.where(np.arange(n) % 2 == 0, -1.0, 1.0)
    base = _resolve(FlownBandsResolver, rows, side, ids=False, **K1)
    for ids, s in ((False, side), (True, np.zeros(n))):
        out = _resolve(PairedFlownBandsResolver, rows, s, ids=ids, **K1)
        ref = base if ids is False else _resolve(FlownBandsResolver, rows, s, ids=False, **K1)
        for field in ("heading_change", "first_clear", "best_blocked", "min_ratio"):
            np.testing.assert_array_equal(getattr(out, field), getattr(ref, field))


def _oracle_score(pos, vel, i, a, j, b, r_clear):
    """The pair's score judged by the sampled oracle: ``min`` over i's and j's third
    aircraft (straight) and over each other (both as flown) of distance / ``r_clear``."""
    n = pos.shape[0]
    worst = _oracle_distance(pos[i], vel[i], a, pos[j], vel[j], b)
    for me, psi, other in ((i, a, j), (j, b, i)):
        for q in range(n):
            if q not in (me, other):
                d = _oracle_distance(pos[me], vel[me], psi, pos[q], vel[q], None)
                worst = min(worst, d)
    return worst / r_clear


@pytest.mark.parametrize("seed", [3, 4])
def test_boxed_pairs_fly_a_joint_pick_the_oracle_scores_higher(seed):
    """In a crowd with every aircraft committed right, only rows of mutual pairs of rows
    boxed on both sides differ from bands-flown, and for each pair that changed the sampled
    oracle scores the joint pick above the two rows' own picks by the margin."""
    pos, vel, rows = _crowd(seed)
    vo, r, v, valid, _, ids, intruder = rows
    n = pos.shape[0]
    side = np.full(n, -1.0)
    base = _resolve(FlownBandsResolver, rows, side, ids=False, **K1)
    out = _resolve(PairedFlownBandsResolver, rows, side, pair_margin=0.05, **K1)
    np.testing.assert_array_equal(out.first_clear, base.first_clear)
    boxed = (base.first_clear[:, 0] < 0) & (base.first_clear[:, 1] < 0)
    r_clear = 3000.0 * 1.1
    urgency = cpa_pair_ratios(vo, r, v, valid, np.zeros((n, 1)), r_clear, 120.0)[:, :, 0]
    pairs = list(zip(*mutual_pairs(boxed, ids, intruder, valid, urgency)))
    changed = out.best_blocked[:, 0] != base.best_blocked[:, 0]
    in_pair = np.zeros(n, bool)
    moved = 0
    for i, _, j, _ in pairs:
        in_pair[[i, j]] = True
        if not (changed[i] or changed[j]):
            continue
        moved += 1
        ci, cj = out.candidates[i], out.candidates[j]
        new = _oracle_score(
            pos, vel, i, ci[out.best_blocked[i, 0]], j, cj[out.best_blocked[j, 0]], r_clear
        )
        old = _oracle_score(
            pos, vel, i, ci[base.best_blocked[i, 0]], j, cj[base.best_blocked[j, 0]], r_clear
        )
        assert new > old + 0.05 - 20.0 / r_clear, (i, j, new, old)
    assert moved >= 2
    assert not changed[~in_pair].any()
    np.testing.assert_array_equal(out.best_blocked[:, 1], base.best_blocked[:, 1])


def test_policy_gives_each_slot_the_aircraft_it_tracks():
    """The CDA policy hands a resolver with ``uses_aircraft_ids`` the rows' aircraft and each
    slot's: the slot's relative position (a track) is that aircraft's true position minus the
    row's, within the tracking error; and a paired run keeps dense traffic free of NMAC."""
    from airspace_sim.scenarios import load
    from airspace_sim.world import World

    sc = load("dense_random", ['resolver.kind="bands-flown-paired"', "duration=120.0"])
    world = World(sc, seed=1)
    policy = world.policy
    assert isinstance(policy.resolver, PairedFlownBandsResolver)
    resolve, seen = policy.resolver.resolve, []

    def spy(*args, **kw):
        seen.append((kw["aircraft_ids"].copy(), kw["intruder_ids"].copy(), args[1].copy()))
        return resolve(*args, **kw)

    policy.resolver.resolve = spy
    checked = 0
    for _ in range(120):
        seen.clear()
        positions = world.positions.copy()
        world.step()
        for own, intruder, rel in seen:
            assert own.shape == intruder.shape[:1] and rel.shape[:2] == intruder.shape
            slots = intruder >= 0
            rows = np.broadcast_to(own[:, None], intruder.shape)[slots]
            truth = positions[intruder[slots]] - positions[rows]
            assert np.hypot(*(rel[slots] - truth).T).max() < 1000.0
            checked += int(slots.sum())
    assert checked > 50
    assert world.metrics()["nmac_pairs"] == 0
