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
