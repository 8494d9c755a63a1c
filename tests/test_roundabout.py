"""bands-roundabout (avoidance/roundabout.py): the right-of-way convention against geometry."""

import math

import numpy as np
import pytest

from airspace_sim import registry
from airspace_sim.avoidance.roundabout import candidate_time_to_loss, give_way, time_to_loss
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
