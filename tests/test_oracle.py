"""The centralised oracle planner (avoidance/oracle.py): its motion against closed-form
turns, its plans flown in the World by controlled aircraft, brute-force optimality within
its family."""

import math

import numpy as np
import pytest

from airspace_sim.avoidance.oracle import (
    best_plan,
    common_plan,
    fly,
    fly_in_world,
    manoeuvre_family,
    priority_plan,
)
from airspace_sim.geometry import coordinated_turn_positions

V, RATE, R_SAFE = 230.0, math.radians(3.0), 3000.0
SMALL = manoeuvre_family(t0_s=(0, 20), offsets_deg=(20, 30, 45), hold_s=(40, 60, 80, 100, 120))


def ring(n, radius=20000.0):
    a = 2 * math.pi * np.arange(n) / n
    start = radius * np.stack([np.cos(a), np.sin(a)], axis=1)
    return start, a + math.pi, -start


def test_fly_turns_on_the_closed_form_arc_and_arrives_on_the_capture_step():
    # δ = +90° held long: 30 s at the 3°/s limit, on the circle of radius v/ω
    cand = np.array([[0.0, math.radians(90.0), 500.0], [0.0, 0.0, 0.0]])
    pos, rates, arrival, flown = fly((0.0, 0.0), 0.0, (10100.0, 0.0), V, RATE, cand, 200)
    x0 = np.array([[0.0, V, 0.0, 0.0, RATE]])
    arc = coordinated_turn_positions(x0, np.arange(1, 31, dtype=float))[0]
    np.testing.assert_allclose(pos[0, 1:31], arc, atol=1e-6)
    np.testing.assert_allclose(rates[0, :30], RATE)
    # straight: captured at the first step within one step's travel, k = ceil(L/v − 1)
    assert arrival[1] == math.ceil(10100.0 / V - 1)
    assert flown[1] == pytest.approx(arrival[1] * V)
    assert np.isnan(pos[1, int(arrival[1]) + 1 :]).all()


def test_traffic_without_conflicts_flies_straight():
    start = np.array([[0.0, 0.0], [0.0, 10000.0]])
    dest = start + [30000.0, 0.0]
    p = best_plan(start, 0.0, dest, V, RATE, R_SAFE, 200, family=SMALL)
    assert p.feasible and (p.params[:, 2] == 0).all()
    assert -V <= p.extra_m.min() and p.extra_m.max() <= 0.0  # the capture slack only


def _world_replay(plan, start, heading, dest):
    """Fly the plan in the World; the World's metrics and the least distance between any
    two flying aircraft at any step instant (brute force over the positions)."""
    min_d = math.inf

    def observe(w):
        nonlocal min_d
        idx = np.flatnonzero(w.active)
        if idx.size > 1:
            d = np.hypot(*(w.positions[idx, None] - w.positions[None, idx]).transpose(2, 0, 1))
            min_d = min(min_d, d[np.triu_indices(idx.size, 1)].min())

    m = fly_in_world(plan, start, heading, dest, V, RATE, R_SAFE, after_step=observe)
    return m, min_d


@pytest.mark.parametrize("planner", [common_plan, priority_plan])
def test_ring_plans_fly_conflict_free_in_the_world(planner):
    start, heading, dest = ring(6)
    plan = planner(start, heading, dest, V, RATE, R_SAFE, 320, family=SMALL)
    assert plan.feasible and np.isfinite(plan.arrival).all()
    m, min_d = _world_replay(plan, start, heading, dest)
    assert m["los_pairs"] == 0 and min_d >= R_SAFE
    assert m["arrived"] == 6 and m["not_arrived"] == 0
    assert m["extra_path_m"] == pytest.approx(plan.extra_m.sum(), abs=1e-3)
    assert m["extra_path_pct"] == pytest.approx(plan.extra_pct, abs=1e-6)
    assert plan.extra_pct > 0  # straight through the centre is a conflict


def test_priority_plan_is_the_cheapest_clear_member_brute_force():
    # head-on pair: the first flies straight; the second takes the cheapest member of the
    # family that keeps r_safe from it at every step instant (checked member by member)
    start = np.array([[-20000.0, 0.0], [20000.0, 0.0]])
    heading = np.array([0.0, math.pi])
    dest = -start
    plan = priority_plan(start, heading, dest, V, RATE, R_SAFE, 300, family=SMALL)
    assert plan.feasible and plan.params[0, 2] == 0.0
    best = math.inf
    first = plan.positions[0]
    for c in SMALL:
        pos, _, arr, fl = fly(start[1], heading[1], dest[1], V, RATE, c[None], 300)
        d = np.hypot(*(pos[0] - first).T)
        if np.isfinite(arr[0]) and not (d[np.isfinite(d)] < R_SAFE).any():
            best = min(best, fl[0])
    assert plan.extra_m[1] == pytest.approx(best - np.hypot(*(dest[1] - start[1])))


def test_infeasible_when_the_family_cannot_separate():
    start, heading, dest = ring(6)
    only_straight = manoeuvre_family(t0_s=(), offsets_deg=(), hold_s=())
    p = common_plan(start, heading, dest, V, RATE, R_SAFE, 320, family=only_straight)
    assert not p.feasible and math.isinf(p.extra_pct)
