"""The CDA policy's resume rules (world/policy.py, ``resolver.resume_rule``): the turn back
judged against brute-force time sampling of straight flight, a two-aircraft overtaking where
"no-worse" turns back sooner and keeps r_safe, and the loader's rule for the knob."""

import numpy as np
import pytest

from airspace_sim.errors import UserError
from airspace_sim.scenarios import load
from airspace_sim.world import World
from airspace_sim.world.control import Encounters
from airspace_sim.world.policy import RESUME_FRACTIONS, AvoidancePolicy, turn_probability

R_SAFE, MARGIN, RESUME_MARGIN, LOOKAHEAD_S = 3000.0, 0.1, 1.5, 120.0
R0 = R_SAFE * (1 + MARGIN)  # m, the resolver's clear radius
R1 = R_SAFE * (1 + MARGIN + RESUME_MARGIN)  # m, the resume radius


def _policy(rule, n=2):
    sc = load("dense_random", [f'resolver.resume_rule="{rule}"', "resolver.lookahead=120.0"])
    pol = AvoidancePolicy(sc, 1.0, np.ones(n, bool), np.ones(n, bool))
    assert (pol.r_safe, pol.margin, pol.resume_margin, pol.lookahead_s) == (
        R_SAFE,
        MARGIN,
        RESUME_MARGIN,
        LOOKAHEAD_S,
    )
    return pol


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


@pytest.mark.parametrize("rule", ["partial", "no-worse", "diverging"])
def test_the_fraction_flown_is_the_largest_that_passes_by_brute_force(rule):
    rng = np.random.default_rng(5)
    n, k = 300, 3
    vo = rng.uniform(-250, 250, (n, 2))
    r = rng.uniform(-12000, 12000, (n, k, 2))
    v = rng.uniform(-400, 400, (n, k, 2))
    valid = rng.random((n, k)) < 0.8
    turn = rng.uniform(-0.06, 0.06, n)
    pol = _policy(rule, n)
    enc = Encounters(np.arange(n), np.zeros((n, k), np.int64), r, v, valid)
    got = pol._resume_fraction(enc, vo, turn, np.full(n, np.radians(3.0)))
    checked = 0
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
            ok = (ds >= R0) & (capped >= capped[-1:]).all(axis=1)
        else:
            ok = (ds >= R0) & ((each >= R1) | (each >= now)).all(axis=1)
        ok[-1] = True
        assert got[i] == RESUME_FRACTIONS[np.argmax(ok)], i
        checked += 1
    assert checked > n // 2
    assert 0 < np.count_nonzero((got > 0) & (got < 1))  # partial turns happen


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
    assert load("ring").resolver.resume_rule == "hold"
    assert load("ring", ['resolver.resume_rule="partial"']).resolver.resume_rule == "partial"
    with pytest.raises(UserError) as info:
        load("ring", ['resolver.resume_rule="sideways"'])
    msg = str(info.value)
    assert "\n" not in msg and "resolver.resume_rule" in msg and "sideways" in msg
    assert "hold, partial, no-worse" in msg


def _guarded_policy(rule, n, **knobs):
    pol = _policy(rule, n)
    pol.resume_decay_s = None  # dense_random's decay would shrink R1 with off_route_s
    for k, v in knobs.items():
        setattr(pol, k, v)
    return pol


@pytest.mark.parametrize("rule", ["no-worse", "diverging"])
@pytest.mark.parametrize("guard", ["turning", "crowd", "after"])
def test_the_guards_require_the_resume_radius_by_brute_force(rule, guard):
    # The three guards of the non-"hold" rules: a turning intruder (turn probability >= p),
    # a crowded ownship (>= m intruders inside R1 now) and an ownship off its route for less
    # than resume_rule_after_s each replace the rule's floor by R1 ("hold"'s test).
    rng = np.random.default_rng(11)
    n, k = 300, 3
    vo = rng.uniform(-250, 250, (n, 2))
    r = rng.uniform(-10000, 10000, (n, k, 2))
    v = rng.uniform(-400, 400, (n, k, 2))
    valid = rng.random((n, k)) < 0.8
    turn = rng.uniform(-0.06, 0.06, n)
    turn_p = rng.random((n, k))
    knobs = {"turning": {"resume_turning_p": 0.5}, "crowd": {"resume_crowd": 2}}
    knobs["after"] = {"rule_after_s": 60.0}
    pol = _guarded_policy(rule, n, **knobs[guard])
    pol.off_route_s = rng.uniform(0.0, 120.0, n)
    enc = Encounters(np.arange(n), np.zeros((n, k), np.int64), r, v, valid)
    got = pol._resume_fraction(enc, vo, turn, np.full(n, np.radians(3.0)), turn_p)
    checked = guarded_rows = 0
    for i in range(n):
        sel = valid[i]
        if not sel.any():
            continue
        each = np.array(
            [
                _brute_min_distance(vo[i], r[i][sel], v[i][sel], f * turn[i])
                for f in RESUME_FRACTIONS
            ]
        )  # (fractions, valid intruders) m
        now = np.hypot(r[i][sel][:, 0], r[i][sel][:, 1])
        if guard == "turning":
            strict = turn_p[i][sel] >= 0.5
        elif guard == "crowd":
            strict = np.full(sel.sum(), (now < R1).sum() >= 2)
        else:
            strict = np.full(sel.sum(), pol.off_route_s[i] < 60.0)
        ds = each.min(axis=1)
        capped = np.minimum(each, R1)
        near = [abs(ds / R0 - 1).min() < 1e-3, (abs(each / R1 - 1) < 1e-3).any()]
        if rule == "no-worse":
            rel = abs(capped[:-1] / capped[-1:] - 1)
            near.append(bool(((rel > 0) & (rel < 1e-5)).any()))
            own = capped >= capped[-1:]
        else:
            gap = 1 - each / now
            near.append(bool(((gap > 0) & (gap < 1e-5)).any()))
            own = (each >= R1) | (each >= now)
        if any(near):
            continue
        ok = (ds >= R0) & np.where(strict[None, :], each >= R1, own).all(axis=1)
        ok[-1] = True
        assert got[i] == RESUME_FRACTIONS[np.argmax(ok)], i
        checked += 1
        guarded_rows += bool(strict.any())
    assert checked > n // 2 and guarded_rows > n // 10
    # the guard changes decisions: without it the same encounters turn back more often
    free = _guarded_policy(rule, n)._resume_fraction(enc, vo, turn, np.full(n, np.radians(3.0)), turn_p)
    assert (got <= free).all() and (got < free).any()


def test_a_refused_turn_back_stays_refused_for_resume_refused_hold_s():
    # Ownship east at 200 m/s wants to turn left. Step 0: an intruder 5 km ahead and
    # closing head-on at 400 m/s blocks it (its CPA is a collision). From step 1 on there is
    # no intruder: without hysteresis the turn back flies at once; with 5 s it waits until
    # step 5 (steps 0-4 held).
    blocked = Encounters(
        np.array([0]),
        np.array([[0]]),
        np.array([[[5000.0, 0.0]]]),
        np.array([[[-400.0, 0.0]]]),
        np.array([[True]]),
    )
    clear = Encounters(
        np.array([0]),
        np.array([[-1]]),
        np.zeros((1, 1, 2)),
        np.zeros((1, 1, 2)),
        np.zeros((1, 1), bool),
    )
    rate = np.array([np.radians(3.0)])
    vel = np.array([[200.0, 0.0]])
    flown = {}
    for hold_s in (0.0, 5.0):
        pol = _policy("no-worse", 1)
        pol.refused_hold_steps = int(hold_s)
        flown[hold_s] = []
        for step in range(8):
            pol._encounters = blocked if step == 0 else clear
            out = pol.override(rate.copy(), np.zeros(1), np.ones(1, bool), vel, np.radians([3.0]))
            flown[hold_s].append(float(out[0]))
    assert flown[0.0] == [0.0] + [rate[0]] * 7
    assert flown[5.0] == [0.0] * 5 + [rate[0]] * 3


def test_turn_probability_is_one_minus_the_straight_mode_of_each_track():
    w = World(
        load("dense_random", ['resolver.resume_rule="no-worse"', "resolver.resume_turning_p=0.5"]),
        seed=0,
    )
    for _ in range(30):
        w.step()
    view, enc = w.tracks.view(), w.policy._encounters
    p = turn_probability(w.tracks, view, enc)
    straight = list(w.tracks.mode_names).index("straight")
    assert enc.valid.sum() > 50
    for o, kk in zip(*np.nonzero(enc.valid), strict=True):
        row = enc.rows[o, kk]
        assert view.owner[row] == enc.owners[o]
        assert p[o, kk] == 1.0 - view.mu[row, straight]
    assert np.isnan(p[~enc.valid]).all()
    np.testing.assert_array_equal(p, w.policy._turn_p)
    assert (p[enc.valid] > 0.5).any() and (p[enc.valid] < 0.5).any()


def test_guard_knobs_defaults_and_validation():
    r = load("ring").resolver
    assert (r.resume_turning_p, r.resume_crowd, r.resume_rule_after_s, r.resume_refused_hold_s) == (
        None,
        None,
        0.0,
        0.0,
    )
    for bad in (
        "resume_turning_p=1.5",
        "resume_crowd=0",
        "resume_rule_after_s=-1.0",
        "resume_refused_hold_s=-2.0",
    ):
        with pytest.raises(UserError) as info:
            load("ring", [f"resolver.{bad}"])
        msg = str(info.value)
        assert "\n" not in msg and f"resolver.{bad.split('=')[0]}" in msg
