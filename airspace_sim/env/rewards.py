"""Reward terms of the PettingZoo env, each weighted by a configurable factor.

``reward = Σ weight[term] · value[term]``; each weighted term is reported per agent in
``infos[agent]["reward_terms"]``. Term values per step (before weighting):

=================  =========================================================================
term               value
=================  =========================================================================
``los``            -1 while the ownship is within r_safe of any aircraft (loss of separation)
``nmac``           -1 on the step of a near mid-air collision (the episode ends for the agent)
``conflict``       -1 while the ownship's resolver raises a conflict alert
``heading_change`` -(commanded turn rate / turn-rate limit)²
``deviation``      -min(|cross-track error| / r_safe, 1)   (0 with no route)
``progress``       distance to the waypoint gained this step / (v_ref · dt), about +1 at
                   full speed straight at it (0 with no route)
``arrival``        +1 on reaching the last waypoint (the episode ends for the agent)
=================  =========================================================================
"""

from __future__ import annotations

from airspace_sim.errors import UserError

DEFAULT_WEIGHTS = {
    "los": 1.0,
    "nmac": 10.0,
    "conflict": 0.0,
    "heading_change": 0.05,
    "deviation": 0.02,
    "progress": 0.05,
    "arrival": 1.0,
}


def merge_weights(weights: dict | None) -> dict[str, float]:
    """Default weights updated with ``weights``; :class:`UserError` on unknown terms."""
    out = dict(DEFAULT_WEIGHTS)
    for name, w in (weights or {}).items():
        if name not in DEFAULT_WEIGHTS:
            raise UserError(f"reward: unknown term {name!r} (known: {', '.join(DEFAULT_WEIGHTS)})")
        try:
            w = float(w)
        except (TypeError, ValueError):
            raise UserError(f"reward.{name}: expected a number, got {w!r}") from None
        if w != w or w in (float("inf"), float("-inf")):
            raise UserError(f"reward.{name}: expected a finite number, got {w!r}")
        out[name] = w
    return out


def weighted_terms(weights: dict[str, float], values: dict[str, float]) -> dict[str, float]:
    """``{term: weight · value}`` for every known term (missing values count as 0)."""
    return {name: float(weights[name] * values.get(name, 0.0)) for name in DEFAULT_WEIGHTS}
