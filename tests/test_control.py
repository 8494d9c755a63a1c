"""Gathering tracks into per-ownship arrays and the resolver's prefilter: the numba kernels
against the numpy references (same arrays bit for bit), and the reachability test against
a brute-force oracle over headings."""

import dataclasses

import numpy as np
import pytest

from airspace_sim.avoidance.bands import CLEAR_TOLERANCE
from airspace_sim.geometry import rotate
from airspace_sim.scenarios import load
from airspace_sim.world import World
from airspace_sim.world.control import (
    Encounters,
    gather,
    gather_numpy,
    reachable,
    reachable_numpy,
    screen,
    screen_numpy,
)

R = 3000.0 * 1.1
T = 120.0


def assert_same(a: Encounters, b: Encounters):
    for name in ("owners", "rows", "rel_position", "rel_velocity", "valid"):
        x, y = getattr(a, name), getattr(b, name)
        assert x.shape == y.shape, name
        assert x.dtype == y.dtype, name
        np.testing.assert_array_equal(x, y, err_msg=name)


def random_tracks(rng, n, p):
    owner = rng.integers(0, n, p)
    x = np.column_stack(
        [
            rng.uniform(-4e4, 4e4, p),
            rng.uniform(-300, 300, p),
            rng.uniform(-4e4, 4e4, p),
            rng.uniform(-300, 300, p),
            rng.normal(0, 0.01, p),
        ]
    )
    return owner, x, rng.uniform(-4e4, 4e4, (n, 2)), rng.uniform(-250, 250, (n, 2))


@pytest.mark.parametrize("seed", range(6))
def test_gather_same_as_argsort(seed):
    rng = np.random.default_rng(seed)
    n, p = 50, int(rng.integers(0, 800))
    owner, x, pos, vel = random_tracks(rng, n, p)
    runs = rng.random(n) < 0.7
    keep = rng.random(p) < 0.8
    assert_same(
        gather(owner, x, pos, vel, runs, keep), gather_numpy(owner, x, pos, vel, runs, keep)
    )
    assert_same(gather(owner, x, pos, vel, runs), gather_numpy(owner, x, pos, vel, runs))


def test_gather_order_and_values():
    # independent oracle: owners ascending, each owner's tracks in the order given
    owner = np.array([3, 1, 3, 0, 1, 3])
    x = np.arange(30.0).reshape(6, 5)
    pos = np.arange(8.0).reshape(4, 2)
    vel = -np.arange(8.0).reshape(4, 2)
    runs = np.array([False, True, True, True])
    enc = gather(owner, x, pos, vel, runs, keep=np.array([True, True, True, True, True, False]))
    np.testing.assert_array_equal(enc.owners, [1, 3])
    np.testing.assert_array_equal(enc.rows, [[1, 4], [0, 2]])
    np.testing.assert_array_equal(
        enc.rel_position[1, 1], [x[2, 0] - pos[3, 0], x[2, 2] - pos[3, 1]]
    )
    np.testing.assert_array_equal(
        enc.rel_velocity[0, 0], [x[1, 1] - vel[1, 0], x[1, 3] - vel[1, 1]]
    )
    assert enc.valid.all()


def test_gather_empty():
    z = np.zeros(0, np.int64)
    enc = gather(z, np.zeros((0, 5)), np.zeros((3, 2)), np.zeros((3, 2)), np.ones(3, bool))
    assert_same(enc, Encounters.empty())
    assert_same(
        enc, gather_numpy(z, np.zeros((0, 5)), np.zeros((3, 2)), np.zeros((3, 2)), np.ones(3, bool))
    )


def random_encounters(rng, n, k, spread=40000.0):
    vo = rotate(np.array([230.0, 0.0]), rng.uniform(-np.pi, np.pi, n))
    pos = rng.uniform(-spread, spread, (n, k, 2))
    aim = np.arctan2(-pos[..., 1], -pos[..., 0]) + rng.normal(0.0, 0.5, (n, k))
    vi = rotate(np.stack([rng.uniform(100, 400, (n, k)), np.zeros((n, k))], -1), aim)
    valid = rng.random((n, k)) < 0.8
    rows = np.where(valid, np.arange(n * k).reshape(n, k), -1)
    rp = np.where(valid[..., None], pos, 0.0)
    rv = np.where(valid[..., None], vi - vo[:, None, :], 0.0)
    return Encounters(np.arange(n) * 2, rows, rp, rv, valid), vo


@pytest.mark.parametrize("seed", range(5))
def test_reachable_same_as_numpy(seed):
    rng = np.random.default_rng(seed)
    enc, vo = random_encounters(rng, 80, 30)
    vo[0] = 0.0  # a hovering ownship
    enc.rel_velocity[1, 0] = np.nan  # a NaN slot is never reachable, in both
    for step, lookahead in ((10.0, T), (7.0, 95.0), (1.0, 30.0)):
        got = reachable(enc, vo, R, lookahead, step)
        np.testing.assert_array_equal(got, reachable_numpy(enc, vo, R, lookahead, step))
    assert not got[1, 0]


def test_reachable_is_conservative():
    # brute-force oracle: any intruder that some heading brings within R (fine sampling of
    # heading and time) must be kept
    rng = np.random.default_rng(11)
    enc, vo = random_encounters(rng, 40, 20, spread=25000.0)
    keep = reachable(enc, vo, R, T)
    psi = np.linspace(-np.pi, np.pi, 721)
    t = np.linspace(0.0, T, 481)
    for o in range(vo.shape[0]):
        own = rotate(vo[o], psi)  # (H, 2)
        for k in np.flatnonzero(enc.valid[o]):
            vi = enc.rel_velocity[o, k] + vo[o]
            rel = enc.rel_position[o, k] + (vi - own)[:, None, :] * t[None, :, None]
            if np.hypot(rel[..., 0], rel[..., 1]).min() < R:
                assert keep[o, k], (o, k)
    assert 0 < keep.sum() < enc.valid.sum()


@pytest.mark.parametrize("seed", range(5))
def test_screen_same_as_separate_steps(seed):
    rng = np.random.default_rng(seed)
    enc, vo = random_encounters(rng, 120, 25, spread=20000.0 + 10000.0 * seed)
    thr = 1.0 - CLEAR_TOLERANCE
    got = screen(enc, vo, R, T, thr)
    ref = screen_numpy(enc, vo, R, T, thr)
    assert_same(got, ref)
    assert 0 < got.owners.size < enc.owners.size


def test_screen_nothing_kept():
    rng = np.random.default_rng(0)
    enc, vo = random_encounters(rng, 10, 5)
    enc.rel_position[:] = 1e7  # everyone far away: no ownship fails its CPA test
    assert_same(screen(enc, vo, R, T, 0.99), screen_numpy(enc, vo, R, T, 0.99))
    assert screen(enc, vo, R, T, 0.99).owners.size == 0
    empty = Encounters(
        np.zeros(0, np.int64),
        np.zeros((0, 0), np.int64),
        np.zeros((0, 0, 2)),
        np.zeros((0, 0, 2)),
        np.zeros((0, 0), bool),
    )
    assert_same(
        screen(empty, np.zeros((0, 2)), R, T, 0.99),
        screen_numpy(empty, np.zeros((0, 2)), R, T, 0.99),
    )


def test_world_encounters_same_as_reference():
    # the arrays of a real world step: gather and the prefilter against the references
    world = World(load("dense_random", []), seed=0)
    for _ in range(30):
        world.step()
    pol = world.policy
    view = world.tracks.view()
    ok = view.age >= pol.confirm_steps
    runs = pol.tracking & world.active
    args = (view.owner, view.x, world.positions, world.velocities, runs)
    enc = gather(*args, keep=ok)
    assert_same(enc, gather_numpy(*args, keep=ok))
    assert enc.owners.size > 0
    r = pol.r_safe * (1.0 + pol.margin)
    vo = world.velocities[enc.owners]
    thr = 1.0 - CLEAR_TOLERANCE
    assert_same(
        screen(enc, vo, r, pol.lookahead_s, thr), screen_numpy(enc, vo, r, pol.lookahead_s, thr)
    )


def test_reachable_at_the_boundary():
    # the radius placed exactly on a slot's min_j f_j − slack and one ulp either side: the
    # kernel's sqrt fast path must still give numpy's (hypot) decision
    rng = np.random.default_rng(5)
    enc, vo = random_encounters(rng, 100, 10)
    T, step = 120.0, 10.0
    t = np.append(np.arange(0.0, T, step), T)
    checked = 0
    for o, k in zip(*np.nonzero(enc.valid), strict=True):
        one = Encounters(
            enc.owners[o : o + 1],
            enc.rows[o : o + 1, k : k + 1],
            enc.rel_position[o : o + 1, k : k + 1],
            enc.rel_velocity[o : o + 1, k : k + 1],
            enc.valid[o : o + 1, k : k + 1],
        )
        vi = enc.rel_velocity[o, k] + vo[o]
        so = np.hypot(*vo[o])
        p = enc.rel_position[o, k] + vi * t[:, None]
        g = (np.hypot(p[:, 0], p[:, 1]) - so * t).min() - (np.hypot(*vi) + so) * step / 2.0
        for radius in (g, np.nextafter(g, np.inf), np.nextafter(g, -np.inf)):
            if radius <= 0:
                continue
            ref = reachable_numpy(one, vo[o : o + 1], radius, T, step)
            np.testing.assert_array_equal(reachable(one, vo[o : o + 1], radius, T, step), ref)
            checked += 1
    assert checked > 200


def test_reachable_non_finite_and_huge():
    rng = np.random.default_rng(8)
    enc, vo = random_encounters(rng, 6, 6)
    enc.valid[:] = True
    enc.rel_position[0, 0] = np.inf
    enc.rel_position[0, 1] = [1e200, -1e200]
    enc.rel_velocity[0, 2] = [np.nan, 0.0]
    enc.rel_velocity[0, 3] = [1e300, 1e300]
    vo[1] = [1e305, 0.0]
    vo[2] = np.nan
    for radius in (R, 1e250, np.inf):
        np.testing.assert_array_equal(
            reachable(enc, vo, radius, T), reachable_numpy(enc, vo, radius, T)
        )


@pytest.mark.parametrize("preference", ["right", "nearest"])
def test_committed_side_search_flies_the_same_world(monkeypatch, preference):
    # the policy passing its committed sides (the resolver then searches the best blocked
    # heading of that side only) flies exactly the world of the side-free search
    from airspace_sim.avoidance.resolvers import BandsResolver
    from airspace_sim.world.benchmark import random_scenario

    sc = random_scenario(120, duration=60.0)
    sc = dataclasses.replace(
        sc, resolver=dataclasses.replace(sc.resolver, turn_preference=preference)
    )
    runs = []
    for uses in (True, False):
        monkeypatch.setattr(BandsResolver, "uses_committed_side", uses)
        world = World(sc, seed=3)
        steps = []
        for _ in range(40):
            world.step()
            steps.append(
                (world.positions.tobytes(), world.advice.tobytes(), world.policy.side.tobytes())
            )
        runs.append(steps)
        assert (world.policy.side != 0).sum() > 10 and world.conflict.sum() > 10
    assert runs[0] == runs[1]
