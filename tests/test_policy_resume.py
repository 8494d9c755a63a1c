"""The CDA policy's resume rules (world/policy.py, ``resolver.resume_rule``): the turn back
judged against brute-force time sampling of straight flight, a two-aircraft overtaking where
"no-worse" turns back sooner and keeps r_safe, and the loader's rule for the knob."""

import numpy as np
import pytest

from airspace_sim.errors import UserError
from airspace_sim.scenarios import load
from airspace_sim.world import World
from airspace_sim.world.control import Encounters
from airspace_sim.world.policy import RESUME_FRACTIONS, AvoidancePolicy

R_SAFE, MARGIN, RESUME_MARGIN, LOOKAHEAD_S = 3000.0, 0.1, 1.5, 120.0
R0 = R_SAFE * (1 + MARGIN)  # m, the resolver's clear radius
R1 = R_SAFE * (1 + MARGIN + RESUME_MARGIN)  # m, the resume radius


def _policy(rule, n=2):
    sc = load(
        "dense_random",
        [f'resolver.resume_rule="{rule}"', "resolver.lookahead=120.0", f"resolver.margin={MARGIN}"],
    )
    pol = AvoidancePolicy(sc, 1.0, np.ones(n, bool), np.ones(n, bool))
    assert (pol.r_safe, pol.margin, pol.resume_margin, pol.lookahead_s) == (
        R_SAFE,
        MARGIN,
        RESUME_MARGIN,
        LOOKAHEAD_S,
    )
    return pol


def _off_course_policy(n, degrees):
    sc = load(
        "dense_random",
        [
            'resolver.resume_rule="no-worse"',
            "resolver.lookahead=120.0",
            f"resolver.margin={MARGIN}",
            f"resolver.resume_off_course_deg={degrees}",
        ],
    )
    return AvoidancePolicy(sc, 1.0, np.ones(n, bool), np.ones(n, bool))


def _brute_min_distance(vo, r, v, psi):
    """(K,) minimum distance over t in [0, T] sampled every 0.01 s, the ownship turned by psi
    rad and then straight, the intruders straight (r, v: (K, 2) relative at psi = 0)."""
    t = np.linspace(0.0, LOOKAHEAD_S, 12001)[:, None, None]
    c, s = np.cos(psi), np.sin(psi)
    turned = np.array([c * vo[0] - s * vo[1], s * vo[0] + c * vo[1]])
    vi = v + vo  # intruder world velocities
    d = r[None] + t * (vi - turned)[None]
    return np.hypot(d[..., 0], d[..., 1]).min(axis=0)


def test_a_passed_diverging_intruder_inside_the_resume_radius_blocks_only_hold():
    # Ownship east at 200 m/s; the intruder, flying west at 200 m/s, passed 3 km ago and is
    # 5 km to the left: |r| = 5831 m, inside R1 = 7800 m but diverging. A 3 deg left turn
    # keeps r·v > 0, so its closest point is now: 5831 m, the same as holding.
    r = np.array([[-3000.0, 5000.0]])
    vo = np.array([200.0, 0.0])
    v = np.array([[-400.0, 0.0]])
    turn = np.radians(3.0)
    turned = np.array([np.cos(turn), np.sin(turn)]) * 200.0
    assert np.dot(r[0], v[0] + vo - turned) > 0  # closed form: diverging after the turn
    want = np.hypot(3000.0, 5000.0)
    got = _brute_min_distance(vo, r, v, turn)[0]
    assert got == pytest.approx(want, abs=1e-6) and R0 < got < R1
    enc = Encounters(np.array([0]), np.array([[0]]), r[None], v[None], np.array([[True]]))
    velocities = np.array([vo, vo])
    mx = np.full(2, np.radians(3.0))
    fly = np.full(1, turn)
    assert _policy("hold")._resume_clear(enc, velocities, fly, mx).tolist() == [False]
    assert _policy("partial")._resume_fraction(enc, velocities, fly, mx).tolist() == [0.0]
    assert _policy("no-worse")._resume_fraction(enc, velocities, fly, mx).tolist() == [1.0]


@pytest.mark.parametrize(
    "rule, off_course_deg",
    [("partial", None), ("no-worse", None), ("diverging", None), ("no-worse", 30.0)],
)
def test_the_fraction_flown_is_the_largest_that_passes_by_brute_force(rule, off_course_deg):
    # with off_course_deg, random autopilot headings: an ownship at least that far off course
    # passes a fraction on the no-conflict test alone, the others on "no-worse"'s full test
    rng = np.random.default_rng(5)
    n, k = 300, 3
    vo = rng.uniform(-250, 250, (n, 2))
    r = rng.uniform(-12000, 12000, (n, k, 2))
    v = rng.uniform(-400, 400, (n, k, 2))
    valid = rng.random((n, k)) < 0.8
    turn = rng.uniform(-0.06, 0.06, n)
    heading = np.arctan2(vo[:, 1], vo[:, 0])
    desired = heading + rng.uniform(-np.pi, np.pi, n)
    off = np.zeros(n, bool)
    if off_course_deg is None:
        pol = _policy(rule, n)
    else:
        pol = _off_course_policy(n, off_course_deg)
        off = np.abs(np.angle(np.exp(1j * (desired - heading)))) >= np.radians(off_course_deg)
    enc = Encounters(np.arange(n), np.zeros((n, k), np.int64), r, v, valid)
    got = pol._resume_fraction(enc, vo, turn, np.full(n, np.radians(3.0)), desired)
    checked = waived = 0
    for i in range(n):
        # (fractions, valid intruders) minimum distances, m
        each = np.array(
            [
                _brute_min_distance(vo[i], r[i][valid[i]], v[i][valid[i]], f * turn[i])
                for f in RESUME_FRACTIONS
            ]
        )
        if not each.size:
            continue  # no intruder: every rule turns back in full
        ds = each.min(axis=1)
        capped = np.minimum(each, R1)
        near = [abs(ds / x - 1).min() < 1e-3 for x in (R0, R1)]
        near.append(rule != "partial" and (abs(each / R1 - 1) < 1e-3).any())
        if rule == "no-worse":
            # exact ties (a diverging intruder's closest point is now, whatever the turn) are
            # decided; near ties are not (sampling error ~1e-6)
            rel = abs(capped[:-1] / capped[-1:] - 1)
            near.append(bool(((rel > 0) & (rel < 1e-5)).any()))
        now = np.hypot(r[i][valid[i]][:, 0], r[i][valid[i]][:, 1])  # (valid,) m
        if rule == "diverging":
            # sampling includes t = 0: a diverging pair's sampled minimum is exactly now
            gap = 1 - each / now
            near.append(bool(((gap > 0) & (gap < 1e-5)).any()))
        if any(near):
            continue  # sampling cannot decide a tie at a threshold
        if rule == "partial":
            ok = ds >= R1
        elif rule == "no-worse":
            plain = (ds >= R0) & (capped >= capped[-1:]).all(axis=1)
            ok = plain | ((ds >= R0) & off[i])
            plain[-1] = True
            ok[-1] = True
            waived += int(np.argmax(plain) != np.argmax(ok))
        else:
            ok = (ds >= R0) & ((each >= R1) | (each >= now)).all(axis=1)
        ok[-1] = True
        assert got[i] == RESUME_FRACTIONS[np.argmax(ok)], i
        checked += 1
    assert checked > n // 2
    assert 0 < np.count_nonzero((got > 0) & (got < 1))  # partial turns happen
    if off_course_deg is not None:
        assert waived > 0  # the waiver changed some decisions


def test_no_worse_turns_back_sooner_on_an_overtaking_and_keeps_r_safe():
    # A 250 m/s aircraft overtakes a 180 m/s one on the same track. After the pass the two
    # diverge at 70 m/s from ~3.3 km apart: "hold" waits until 7.8 km, "no-worse" turns back
    # while the other stays no closer. Separation is checked on the true positions.
    held, closest, extra = {}, {}, {}
    for rule in ("hold", "no-worse"):
        w = World(load("overtaking", [f'resolver.resume_rule="{rule}"']), seed=0)
        held[rule], closest[rule] = 0, np.inf
        for _ in range(400):
            w.step()
            held[rule] += int((w.policy.following & ~w.policy.conflict & w.active).sum())
            if w.active.all():
                d = np.hypot(*(w.positions[0] - w.positions[1]))
                closest[rule] = min(closest[rule], float(d))
        extra[rule] = w.metrics()["extra_path_pct"]
    assert held["no-worse"] < held["hold"], held
    assert closest["no-worse"] >= R_SAFE and closest["hold"] >= R_SAFE, closest
    assert extra["no-worse"] < extra["hold"], extra


def test_resume_rule_default_and_validation():
    from airspace_sim.scenarios.schema import ResolverSpec

    assert ResolverSpec().resume_rule == "hold"
    assert load("ring").resolver.resume_rule == "no-worse"  # the shipped ring's choice
    assert load("ring", ['resolver.resume_rule="partial"']).resolver.resume_rule == "partial"
    with pytest.raises(UserError) as info:
        load("ring", ['resolver.resume_rule="sideways"'])
    msg = str(info.value)
    assert "\n" not in msg and "resolver.resume_rule" in msg and "sideways" in msg
    assert "hold, partial, no-worse" in msg


def _integrated_turning_min(vo, r, vi, psi, w, turn_s, T=LOOKAHEAD_S, step=2.0, h=0.01):
    """(2,) min distance, m, on the grid t = 0, 2, ..., T with the intruder turning left and
    right at w rad/s for turn_s s then straight (heading integrated, midpoint rule), the
    ownship turned by psi and straight: the oracle of "no-worse-turns"."""
    n = int(round(T / h))
    tt = np.arange(n) * h + h / 2
    c, s = np.cos(psi), np.sin(psi)
    own = np.array([c * vo[0] - s * vo[1], s * vo[0] + c * vo[1]])
    grid = np.rint(np.unique(np.append(np.arange(0.0, T, step), T)) / h).astype(int)
    out = []
    for sign in (1.0, -1.0):
        a = sign * w * np.minimum(tt, turn_s)
        px = np.concatenate([[0.0], np.cumsum((np.cos(a) * vi[0] - np.sin(a) * vi[1]) * h)])
        py = np.concatenate([[0.0], np.cumsum((np.sin(a) * vi[0] + np.cos(a) * vi[1]) * h)])
        t = grid * h
        out.append(np.hypot(r[0] + px[grid] - own[0] * t, r[1] + py[grid] - own[1] * t).min())
    return np.array(out)


@pytest.mark.parametrize("clear", [False, True])
def test_no_worse_turns_by_brute_force(clear):
    # "no-worse" on the straight prediction, and again against each intruder turning left
    # and right at 3 deg/s for 30 s: no turned path comes closer (capped at R1, or at R0
    # with resume_turn_clear) than holding.
    rng = np.random.default_rng(21)
    n, k = 80, 2
    vo = rng.uniform(-250, 250, (n, 2))
    r = rng.uniform(-12000, 12000, (n, k, 2))
    v = rng.uniform(-400, 400, (n, k, 2))
    valid = rng.random((n, k)) < 0.9
    turn = rng.uniform(-0.06, 0.06, n)
    pol = _policy("no-worse-turns", n)
    assert pol.resume_turn_s == 60.0  # the default
    pol.resume_turn_s = 30.0
    pol.resume_turn_clear = clear
    cap = R0 if clear else R1  # m, what a turned path may not be brought inside
    w = np.radians(3.0)
    enc = Encounters(np.arange(n), np.zeros((n, k), np.int64), r, v, valid)
    got = pol._resume_fraction(enc, vo, turn, np.full(n, w))
    plain = _policy("no-worse", n)._resume_fraction(enc, vo, turn, np.full(n, w))
    checked = 0
    for i in range(n):
        sel = np.flatnonzero(valid[i])
        if not sel.size:
            continue
        straight = np.array(
            [
                _brute_min_distance(vo[i], r[i][sel], v[i][sel], f * turn[i])
                for f in RESUME_FRACTIONS
            ]
        )  # (F, K') m
        turned = np.array(
            [
                [
                    _integrated_turning_min(vo[i], r[i, j], v[i, j] + vo[i], f * turn[i], w, 30.0)
                    for j in sel
                ]
                for f in RESUME_FRACTIONS
            ]
        )  # (F, K', 2) m
        ds = straight.min(axis=1)
        capped, tcap = np.minimum(straight, R1), np.minimum(turned, cap)
        rel = abs(capped[:-1] / capped[-1:] - 1)
        trel = abs(tcap[:-1] / tcap[-1:] - 1)
        if (
            abs(ds / R0 - 1).min() < 1e-3
            or (abs(straight / R1 - 1) < 1e-3).any()
            or (abs(turned / cap - 1) < 1e-6).any()
            or ((rel > 0) & (rel < 1e-5)).any()
            or ((trel > 0) & (trel < 1e-6)).any()
        ):
            continue  # a tie at a threshold: sampling cannot decide it
        ok = (ds >= R0) & (capped >= capped[-1:]).all(axis=1)
        ok &= (tcap >= tcap[-1:]).all(axis=(1, 2))
        ok[-1] = True
        assert got[i] == RESUME_FRACTIONS[np.argmax(ok)], i
        checked += 1
    assert checked > n // 2
    assert (got <= plain).all() and (got < plain).any()  # stricter than no-worse, and it matters


def test_resume_turn_knobs_defaults_and_validation():
    r = load("ring").resolver
    assert (r.resume_turn_s, r.resume_turn_clear) == (60.0, False)
    sc = load("ring", ['resolver.resume_rule="no-worse-turns"', "resolver.resume_turn_s=20.0"])
    assert (sc.resolver.resume_rule, sc.resolver.resume_turn_s) == ("no-worse-turns", 20.0)
    with pytest.raises(UserError) as info:
        load("ring", ["resolver.resume_turn_s=-1.0"])
    msg = str(info.value)
    assert "\n" not in msg and "resolver.resume_turn_s" in msg and "-1" in msg


def test_off_course_an_ownship_turns_back_past_a_neighbour_no_worse_holds_it_for():
    # Ownship east at 200 m/s, its autopilot's heading `off` degrees to the left. The
    # intruder 5 km ahead-left at 6 km lateral, flying east at 190 m/s: a slow overtaking
    # whose closest distance (~6 km, inside R1 = 7.8 km, outside R0 = 3.3 km) a 3 deg left
    # turn lowers. "no-worse" holds; waived from 30 deg off course on, it turns back.
    r = np.array([[5000.0, 6000.0]])
    vo = np.array([200.0, 0.0])
    v = np.array([[-10.0, 0.0]])
    turn = np.radians(3.0)
    held, turned = (_brute_min_distance(vo, r, v, f * turn)[0] for f in (0.0, 1.0))
    assert R0 < turned < held < R1
    enc = Encounters(np.array([0]), np.array([[0]]), r[None], v[None], np.array([[True]]))
    velocities, mx, fly = np.array([vo, vo]), np.full(2, turn), np.full(1, turn)
    for off, want in ((20.0, 0.0), (40.0, 1.0), (-40.0, 1.0)):
        desired = np.array([np.radians(off)])
        got = _off_course_policy(2, 30.0)._resume_fraction(enc, velocities, fly, mx, desired)
        assert got.tolist() == [want], off
    plain = _policy("no-worse")._resume_fraction(enc, velocities, fly, mx, np.array([0.7]))
    assert plain.tolist() == [0.0]
    # an intruder the turn would bring inside R0 still holds an ownship however far off
    # course: the waiver keeps the no-conflict test
    close = Encounters(
        np.array([0]),
        np.array([[0]]),
        np.array([[[1000.0, 3500.0]]]),
        v[None],
        np.ones((1, 1), bool),
    )
    near = _brute_min_distance(vo, close.rel_position[0], v, turn)[0]
    assert near < R0 < _brute_min_distance(vo, close.rel_position[0], v, 0.0)[0]
    got = _off_course_policy(2, 30.0)._resume_fraction(
        close, velocities, fly, mx, np.array([np.radians(90.0)])
    )
    assert got[0] < 1.0


def test_resume_off_course_validation():
    from airspace_sim.scenarios.schema import ResolverSpec

    assert ResolverSpec().resume_off_course_deg is None
    # another rule ignores it, as the other rules' knobs (resume_turn_s, ...)
    sc = load("ring", ['resolver.resume_rule="hold"', "resolver.resume_off_course_deg=30.0"])
    assert World(sc, seed=0).policy.resume_off_course == pytest.approx(np.radians(30.0))
    with pytest.raises(UserError) as info:
        load("ring", ["resolver.resume_off_course_deg=200.0"])
    msg = str(info.value)
    assert "\n" not in msg and "resolver.resume_off_course_deg" in msg and "200" in msg
