"""bands-roundabout (avoidance/roundabout.py): the right-of-way convention against geometry."""

import math

import numpy as np
import pytest

from airspace_sim import registry
from airspace_sim.avoidance.cpa import cpa_min_ratio_numpy
from airspace_sim.avoidance.mode_bands import mode_path_min_ratio
from airspace_sim.avoidance.roundabout import (
    candidate_time_to_loss,
    co_rotated_boundaries,
    co_rotated_min_ratio,
    give_way,
    time_to_loss,
)
from airspace_sim.geometry import wrap_angle
from airspace_sim.scenarios import load
from airspace_sim.world import World

V, D, R_SAFE, MARGIN = 230.0, 20000.0, 3000.0, 0.1
RHO = R_SAFE * (1 + MARGIN)


def resolver(**params):
    return registry.build(
        "resolver", "bands-roundabout", params={"r_safe": R_SAFE, "margin": MARGIN, **params}
    )


def one(own, intruder_pos, intruder_vel, **params):
    own = np.asarray(own, dtype=float)
    out = resolver(**params).resolve(
        own[None],
        np.asarray(intruder_pos, dtype=float)[None, None],
        (np.asarray(intruder_vel, dtype=float) - own)[None, None],
        np.array([[True]]),
        np.array([math.pi / 2]),
    )
    return float(out.heading_change[0]), bool(out.conflict[0])


def test_head_on_both_give_way_and_turn_right_by_the_closed_form_angle():
    # alone against a straight intruder the relative velocity is v(−1 − cos ψ, −sin ψ) and
    # the miss distance D·sin(|ψ|/2): the smallest clear turn is 2·asin(ρ/D), to the right
    # (ties go right); the intruder sees the mirror geometry and does the same
    psi, conflict = one([V, 0.0], [D, 0.0], [-V, 0.0])
    assert conflict
    assert psi == pytest.approx(-2 * math.asin(RHO / D), abs=1e-6)
    psi2, _ = one([-V, 0.0], [-D, 0.0], [V, 0.0])
    assert psi2 == pytest.approx(psi, abs=1e-9)


def test_crossing_from_the_right_gives_way_from_the_left_stands_on():
    # eastbound and northbound both 20 km from the crossing point: the northbound comes from
    # the eastbound's right, so the eastbound gives way and the northbound holds its heading
    d = 20000.0
    psi_e, conflict_e = one([V, 0.0], [d, -d], [0.0, V])
    psi_n, conflict_n = one([0.0, V], [-d, d], [V, 0.0])
    assert conflict_e and psi_e != 0.0
    assert not conflict_n and psi_n == 0.0
    # the give-way turn is exactly "bands" against that intruder alone
    bands = registry.build("resolver", "bands", params={"r_safe": R_SAFE, "margin": MARGIN})
    own = np.array([[V, 0.0]])
    out = bands.resolve(
        own,
        np.array([[[d, -d]]]),
        np.array([[[-V, V]]]),
        np.array([[True]]),
        np.array([math.pi / 2]),
    )
    assert psi_e == float(out.heading_change[0])


def test_stand_on_resolves_when_the_loss_is_closer_than_standon_s():
    # the same crossing 4 km out: the loss of ρ comes at (√2·4000 − ρ)/(√2·V) ≈ 7.2 s
    d = 4000.0
    t = (math.sqrt(2) * d - RHO) / (math.sqrt(2) * V)
    psi, conflict = one([0.0, V], [-d, d], [V, 0.0], standon_s=t + 0.5)
    assert conflict and psi != 0.0
    psi, conflict = one([0.0, V], [-d, d], [V, 0.0], standon_s=t - 0.5)
    assert not conflict and psi == 0.0


def test_give_way_is_antisymmetric():
    rng = np.random.default_rng(3)
    par = math.radians(10.0)
    n = 2000
    vi, vj = rng.normal(size=(n, 2)) * 200, rng.normal(size=(n, 2)) * 200
    ij = give_way(vi, (vj - vi)[:, None], np.ones((n, 1), bool), par)[:, 0]
    ji = give_way(vj, (vi - vj)[:, None], np.ones((n, 1), bool), par)[:, 0]
    cross = vi[:, 0] * vj[:, 1] - vi[:, 1] * vj[:, 0]
    sine = np.abs(cross) / (np.linalg.norm(vi, axis=1) * np.linalg.norm(vj, axis=1))
    assert np.all(ij | ji)  # never both stand on
    crossing = sine > math.sin(par)
    assert np.all((ij ^ ji)[crossing])  # a crossing pair: exactly one gives way
    assert np.all((ij & ji)[~crossing])  # near-parallel: both give way
    assert not give_way(vi, (vj - vi)[:, None], np.zeros((n, 1), bool), par).any()


def test_time_to_loss_against_brute_force():
    rng = np.random.default_rng(5)
    r = rng.uniform(-20000, 20000, size=(300, 2))
    v = rng.uniform(-460, 460, size=(300, 2))
    t = time_to_loss(r, v, RHO)
    ts = np.linspace(0.0, 200.0, 20001)  # 10 ms grid
    dist = np.hypot(r[:, :1] + ts * v[:, :1], r[:, 1:] + ts * v[:, 1:])
    inside = dist <= RHO
    first = np.where(inside.any(axis=1), ts[np.argmax(inside, axis=1)], np.inf)
    hit = np.isfinite(first)
    assert hit.sum() > 10 and (~hit).sum() > 10
    assert np.all(t[~hit] > 200.0 - 0.01)
    assert np.all((t[hit] <= first[hit]) & (t[hit] > first[hit] - 0.011))


def test_candidate_time_to_loss_is_the_min_over_intruders_of_the_turned_track():
    own = np.array([[V, 0.0]])
    r = np.array([[[D, 0.0], [0.0, 8000.0]]])
    vi = np.array([[[-V, 0.0], [0.0, -V]]])
    psi = np.array([[0.0, -0.5, np.nan]])
    t = candidate_time_to_loss(own, r, vi - own[:, None], np.array([[True, True]]), psi, RHO, 120)
    for c in range(2):
        turned = np.array([V * math.cos(psi[0, c]), V * math.sin(psi[0, c])])
        want = min(time_to_loss(r[0, k], vi[0, k] - turned, RHO) for k in range(2))
        assert t[0, c] == pytest.approx(min(want, 120.0))
    assert t[0, 2] == -np.inf


def test_crossing_world_give_way_turns_stand_on_keeps_its_route():
    w = World(load("crossing", ['resolver.kind="bands-roundabout"']), seed=0)
    m = w.run()
    assert m["los_events"] == 0 and m["min_separation_m"] >= R_SAFE
    ids = list(w.ids)
    # the northbound stands on: its track stays on x = 0 (noise-free route autopilot)
    north = ids.index("northbound")
    assert abs(float(w.positions[north, 0])) < 1.0


def test_co_rotation_head_on_turns_half_the_lone_angle():
    # both turn right by ψ: relative velocity 2v(−cos ψ, −sin ψ), miss D·sin ψ: ψ = asin(ρ/D)
    for turn in ("same", "mutual"):
        psi, conflict = one([V, 0.0], [D, 0.0], [-V, 0.0], intruder_turn=turn)
        assert conflict and psi == pytest.approx(-math.asin(RHO / D), abs=1e-6)


def test_co_rotated_ratio_against_brute_force_time_sampling():
    rng = np.random.default_rng(7)
    n, k, c, horizon = 6, 3, 5, 120.0
    r = rng.uniform(-15000, 15000, size=(n, k, 2))
    v = rng.uniform(-460, 460, size=(n, k, 2))
    valid = rng.random((n, k)) < 0.8
    psi = rng.uniform(-1.5, 1.5, size=(n, c))
    got = co_rotated_min_ratio(r, v, valid, psi, RHO, horizon, rows=4)
    ts = np.linspace(0.0, horizon, 12001)
    for i in range(n):
        for j in range(c):
            want = np.inf
            for q in range(k):
                if valid[i, q]:
                    cs, sn = math.cos(psi[i, j]), math.sin(psi[i, j])
                    vr = np.array(
                        [cs * v[i, q, 0] - sn * v[i, q, 1], sn * v[i, q, 0] + cs * v[i, q, 1]]
                    )
                    d = np.hypot(r[i, q, 0] + ts * vr[0], r[i, q, 1] + ts * vr[1]).min()
                    want = min(want, d / RHO)
            assert got[i, j] == pytest.approx(want, rel=1e-4)
    assert co_rotated_min_ratio(r, v, valid, np.full((n, 1), np.nan), RHO, horizon)[0, 0] == -np.inf


def test_co_rotated_boundaries_are_where_the_fine_grid_band_changes():
    rng = np.random.default_rng(11)
    grid = np.linspace(-math.pi, math.pi, 72001)[None, :]  # 0.005° apart
    checked = 0
    for _ in range(40):
        r = rng.uniform(-20000, 20000, size=(1, 1, 2))
        v = rng.uniform(-460, 460, size=(1, 1, 2))
        clear = co_rotated_min_ratio(r, v, np.ones((1, 1), bool), grid, RHO, 120.0)[0] >= 1
        edges = grid[0, 1:][clear[1:] != clear[:-1]]
        bounds = co_rotated_boundaries(r, v, np.ones((1, 1), bool), RHO, 120.0)[0]
        bounds = bounds[np.isfinite(bounds)]
        for e in edges:  # every edge of the clear set is one of the closed-form boundaries
            gap = np.abs(wrap_angle(bounds - e)).min()
            assert gap < 2e-4
            checked += 1
    assert checked > 20


def test_mode_paths_of_a_straight_mode_are_the_cpa_test():
    # a mode predicting straight flight puts xs = r + v·t: the polyline is the straight
    # relative track, so the distance is the closed-form clamped CPA of "bands" over [0, T]
    rng = np.random.default_rng(13)
    n, k, c, T = 5, 4, 7, 45.0
    own = rng.uniform(-250, 250, size=(n, 2))
    r = rng.uniform(-15000, 15000, size=(n, k, 2))
    v = rng.uniform(-460, 460, size=(n, k, 2))
    valid = rng.random((n, k)) < 0.8
    t = np.linspace(T / 10, T, 10)
    xs = (r[:, :, None, :] + v[:, :, None, :] * t[:, None])[:, :, None]  # one mode
    psi = rng.uniform(-1.2, 1.2, size=(n, c))
    got = mode_path_min_ratio(own, r, xs, t, valid[:, :, None], psi, RHO, chunk=3)
    want = cpa_min_ratio_numpy(own, r, v, valid, psi, RHO, T)
    # exact where some path can come within the radius, else only "clear" (> 1) is promised
    exact = np.isclose(got, want, rtol=1e-9)
    assert np.all(exact | ((got == np.inf) & (want > 1.0)))
    assert exact.sum() > 10


def test_mode_aware_sees_a_turning_intruder_the_straight_test_misses():
    # an intruder 12 km ahead-right flying parallel, turning left into the ownship at 3°/s:
    # straight, the current heading is clear; its turn mode's path crosses the ownship's
    own = np.array([[V, 0.0]])
    r = np.array([[[8000.0, -6000.0]]])
    w = math.radians(3.0)
    t = np.arange(1, 46, dtype=float)
    # the intruder's coordinated turn from heading 0 at rate w, relative to a straight ownship
    xi = r[0, 0, 0] + V * np.sin(w * t) / w - V * t
    yi = r[0, 0, 1] + V * (1 - np.cos(w * t)) / w
    xs = np.stack([xi, yi], axis=-1)[None, None, None]  # (1, 1, 1, S, 2)
    ratio = mode_path_min_ratio(own, r, xs, t, np.ones((1, 1, 1), bool), np.zeros((1, 1)), RHO)
    direct = np.hypot(xi, yi).min() / RHO
    assert ratio[0, 0] < 1.0 and ratio[0, 0] == pytest.approx(direct, rel=0.02)
    straight = cpa_min_ratio_numpy(
        own, r, np.zeros((1, 1, 2)), np.ones((1, 1), bool), np.zeros((1, 1)), RHO, 45.0
    )
    assert straight[0, 0] > 1.0


def test_without_convention_or_predictions_the_choice_is_bands():
    rng = np.random.default_rng(17)
    n, k = 40, 6
    own = rng.uniform(-250, 250, size=(n, 2))
    r = rng.uniform(-20000, 20000, size=(n, k, 2))
    v = rng.uniform(-460, 460, size=(n, k, 2))
    valid = rng.random((n, k)) < 0.7
    mx = np.full(n, math.pi / 2)
    params = {"r_safe": R_SAFE, "margin": MARGIN}
    want = registry.build("resolver", "bands", params=params).resolve(own, r, v, valid, mx)
    for name, extra in (("bands-modes", {}), ("bands-roundabout", {"parallel_angle": math.pi / 2})):
        got = registry.build("resolver", name, params={**params, **extra}).resolve(
            own, r, v, valid, mx
        )
        assert np.array_equal(got.heading_change, want.heading_change)
        assert np.array_equal(got.conflict, want.conflict)


def test_mode_aware_world_crossing_keeps_separation():
    sc = load("crossing", ['resolver.kind="bands-modes"'])
    m = World(sc, seed=0).run()
    assert m["los_events"] == 0 and m["min_separation_m"] >= R_SAFE


def test_mode_path_blocking_the_lone_escape_moves_the_choice():
    # a head-on intruder (bands: 2·asin(ρ/D) right) and a second track whose straight
    # prediction is far away but whose likely mode puts it, fixed, on that escape heading
    T = 45.0
    t = np.maximum(1, np.rint(T * np.arange(1, 11) / 10))  # the policy's sample times
    own = np.array([[V, 0.0]])
    lone = -2 * math.asin(RHO / D)
    p = 9000.0 * np.array([math.cos(lone), math.sin(lone)])  # on the lone escape track
    r = np.array([[[D, 0.0], [p[0], p[1] - 30000.0]]])
    v = np.array([[[-2 * V, 0.0], [-V, -V]]])  # second: straight, it is far off
    xs = np.zeros((1, 2, 1, t.size, 2))
    xs[0, 0, 0] = r[0, 0] + v[0, 0] * t[:, None]
    xs[0, 1, 0] = p - own[0] * t[:, None]  # fixed at p, seen from a straight ownship
    pred = (xs, np.zeros(xs.shape + (2,)), np.ones((1, 2, 1)))
    args = (own, r, v, np.array([[True, True]]), np.array([math.pi / 2]))
    params = {"r_safe": R_SAFE, "margin": MARGIN, "lookahead_s": T}
    bands = registry.build("resolver", "bands", params=params).resolve(*args)
    assert float(bands.heading_change[0]) == pytest.approx(lone, abs=1e-6)
    modes = registry.build("resolver", "bands-modes", params=params)
    psi = float(modes.resolve(*args, mode_predictions=pred).heading_change[0])
    # the choice clears the fixed point: the turned track's distance to p over [0, T]
    ts = np.linspace(0, T, 4501)
    track = np.stack([V * math.cos(psi) * ts, V * math.sin(psi) * ts], axis=1)
    assert np.hypot(*(track - p).T).min() >= RHO * (1 - 1e-6)
    assert abs(psi - lone) > math.radians(1.0)
    # judged only over the first 2 s (before any sample), it is bands again
    near = registry.build("resolver", "bands-modes", params={**params, "mode_horizon_s": 2.0})
    assert float(near.resolve(*args, mode_predictions=pred).heading_change[0]) == float(
        bands.heading_change[0]
    )
