"""Reward terms of the PettingZoo env: what each pays, and why no collision ever pays.

``reward = Σ weight[term] · value[term]``; each weighted term is reported per agent in
``infos[agent]["reward_terms"]``. Values per step, before weighting (L = the agent's planned
route length in metres, v its speed, dt the step):

=================  =========================================================================
term               value per step
=================  =========================================================================
``los``            -severity of the worst intrusion into r_safe this step:
                   ``(r_safe - d) / (r_safe - d_nmac)`` clipped to [0, 1], d the distance to
                   the nearest aircraft (0 outside r_safe, 1 at the NMAC distance)
``nmac``           on the step of a near mid-air collision only (the agent's episode ends):
                   ``-(1 + (T - t + 1) · c_max / w_nmac)``, see below
``conflict``       -1 while the ownship's resolver raises a conflict alert
``heading_change`` -(commanded turn rate / turn-rate limit)²
``progress``       route length gained this step / L (sums to 1 over a whole route: a
                   potential-based term, it does not change which policy is optimal)
``path``           -(metres flown - route length gained) / L (sums to minus the extra path
                   as a fraction of the route; the same units as ``progress``); ≥ -2 v dt / L,
                   positive only on a step whose waypoint capture (the route autopilot's
                   "abeam" rule) shortens the remaining route by more than a step's travel
``arrival``        +1 on reaching the last waypoint (the agent's episode ends)
=================  =========================================================================

Agents without a route (Markov or straight autopilots) get 0 for ``progress``, ``path`` and
``arrival``.

**No collision pays.** Every term but ``nmac`` and the bonuses (``progress`` gained,
``arrival``) is a penalty bounded per step, so every step's reward without an NMAC is at
least ``-c_max``, ``c_max = w_los + w_conflict + w_heading_change + (w_progress + 2 w_path)
· v dt / L`` (progress loses at most one step's travel, the path term at most two). An NMAC
on step ``t`` (1-based) of a ``T``-step episode (``max_cycles``) costs ``w_nmac + (T - t +
1) · c_max``: more than the worst that step and every later one could cost an agent that
does not collide, even one at the NMAC distance, in loss of separation, every remaining
step. So a policy that collides at ``t`` earns less than any policy with the same history
that avoids from ``t`` on (the colliding step's own gain is at most ``w_progress · v dt / L``
< ``w_nmac``), whatever the weights (non-negative, ``w_nmac`` > 0).
``tests/test_env_rewards.py`` checks the bound on every step and the order of fixed
policies (straight, random, built-in resolver) on rings.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from airspace_sim.errors import UserError

DEFAULT_WEIGHTS = {
    "los": 0.5,
    "nmac": 10.0,
    "conflict": 0.0,
    "heading_change": 0.002,
    "progress": 1.0,
    "path": 1.0,
    "arrival": 0.5,
}


def merge_weights(weights: dict | None) -> dict[str, float]:
    """Default weights updated with ``weights``; :class:`UserError` on unknown terms or on
    weights that are not finite and non-negative (a negative weight would pay for the
    behaviour the term penalises)."""
    if weights is not None and not isinstance(weights, dict):
        raise UserError(f"reward: expected a dict of term weights, got {weights!r}")
    out = dict(DEFAULT_WEIGHTS)
    for name, w in (weights or {}).items():
        if name not in DEFAULT_WEIGHTS:
            raise UserError(f"reward: unknown term {name!r} (known: {', '.join(DEFAULT_WEIGHTS)})")
        if isinstance(w, bool):
            raise UserError(f"reward.{name}: expected a number, got {w!r}")
        try:
            w = float(w)
        except (TypeError, ValueError):
            raise UserError(f"reward.{name}: expected a number, got {w!r}") from None
        if not math.isfinite(w) or w < 0:
            raise UserError(f"reward.{name}: expected a finite non-negative number, got {w!r}")
        if name == "nmac" and w == 0:
            raise UserError(
                "reward.nmac: expected a positive number (it makes avoiding pay), got 0"
            )
        out[name] = w
    return out


def step_bound(weights: dict[str, float], travel_fraction) -> np.ndarray:
    """``c_max`` per agent: the largest penalty (negative reward) of one step without an
    NMAC.

    travel_fraction : (A,) ``v · dt / L`` of each agent (0 without a route).
    """
    w = weights
    fixed = w["los"] + w["conflict"] + w["heading_change"]
    return fixed + (w["progress"] + 2.0 * w["path"]) * np.asarray(travel_fraction, float)


def nmac_value(weights: dict[str, float], steps_left, c_max) -> np.ndarray:
    """The ``nmac`` term's value (before weighting) on the step of an NMAC, with
    ``steps_left`` = T - t + 1 steps of the episode (this one included):
    ``-(1 + steps_left · c_max / w_nmac)``, so that weighted it costs ``w_nmac +
    steps_left · c_max``."""
    steps_left = np.maximum(np.asarray(steps_left, float), 0.0)
    return -(1.0 + steps_left * c_max / weights["nmac"])


def severity(distance, r_safe: float, nmac: float) -> np.ndarray:
    """Intrusion severity in [0, 1]: 0 at or outside r_safe, 1 at or inside the NMAC
    distance, linear between. distance : (A,) m to the nearest aircraft (inf: none)."""
    d = np.asarray(distance, float)
    return np.clip((r_safe - d) / (r_safe - nmac), 0.0, 1.0)


def weighted_terms(weights: dict[str, float], values: dict[str, float]) -> dict[str, float]:
    """``{term: weight · value}`` for every known term (missing values count as 0)."""
    return {name: float(weights[name] * values.get(name, 0.0)) for name in DEFAULT_WEIGHTS}


#: the weighted terms' columns, in :data:`DEFAULT_WEIGHTS` order (:func:`step_terms`)
TERMS = tuple(DEFAULT_WEIGHTS)


@njit(cache=True)
def step_terms(
    idx,
    weights,
    positions,
    los_i,
    los_j,
    r_safe,
    nmac_distance,
    nmac,
    conflict,
    turns,
    turn_rates,
    max_rate,
    speeds,
    dt,
    covered,
    covered_before,
    planned,
    done,
    active,
    steps_left,
    out,
    nearest,
    ended,
):  # pragma: no cover - compiled
    """Every agent's weighted terms of one step, in one pass (the env's step reads them).

    idx (A,) int: the agents' aircraft indices into the (N,) world arrays; ``weights`` (7,)
    in :data:`TERMS` order; ``positions`` (N, 2) m; ``los_i``, ``los_j`` (L,) the pairs in
    loss of separation; ``r_safe``, ``nmac_distance`` m; ``nmac``, ``conflict``, ``done``
    (finished route), ``active`` (N,) bool; ``turns`` (N,) bool (a turn-rate limit > 0),
    ``turn_rates`` and ``max_rate`` rad/s, ``speeds`` m/s, ``dt`` s; ``covered`` and
    ``covered_before`` (N,) m of route covered after and before the step, ``planned``
    (N,) m route length (0: no route); ``steps_left`` T - t + 1.

    Writes ``out`` (A, 7) the weighted terms (the values of :func:`severity`,
    :func:`step_bound` and :func:`nmac_value` and the module docstring's table, each
    computed as their numpy expressions compute it, so bit for bit the same),
    ``nearest`` (A,) m to the nearest aircraft in loss of separation (inf: none) and
    ``ended`` (A,) bool (NMAC, arrived or out of play). The row sums are left to numpy
    (its pairwise summation order).
    """
    n = positions.shape[0]
    near = np.full(n, np.inf)
    for p in range(los_i.size):
        i, j = los_i[p], los_j[p]
        d = math.hypot(positions[i, 0] - positions[j, 0], positions[i, 1] - positions[j, 1])
        if d < near[i]:
            near[i] = d
        if d < near[j]:
            near[j] = d
    w_los, w_nmac, w_conflict, w_heading = weights[0], weights[1], weights[2], weights[3]
    w_progress, w_path, w_arrival = weights[4], weights[5], weights[6]
    fixed = w_los + w_conflict + w_heading
    any_nmac = False
    for k in range(idx.size):
        any_nmac = any_nmac or nmac[idx[k]]
    left = max(float(steps_left), 0.0)
    span = r_safe - nmac_distance
    for k in range(idx.size):
        i = idx[k]
        L = planned[i]
        has_route = L > 0
        Ls = L if has_route else 1.0
        travel = speeds[i] * dt / Ls if has_route else 0.0
        turn = turn_rates[i] / max_rate[i] if turns[i] else 0.0
        d = near[i]
        nearest[k] = d
        sev = (r_safe - d) / span
        if sev < 0.0:  # np.clip(sev, 0.0, 1.0) as numpy clips to scalar bounds
            sev = 0.0
        elif sev > 1.0:
            sev = 1.0
        out[k, 0] = w_los * -sev
        value = 0.0
        if any_nmac and nmac[i]:
            c_max = fixed + (w_progress + 2.0 * w_path) * travel
            value = -(1.0 + left * c_max / w_nmac)
        out[k, 1] = w_nmac * value
        out[k, 2] = w_conflict * -(1.0 if conflict[i] else 0.0)
        out[k, 3] = w_heading * -(turn * turn)
        along = (covered[i] - covered_before[i]) / Ls
        out[k, 4] = w_progress * (along if has_route else 0.0)
        out[k, 5] = w_path * (along - travel if has_route else 0.0)
        out[k, 6] = w_arrival * (1.0 if done[i] else 0.0)
        ended[k] = nmac[i] or done[i] or not active[i]
