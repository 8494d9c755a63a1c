"""An oracle reference for multi-aircraft scenes: a centralised, perfect-knowledge planner.

A resolver decides from noisy tracks, one ownship at a time, with no knowledge of what the
others will do. This planner knows every aircraft's true start, speed and destination and
plans all of them together, before anything flies, under the same heading-only dynamics
and turn limit as the world (:class:`~airspace_sim.world.World`'s chord motion, 1 s steps,
route capture within one step's travel or once past abeam). Its extra path is what a
perfect coordinator achieves on the scene: an *achievable* reference (an upper bound on
the true minimum), so "the resolver flies X% extra, a centralised plan needs Y%" says how
far the resolver is from the best achievable, up to the planner's own suboptimality.

Each aircraft flies one manoeuvre of a small family (:func:`manoeuvre_family`): direct to
its destination, at ``t0`` turn (at the turn limit) onto the heading ``h(t0) + δ``, hold
it for ``T`` seconds, then turn back direct to the destination. Two planners search it:

- :func:`priority_plan`: aircraft in a priority order each take the member with the least
  extra path that keeps ``r_safe`` from every aircraft already planned, at every step
  instant (the world's LoS rule), and arrives within the horizon; several orders tried;
- :func:`common_plan`: every aircraft flies the *same* member (the roundabout of a
  symmetric ring: all offset the same way, so they stay a rotated copy of each other);
  the cheapest member that keeps every pair clear.

:func:`best_plan` runs both and keeps the cheaper conflict-free plan. ``plan.turn_rates``
(N, S) is flown in the world by controlled aircraft to check it (:func:`fly_in_world`). Units: metres, seconds, radians CCW from east.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit


@dataclass
class Plan:
    """A conflict-free plan for N aircraft (or ``feasible`` False if none was found).

    turn_rates (N, S) rad/s per step; positions (N, S + 1, 2) m at step instants (NaN once
    arrived); arrival (N,) s (NaN: not arrived); extra_m (N,) flown − plan length, m;
    extra_pct = 100·Σ extra / Σ plan length; method: which planner; params (N, 3):
    (t0 s, δ rad, T s) of each aircraft's manoeuvre.
    """

    feasible: bool
    turn_rates: np.ndarray
    positions: np.ndarray
    arrival: np.ndarray
    extra_m: np.ndarray
    extra_pct: float
    method: str
    params: np.ndarray


def manoeuvre_family(
    t0_s=tuple(range(0, 61, 10)),
    offsets_deg=tuple(range(10, 91, 10)),
    hold_s=tuple(range(10, 241, 10)),
) -> np.ndarray:
    """(C, 3) candidates ``(t0 s, δ rad, T s)``, both signs of δ, plus the straight flight
    ``(0, 0, 0)`` first."""
    rows = [(0.0, 0.0, 0.0)]
    for t0 in t0_s:
        for d in offsets_deg:
            for T in hold_s:
                rows += [(t0, math.radians(d), T), (t0, -math.radians(d), T)]
    return np.array(rows, dtype=float)


@njit(cache=True, error_model="numpy")
def _fly_kernel(x0, y0, h0, dx, dy, speed, max_rate, cand, steps, dt, out, rates, arrival):
    """The loop of :func:`fly`, one candidate at a time (scalar math, numba)."""
    step_len = speed * dt
    lx, ly = dx - x0, dy - y0
    flown = np.zeros(cand.shape[0])
    for c in range(cand.shape[0]):
        t0, delta, hold = cand[c, 0], cand[c, 1], cand[c, 2]
        x, y, h = x0, y0, h0
        locked = np.nan
        out[c, 0, 0], out[c, 0, 1] = x, y
        for k in range(steps):
            t = k * dt
            if hold > 0 and t >= t0 and np.isnan(locked):
                locked = h + delta
            if hold > 0 and t0 <= t < t0 + hold:
                desired = locked
            else:
                desired = math.atan2(dy - y, dx - x)
            e = (desired - h + math.pi) % (2 * math.pi) - math.pi
            w = min(max(e / dt, -max_rate), max_rate)
            turn = w * dt
            mid = h + 0.5 * turn
            u = 0.5 * turn
            chord = step_len * (math.sin(u) / u if u != 0.0 else 1.0)
            x += chord * math.cos(mid)
            y += chord * math.sin(mid)
            h = (h + turn + math.pi) % (2 * math.pi) - math.pi
            rates[c, k] = w
            flown[c] += step_len
            out[c, k + 1, 0], out[c, k + 1, 1] = x, y
            tx, ty = dx - x, dy - y
            if math.hypot(tx, ty) <= step_len or tx * lx + ty * ly < 0.0:
                arrival[c] = (k + 1) * dt
                break
    return flown


def fly(start, heading, dest, speed, max_rate, cand, steps: int, dt: float = 1.0):
    """Fly one aircraft through every candidate of ``cand`` (C, 3).

    start (2,) m, heading rad, dest (2,) m, speed m/s, max_rate rad/s. Returns
    ``(positions (C, steps + 1, 2) m, NaN after arrival; rates (C, steps) rad/s; arrival
    (C,) s, NaN if not arrived within ``steps``; flown (C,) m)``. The motion is the world's:
    turn ``ω·dt`` clipped to the limit, the chord of the arc at the mid heading, the route
    captured within one step's travel of the destination or once past abeam of it.
    """
    cand = np.ascontiguousarray(cand, dtype=float)
    C = len(cand)
    out = np.full((C, steps + 1, 2), np.nan)
    rates = np.zeros((C, steps))
    arrival = np.full(C, np.nan)
    flown = _fly_kernel(
        float(start[0]), float(start[1]), float(heading), float(dest[0]), float(dest[1]),
        float(speed), float(max_rate), cand, int(steps), float(dt), out, rates, arrival,
    )  # fmt: skip
    return out, rates, arrival, flown


@njit(cache=True, error_model="numpy")
def _clear_kernel(cand_pos, others, r2, ok):
    for c in range(cand_pos.shape[0]):
        if not ok[c]:
            continue
        for o in range(others.shape[0]):
            for s in range(cand_pos.shape[1]):
                ddx = cand_pos[c, s, 0] - others[o, s, 0]
                ddy = cand_pos[c, s, 1] - others[o, s, 1]
                if ddx * ddx + ddy * ddy < r2:  # NaN (not flying) compares False
                    ok[c] = False
                    break
            if not ok[c]:
                break


def _clear_of(cand_pos, others, r_safe, ok=None):
    """(C,) bool: candidates' positions (C, S, 2) keep ≥ r_safe from every trajectory in
    ``others`` (k, S, 2) at every common step instant (NaN = not flying, never a conflict);
    only the candidates still ``ok`` (C,) are checked."""
    ok = np.ones(cand_pos.shape[0], dtype=bool) if ok is None else ok.copy()
    if len(others):
        _clear_kernel(cand_pos, np.ascontiguousarray(others), float(r_safe) ** 2, ok)
    return ok


@njit(cache=True, error_model="numpy")
def _pair_kernel(pa, pb, r2, ok):
    for c in range(pa.shape[0]):
        if not ok[c]:
            continue
        for s in range(pa.shape[1]):
            ddx = pa[c, s, 0] - pb[c, s, 0]
            ddy = pa[c, s, 1] - pb[c, s, 1]
            if ddx * ddx + ddy * ddy < r2:
                ok[c] = False
                break


def _pair_clear(pa, pb, r_safe, ok):
    """(C,) bool: candidate c of two aircraft, (C, S, 2) each, keeps ≥ r_safe at every
    step instant (checked where ``ok``)."""
    ok = ok.copy()
    _pair_kernel(pa, pb, float(r_safe) ** 2, ok)
    return ok


def _scene(start, heading, dest, speed, max_rate):
    n = len(start)
    start = np.asarray(start, float).reshape(n, 2)
    dest = np.asarray(dest, float).reshape(n, 2)
    heading = np.broadcast_to(np.asarray(heading, float), (n,))
    speed = np.broadcast_to(np.asarray(speed, float), (n,))
    max_rate = np.broadcast_to(np.asarray(max_rate, float), (n,))
    return n, start, heading, dest, speed, max_rate


def _plan(method, n, plan_len, pos, rates, arrival, flown, params) -> Plan:
    extra = flown - plan_len
    return Plan(
        True,
        rates,
        pos,
        arrival,
        extra,
        100.0 * float(extra.sum() / plan_len.sum()),
        method,
        params,
    )


def _infeasible(method, n, steps) -> Plan:
    nan = np.full(n, np.nan)
    return Plan(
        False, np.zeros((n, steps)), np.full((n, steps + 1, 2), np.nan), nan, nan, math.inf, method,
        np.full((n, 3), np.nan),
    )  # fmt: skip


def priority_plan(
    start, heading, dest, speed, max_rate, r_safe, steps, dt=1.0, order=None, family=None
) -> Plan:
    """Plan aircraft one by one in ``order`` (default 0..N−1), each the cheapest
    (least flown distance) member of ``family`` clear of those planned before and arriving
    within ``steps``. Shapes: start, dest (N, 2) m; heading, speed, max_rate (N,) or
    scalars. Returns a :class:`Plan` (``feasible`` False when some aircraft has no clear
    member)."""
    n, start, heading, dest, speed, max_rate = _scene(start, heading, dest, speed, max_rate)
    fam = manoeuvre_family() if family is None else np.asarray(family, float)
    order = range(n) if order is None else order
    pos = np.full((n, steps + 1, 2), np.nan)
    rates = np.zeros((n, steps))
    arrival = np.full(n, np.nan)
    flown = np.zeros(n)
    params = np.full((n, 3), np.nan)
    done = []
    for a in order:
        p, r, arr, fl = fly(start[a], heading[a], dest[a], speed[a], max_rate[a], fam, steps, dt)
        ok = _clear_of(p, pos[done], r_safe, ok=np.isfinite(arr))
        if not ok.any():
            return _infeasible("priority", n, steps)
        c = int(np.flatnonzero(ok)[np.argmin(np.where(ok, fl, np.inf)[ok])])
        pos[a], rates[a], arrival[a], flown[a], params[a] = p[c], r[c], arr[c], fl[c], fam[c]
        done.append(a)
    return _plan("priority", n, np.hypot(*(dest - start).T), pos, rates, arrival, flown, params)


def common_plan(
    start, heading, dest, speed, max_rate, r_safe, steps, dt=1.0, family=None, chunk=256
) -> Plan:
    """Every aircraft flies the same member of ``family``; the one of least total flown
    distance keeping every pair ≥ r_safe at every step instant and all arriving (shapes as
    :func:`priority_plan`)."""
    n, start, heading, dest, speed, max_rate = _scene(start, heading, dest, speed, max_rate)
    fam = manoeuvre_family() if family is None else np.asarray(family, float)
    best, best_total = None, math.inf
    for s in range(0, len(fam), chunk):
        sub = fam[s : s + chunk]
        flights = [
            fly(start[a], heading[a], dest[a], speed[a], max_rate[a], sub, steps, dt)
            for a in range(n)
        ]
        ok = np.all([np.isfinite(f[2]) for f in flights], axis=0)
        for a in range(n):
            for b in range(a + 1, n):
                ok &= _pair_clear(flights[a][0], flights[b][0], r_safe, ok)
        total = sum(f[3] for f in flights)
        if ok.any() and total[ok].min() < best_total:
            c = int(np.flatnonzero(ok)[np.argmin(total[ok])])
            best_total = float(total[c])
            best = [f[k][c] for f in flights for k in range(4)], sub[c]
    if best is None:
        return _infeasible("common", n, steps)
    flat, member = best
    pos = np.stack(flat[0::4])
    rates = np.stack(flat[1::4])
    arrival = np.array(flat[2::4])
    flown = np.array(flat[3::4])
    params = np.tile(member, (n, 1))
    return _plan("common", n, np.hypot(*(dest - start).T), pos, rates, arrival, flown, params)


def best_plan(
    start, heading, dest, speed, max_rate, r_safe, steps, dt=1.0, orders=4, seed=0, family=None
) -> Plan:
    """The cheaper of :func:`common_plan` (refined on a finer grid around its best member
    when ``family`` is the default) and :func:`priority_plan` over ``orders`` priority
    orders (identity, reversed, then random permutations from ``seed``)."""
    n = len(start)
    args = (start, heading, dest, speed, max_rate, r_safe, steps, dt)
    best = common_plan(*args, family=family)
    if best.feasible and family is None:  # a finer grid around the best common member
        t0, d, T = best.params[0]
        fine = [
            (a, math.copysign(math.radians(b), d), c)
            for a in np.arange(max(t0 - 8, 0), t0 + 9, 2.0)
            for b in np.arange(max(abs(math.degrees(d)) - 8, 1), abs(math.degrees(d)) + 9, 1.0)
            for c in np.arange(max(T - 16, 2), T + 17, 2.0)
        ]
        finer = common_plan(*args, family=np.array(fine))
        if finer.feasible and finer.extra_pct < best.extra_pct:
            best = finer
    rng = np.random.default_rng(seed)
    perms = [np.arange(n), np.arange(n)[::-1]] + [rng.permutation(n) for _ in range(orders)]
    for order in perms[: max(orders, 1)]:
        p = priority_plan(*args, order=order, family=family)
        if p.feasible and p.extra_pct < best.extra_pct:
            best = p
    return best


def fly_in_world(
    plan: Plan, start, heading, dest, speed, max_rate, r_safe, dt=1.0, after_step=None
) -> dict:
    """Fly ``plan.turn_rates`` in the :class:`~airspace_sim.world.World` and return its
    :meth:`~airspace_sim.world.World.metrics`: the check that a plan is what the world
    flies (its LoS pairs, extra path and arrivals are the world's, not the planner's).

    The aircraft are controlled (RL-agent) aircraft on one-waypoint routes from ``start``
    (N, 2) m on ``heading`` (N,) rad (or one for all) to ``dest`` (N, 2) m at ``speed``
    m/s with the turn limit ``max_rate`` rad/s; tracker ``truth`` and resolver ``none``,
    separation ``r_safe`` m, step ``dt`` s; step ``k`` flies column ``k`` of
    ``plan.turn_rates`` (N, S), until every aircraft has arrived. ``after_step(world)``,
    if given, is called after every step (e.g. to measure the separation independently).
    """
    from airspace_sim.scenarios.schema import (
        AircraftSpec,
        ResolverSpec,
        Scenario,
        Separation,
        TrackerSpec,
    )
    from airspace_sim.world import World

    start, dest = np.asarray(start, float), np.asarray(dest, float)
    heading = np.broadcast_to(np.asarray(heading, float), (len(start),))
    specs = [
        AircraftSpec(
            id=f"a{i}",
            position=(float(start[i, 0]), float(start[i, 1])),
            heading_deg=math.degrees(heading[i]),
            speed=float(speed),
            autopilot="route",
            waypoints=[(float(dest[i, 0]), float(dest[i, 1]))],
            controlled=True,
            max_turn_rate_deg=math.degrees(max_rate),
        )
        for i in range(len(start))
    ]
    steps = plan.turn_rates.shape[1]
    scenario = Scenario(
        name="oracle plan",
        dt=float(dt),
        duration=steps * float(dt),
        separation=Separation(r_safe=float(r_safe)),
        tracker=TrackerSpec(kind="truth"),
        resolver=ResolverSpec(kind="none"),
        aircraft=specs,
    )
    world = World(scenario)
    for k in range(steps):
        if world.done:
            break
        world.step(plan.turn_rates[:, k])
        if after_step is not None:
            after_step(world)
    return world.metrics()
