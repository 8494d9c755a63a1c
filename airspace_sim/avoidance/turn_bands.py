"""Band search that also judges the avoidance heading against intruders that may start turning.

``"bands"`` predicts every intruder straight along its track. On crowded rings and in dense
random traffic most remaining losses are a neighbour's *avoidance* turn (alerted by a third
aircraft) carrying it into an ownship that had judged it straight (``docs/resolvers.md``,
session 5's loss traces): a 3°/s turn at 230 m/s has a 4.4 km radius, so a neighbour 5–12 km
away reaches ``r_safe`` 15–50 s after it begins to turn. The ``"no-worse-turns"`` resume rule
judges the *turn back* against such turns; ``"bands-turns"`` judges the *avoidance* heading.

Two tiers, so that the new test can only choose among headings ``"bands"`` calls clear:

- *clear* (``"bands"``' test): the CPA distance to every intruder flying straight, with the
  ownship turned by ψ at once, is at least ``r_safe·(1 + margin)`` over the look-ahead;
- *turn-clear*: clear, and for every intruder the ownship also stays at least
  ``r_safe·(1 + turn_margin)`` from it when it begins a left or a right turn now at
  ``turn_rate`` for ``turn_s`` and then flies straight (the paths of
  :mod:`~airspace_sim.avoidance.turn_paths`: ``p + (R(ωτ) − I)·J⁻¹·v/ω + R(ωτ)·v·(t − τ)``,
  ``τ = min(t, turn_s)``), sampled every ``step_s`` over ``turn_horizon_s`` (default the
  look-ahead); and, with ``buffer`` > 0, the straight CPA distance is at least
  ``r_safe·(1 + margin + buffer)`` (resolve wider than detect: a heading chosen on the
  detection radius leaves the pair's miss distance on that radius, where track noise or a
  small turn of either aircraft flags it again with 15–25 s to go; ``turn_s = 0`` leaves
  this test alone); and, with ``as_flown``, clear as flown: the ownship turning at its turn
  rate until it reaches ψ, then straight (``"bands"``' ``model_turn`` judgement,
  :func:`~airspace_sim.avoidance.cpa_turning.cpa_min_ratio_turning`, here a preference, not
  a requirement: with 15–25 s to go, the headings a 3°/s turn sweeps through on its way to
  ψ are the ones the band search found blocked).

On each side (``ψ ≤ 0``, ``ψ ≥ 0``, ``ψ < 0``: the columns of ``first_clear``) the first
turn-clear candidate in ``"bands"``' preference order is reported as the side's first clear
one; a side without a turn-clear candidate keeps ``"bands"``' first clear one, and a side
with no clear candidate at all keeps ``"bands"``' best blocked one. So where the turn test
finds nothing, the resolver is ``"bands"`` (same candidates, same choice). With
``strong_side_first`` a side that has only clear (not turn-clear) candidates while the other
side has a turn-clear one is reported as blocked, its best blocked candidate being its first
clear one: a fresh ownship takes the side that is also turn-clear, and an ownship already
committed to the other side flies exactly ``"bands"``' heading there. Detection is
``"bands"``' straight CPA test (the world's prefilter holds).

Distances m, velocities m/s, times s, angles rad CCW positive.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from airspace_sim import registry
from airspace_sim.avoidance.bands import (
    CLEAR_TOLERANCE,
    STRICT_RIGHT,
    at_once_ratios,
    band_choice,
    bands_from_ratio,
    first_clear_from_band,
    wanted_sides,
)
from airspace_sim.avoidance.cpa import kernel_array
from airspace_sim.avoidance.cpa_turning import cpa_min_ratio_turning
from airspace_sim.avoidance.resolvers import BandsResolver, ResolverOutput, _arrays
from airspace_sim.parts import param

#: rad/s: the intruders' turn rate when the caller gives none (the shipped 3°/s limit)
DEFAULT_TURN_RATE = math.radians(3.0)


def sample_times(horizon_s: float, step_s: float) -> np.ndarray:
    """(S,) s: every ``step_s`` from 0, and ``horizon_s`` (the times of
    :func:`~airspace_sim.avoidance.turn_paths.turned_path_min_ratio`)."""
    return np.unique(np.append(np.arange(0.0, horizon_s, step_s), horizon_s))


def first_turn_clear(
    own_velocity,
    rel_position,
    rel_velocity,
    valid,
    candidates,
    clear,
    radius,
    turn_rate,
    turn_s: float,
    horizon_s: float,
    step_s: float = 2.0,
):
    """(N, 3) int: per row, the index of the first candidate with ``ψ ≤ 0``, ``ψ ≥ 0`` and
    ``ψ < 0`` (the columns of ``first_clear``) that is ``clear`` and turn-clear (module
    docstring); −1 where none.

    own_velocity (N, 2) m/s; rel_position, rel_velocity (N, K, 2) m, m/s (intruder minus
    ownship); valid (N, K) bool; candidates (N, C) rad in preference order (NaN: unused);
    clear (N, C) bool; radius (N,) or float m (the turn-clear distance); turn_rate (N,) or
    float rad/s > 0, the intruders' hypothetical turn rate; turn_s s of turning before they
    fly straight; the samples :func:`sample_times` ``(horizon_s, step_s)``.
    """
    vo = np.ascontiguousarray(own_velocity, dtype=float)
    n, k = np.shape(valid)
    return _first_turn_clear_kernel(
        vo,
        np.ascontiguousarray(rel_position, dtype=float).reshape(n, k, 2),
        np.ascontiguousarray(rel_velocity, dtype=float).reshape(n, k, 2),
        np.ascontiguousarray(valid, dtype=np.bool_),
        np.ascontiguousarray(candidates, dtype=float),
        np.ascontiguousarray(clear, dtype=np.bool_),
        kernel_array(radius, (n,)),
        kernel_array(np.maximum(np.asarray(turn_rate, dtype=float), 1e-12), (n,)),
        sample_times(float(horizon_s), float(step_s)),
        float(turn_s),
    )


@njit(cache=True)
def _first_turn_clear_kernel(
    vo, r, v, valid, cand, clear, radius, w, t, turn_s
):  # pragma: no cover - compiled
    """:func:`first_turn_clear` row by row. Each row's turned intruder paths (K, 2, S, 2)
    are computed once; an intruder the ownship cannot reach on any heading
    (``|p(t)| − |v_o|·t > radius`` at every sample) is skipped; candidates are tried in
    order only while a column still lacks one, and the intruder that rejected the last
    candidate is tried first (neighbouring candidates fail on the same one)."""
    n, k = valid.shape
    c_n = cand.shape[1]
    s_n = t.size
    out = np.full((n, 3), -1, dtype=np.int64)
    path = np.empty((k, 2, s_n, 2))
    near = np.empty(k, dtype=np.int64)
    for a in range(n):
        speed = math.sqrt(vo[a, 0] * vo[a, 0] + vo[a, 1] * vo[a, 1])
        rad2 = radius[a] * radius[a]
        n_near = 0
        for b in range(k):
            if not valid[a, b]:
                continue
            vx = v[a, b, 0] + vo[a, 0]
            vy = v[a, b, 1] + vo[a, 1]
            reach = False
            for m in range(2):
                ww = w[a] if m == 0 else -w[a]
                for i in range(s_n):
                    ti = t[i]
                    tau = min(ti, turn_s)
                    ang = ww * tau
                    c, s = math.cos(ang), math.sin(ang)
                    rest = ti - tau
                    px = r[a, b, 0] + (s * vx - (1.0 - c) * vy) / ww + (c * vx - s * vy) * rest
                    py = r[a, b, 1] + (s * vy + (1.0 - c) * vx) / ww + (s * vx + c * vy) * rest
                    path[b, m, i, 0] = px
                    path[b, m, i, 1] = py
                    if math.sqrt(px * px + py * py) - speed * ti <= radius[a]:
                        reach = True
            if reach:
                near[n_near] = b
                n_near += 1
        last = 0  # position in near[] of the intruder that rejected the last candidate
        for j in range(c_n):
            psi = cand[a, j]
            if not clear[a, j] or psi != psi:
                continue
            need = (
                (psi <= 0.0 and out[a, 0] < 0)
                or (psi >= 0.0 and out[a, 1] < 0)
                or (psi < 0.0 and out[a, 2] < 0)
            )
            if not need:
                if out[a, 0] >= 0 and out[a, 1] >= 0 and out[a, 2] >= 0:
                    break
                continue
            cp, sp = math.cos(psi), math.sin(psi)
            ovx = cp * vo[a, 0] - sp * vo[a, 1]
            ovy = sp * vo[a, 0] + cp * vo[a, 1]
            ok = True
            for q in range(n_near):
                idx = (last + q) % n_near
                b = near[idx]
                for m in range(2):
                    for i in range(s_n):
                        ex = path[b, m, i, 0] - ovx * t[i]
                        ey = path[b, m, i, 1] - ovy * t[i]
                        if ex * ex + ey * ey < rad2:
                            ok = False
                            break
                    if not ok:
                        break
                if not ok:
                    last = idx
                    break
            if ok:
                if psi <= 0.0 and out[a, 0] < 0:
                    out[a, 0] = j
                if psi >= 0.0 and out[a, 1] < 0:
                    out[a, 1] = j
                if psi < 0.0 and out[a, 2] < 0:
                    out[a, 2] = j
    return out


def tiered_sides(first_clear, first_turn, best_blocked, strong_side_first=False):
    """``(first_clear (N, 3), best_blocked (N, 2))`` of the two-tier search (module
    docstring) from ``"bands"``' ``first_clear`` (N, 3) and ``best_blocked`` (N, 2) and
    :func:`first_turn_clear`'s ``first_turn`` (N, 3) (all int indices, −1: none)."""
    first = np.where(first_turn >= 0, first_turn, first_clear)
    best = best_blocked.copy()
    if strong_side_first:
        strong = first_turn[:, :2] >= 0  # (N, 2): (ψ ≤ 0, ψ ≥ 0) has a turn-clear candidate
        for col, other in ((0, 1), (1, 0)):
            weak_only = ~strong[:, col] & strong[:, other] & (first_clear[:, col] >= 0)
            best[:, col] = np.where(weak_only, first_clear[:, col], best[:, col])
            first[:, col] = np.where(weak_only, -1, first[:, col])
            if col == 0:  # the strict right side goes with the right side
                strict = weak_only & (first_turn[:, STRICT_RIGHT] < 0)
                first[:, STRICT_RIGHT] = np.where(strict, -1, first[:, STRICT_RIGHT])
    return first, best


@registry.register("resolver", "bands-turns")
class TurnAwareBandsResolver(BandsResolver):
    """``"bands"`` preferring, on each side, headings that stay clear of intruders that may
    start turning (module docstring)."""

    @dataclass(frozen=True)
    class Params(BandsResolver.Params):
        turn_s: float = param(
            30.0, unit="s", doc="how long a hypothetical intruder turn lasts", ge=0, le=3600.0
        )
        turn_margin: float = param(
            0.0,
            doc="turn-clear distance r_safe·(1 + turn_margin) from the turning paths",
            ge=0,
            le=10.0,
        )
        turn_horizon_s: float | None = param(
            None,
            unit="s",
            doc="judge the turning paths this far ahead (unset: the look-ahead)",
            gt=0,
            le=3600.0,
        )
        step_s: float = param(2.0, unit="s", doc="sample step of the turning paths", gt=0, le=60.0)
        buffer: float = param(
            0.0,
            doc="turn-clear also needs the straight CPA distance ≥ r_safe·(1 + margin + "
            "buffer) (a wider resolution than detection radius)",
            ge=0,
            le=10.0,
        )
        as_flown: bool = param(
            False,
            doc="turn-clear also needs the candidate clear as flown: the ownship turning "
            "at its turn rate until ψ is reached, then straight",
        )
        strong_side_first: bool = param(
            False, doc="a fresh ownship takes the side with a turn-clear heading"
        )

    def resolve(
        self,
        own_velocity,
        rel_position,
        rel_velocity,
        valid,
        max_heading_change,
        *,
        mode_predictions=None,
        turn_rate=None,
        committed_side=None,
    ):
        p = self.params
        vo, r, v, valid, mx = _arrays(
            own_velocity, rel_position, rel_velocity, valid, max_heading_change
        )
        n = vo.shape[0]
        radius, cand, usable, ratio, conflict = at_once_ratios(vo, r, v, valid, mx, p)
        band, first, best = bands_from_ratio(cand, ratio, usable, wanted_sides(committed_side, n))
        rate = DEFAULT_TURN_RATE if turn_rate is None else turn_rate
        horizon = p.lookahead_s if p.turn_horizon_s is None else p.turn_horizon_s
        turn = np.full((n, 3), -1, dtype=np.int64)
        rows = np.flatnonzero(conflict)  # the choice of a clear ownship is ψ = 0 either way
        # the wide straight test: one common radius, so the ratio scales with it
        wide = band & (ratio >= (1.0 + p.margin + p.buffer) / (1.0 + p.margin) - CLEAR_TOLERANCE)
        if p.as_flown and rows.size and r.shape[1] > 0:
            rate_rows = np.broadcast_to(np.asarray(rate, dtype=float), (n,))[rows]
            flown = cpa_min_ratio_turning(
                vo[rows],
                r[rows],
                v[rows],
                valid[rows],
                np.where(usable[rows], cand[rows], 0.0),
                radius,
                p.lookahead_s,
                rate_rows,
            )
            wide[rows] &= flown >= 1.0 - CLEAR_TOLERANCE
        if p.turn_s == 0.0 or r.shape[1] == 0:
            turn[rows] = first_clear_from_band(cand[rows], wide[rows])
        elif rows.size:
            rate_rows = np.broadcast_to(np.asarray(rate, dtype=float), (n,))[rows]
            turn[rows] = first_turn_clear(
                vo[rows],
                r[rows],
                v[rows],
                valid[rows],
                cand[rows],
                wide[rows],
                p.r_safe * (1.0 + p.turn_margin),
                rate_rows,
                p.turn_s,
                horizon,
                p.step_s,
            )
        first, best = tiered_sides(first, turn, best, p.strong_side_first)
        idx = np.arange(n)
        choice = band_choice(
            first, best, lambda i: np.where(i >= 0, ratio[idx, np.maximum(i, 0)], -np.inf)
        )
        return ResolverOutput(
            cand[idx, choice],
            conflict,
            cand,
            band,
            min_ratio=ratio,
            first_clear=first,
            best_blocked=best,
        )
