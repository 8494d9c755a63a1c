"""The grid placement of ``traffic.pattern = "random"`` against the quadratic original.

The oracle below is the generator as it was before the grid (every candidate tested against
every aircraft placed before it): the same seed must give the same aircraft, bit for bit,
the same generator state afterwards and the same one-line UserErrors.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from airspace_sim.errors import UserError
from airspace_sim.scenarios import from_dict
from airspace_sim.scenarios import traffic as tr

# ------------------------------------------------------------------------ quadratic oracle


def _oracle_min_distance(rel_pos, rel_vel, horizon_s):
    if rel_pos.shape[0] == 0:
        return math.inf
    vv = np.einsum("ij,ij->i", rel_vel, rel_vel)
    t = -np.einsum("ij,ij->i", rel_pos, rel_vel) / np.where(vv > 0, vv, 1.0)
    t = np.clip(np.where(vv > 0, t, 0.0), 0.0, horizon_s)
    return float(np.hypot(*(rel_pos + t[:, None] * rel_vel).T).min())


def _oracle_place(rng, placed, side, r_safe, batch=64):
    for _ in range(0, tr.MAX_TRIES, batch):
        cand = rng.uniform(-side / 2, side / 2, size=(batch, 2))
        if placed.shape[0] == 0:
            return cand[0]
        d2 = ((cand[:, None, :] - placed[None, :, :]) ** 2).sum(axis=-1).min(axis=1)
        ok = np.flatnonzero(d2 > r_safe**2)
        if ok.size:
            return cand[ok[0]]
    return None


def oracle_random_sector(scenario, rng):
    t = scenario.traffic
    side, r_safe, clear_s = t.sector, scenario.separation.r_safe, float(t.spawn_clear_s)
    hand = scenario.aircraft
    n_hand = len(hand)
    placed = np.empty((n_hand + t.count, 2))
    vel = np.empty((n_hand + t.count, 2))
    for k, a in enumerate(hand):
        placed[k] = a.position
        h = math.radians(a.heading_deg)
        vel[k] = a.speed * math.cos(h), a.speed * math.sin(h)
    m = n_hand
    speeds = tr._speeds(scenario, rng)
    out = []
    for i, aid in enumerate(tr._ids("ac", t.count)):
        for _attempt in range(tr.MAX_TRIES):
            p = _oracle_place(rng, placed[:m], side, r_safe)
            if p is None:
                raise UserError(
                    f"{scenario.source}: traffic.count: cannot place {t.count} aircraft more "
                    f"than r_safe = {r_safe:g} m apart in a {side:g} m sector (placed {i}); "
                    f"use a larger traffic.sector or fewer aircraft, got {t.count}"
                )
            for _ in range(tr.MAX_TRIES):
                dest = np.asarray(tr._edge_point(rng.uniform(0, 4 * side), side))
                if np.hypot(*(dest - p)) >= side / 2:
                    break
            heading = math.atan2(dest[1] - p[1], dest[0] - p[0])
            v = speeds[i] * np.array([math.cos(heading), math.sin(heading)])
            if clear_s <= 0 or _oracle_min_distance(placed[:m] - p, vel[:m] - v, clear_s) > r_safe:
                break
        else:
            raise UserError(
                f"{scenario.source}: traffic.spawn_clear_s: cannot place {t.count} aircraft "
                f"clear of each other for {clear_s:g} s in a {side:g} m sector (placed {i}); "
                f"use a smaller traffic.spawn_clear_s, a larger sector or fewer aircraft, "
                f"got {clear_s:g}"
            )
        placed[m], vel[m] = p, v
        m += 1
        out.append(tr._spec(scenario, aid, p, heading, speeds[i], [tuple(dest)]))
    return out


# ------------------------------------------------------------------------------ helpers

HAND = [
    {"id": "h0", "position": [0.0, 0.0], "heading_deg": 30.0, "speed": 250.0},
    # outside every sector it is used with, fast: it still decides spawn-clear tests
    {"id": "h1", "position": [-70000.0, 1000.0], "heading_deg": 0.0, "speed": 400.0},
]


def _scenario(count, sector, r_safe=3000.0, spawn_clear_s=0.0, hand=(), spread=0.0):
    return from_dict(
        {
            "name": "x",
            "separation": {"r_safe": r_safe, "nmac": min(150.0, r_safe / 2)},
            "aircraft": [dict(a) for a in hand],
            "traffic": {
                "pattern": "random",
                "count": count,
                "sector": sector,
                "spawn_clear_s": spawn_clear_s,
                "speed_spread": spread,
            },
        }
    )


def _both(sc, seed):
    """(new aircraft, new rng state), (oracle aircraft, oracle rng state)."""
    r1, r2 = np.random.default_rng(seed), np.random.default_rng(seed)
    a1, a2 = tr.random_sector(sc, r1), oracle_random_sector(sc, r2)
    return (a1, r1.bit_generator.state), (a2, r2.bit_generator.state)


def _assert_same(got, want):
    (a1, s1), (a2, s2) = got, want
    assert s1 == s2  # the same rng draws, so the same number of them
    assert len(a1) == len(a2)
    for x, y in zip(a1, a2):
        assert dataclasses.asdict(x) == dataclasses.asdict(y)
    p1 = np.array([a.position for a in a1])
    p2 = np.array([a.position for a in a2])
    assert (p1 == p2).all()
    assert (np.array([a.heading_deg for a in a1]) == [a.heading_deg for a in a2]).all()


# -------------------------------------------------------------------------------- tests


@pytest.mark.parametrize("seed", [0, 1, 7])
@pytest.mark.parametrize(
    "count, sector, r_safe, clear_s, hand, spread",
    [
        (1, 20000.0, 3000.0, 0.0, (), 0.0),
        (200, 141421.0, 3000.0, 0.0, (), 0.0),  # the benchmark's density
        (150, 120000.0, 3000.0, 0.0, HAND, 30.0),
        (120, 90000.0, 2000.0, 90.0, HAND, 40.0),  # spawn-clear redraws
        (60, 60000.0, 5000.0, 30.0, (), 80.0),
        (300, 1.0e6, 1.0, 0.0, (), 0.0),  # cells far smaller than the sector
    ],
)
def test_grid_placement_is_the_quadratic_placement(
    seed, count, sector, r_safe, clear_s, hand, spread
):
    sc = _scenario(count, sector, r_safe, clear_s, hand, spread)
    _assert_same(*_both(sc, seed))


def test_crowded_sector_rejects_candidates_and_still_matches():
    # 45 aircraft 3 km apart in 25 km: most candidates are rejected, several batches deep
    sc = _scenario(45, 25000.0, 3000.0)
    got, want = _both(sc, 3)
    _assert_same(got, want)
    # the rejections happened: far more draws than one candidate batch + one edge point each
    draws = np.random.default_rng(3)
    tr._speeds(sc, draws)
    for _ in range(45):
        draws.uniform(size=(64, 2))
        draws.uniform()
    assert got[1] != draws.bit_generator.state


def test_crowded_spawn_clear_matches():
    sc = _scenario(50, 40000.0, 3000.0, spawn_clear_s=60.0, spread=50.0)
    _assert_same(*_both(sc, 5))


@pytest.mark.parametrize(
    "count, sector, clear_s, key",
    [(300, 20000.0, 0.0, "traffic.count"), (60, 30000.0, 600.0, "traffic.spawn_clear_s")],
)
def test_impossible_placements_are_the_same_user_error(count, sector, clear_s, key):
    sc = _scenario(count, sector, spawn_clear_s=clear_s)
    with pytest.raises(UserError) as new:
        tr.random_sector(sc, np.random.default_rng(0))
    with pytest.raises(UserError) as old:
        oracle_random_sector(sc, np.random.default_rng(0))
    assert str(new.value) == str(old.value)
    assert "\n" not in str(new.value) and key in str(new.value)


def test_grid_around_finds_every_point_within_reach():
    rng = np.random.default_rng(0)
    pts = rng.uniform(-5e4, 5e4, size=(2000, 2))
    g = tr._Grid(3000.0)
    for k, p in enumerate(pts):
        g.add(k, p)
    for q in rng.uniform(-5e4, 5e4, size=(200, 2)):
        within = set(np.flatnonzero(np.hypot(*(pts - q).T) <= 3000.0))
        found = set(g.around(q).tolist())
        assert within <= found
        # and it is local: only the 3 x 3 cells, not everything
        assert len(found) < len(pts) / 10
