"""An airspace_sim plugin written only against the documented protocols (docs/plugins.md).

Two parts:

- resolver ``"example-right"``: when some intruder's closest point of approach (CPA) over
  the look-ahead is nearer than ``r_safe·(1 + margin)``, turn right by ``turn_deg`` (at
  most the allowed heading change); otherwise keep the heading.
- autopilot ``"orbit"``: circles at a constant turn rate ``turn_rate_deg`` (a holding
  pattern), with no plan to resume.

Units: metres, seconds, radians (degrees only where a name says ``_deg``); angles CCW from
east, so a negative heading change is a right turn.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from airspace_sim.avoidance.resolvers import ResolverOutput
from airspace_sim.parts import Autopilot, Resolver, param
from airspace_sim.registry import register


@register("resolver", "example-right")
class TurnRightResolver(Resolver):
    """Turn right by a fixed angle while a CPA conflict is predicted (see the module)."""

    @dataclass(frozen=True)
    class Params:
        # r_safe, lookahead_s and margin are filled from the scenario (separation.r_safe,
        # resolver.lookahead, resolver.margin); resolver.params may override them
        r_safe: float = param(3000.0, unit="m", doc="safety radius", gt=0, le=1e6)
        lookahead_s: float = param(120.0, unit="s", doc="CPA look-ahead", gt=0, le=3600)
        margin: float = param(0.1, doc="extra fraction of r_safe kept clear", ge=0, le=10)
        turn_deg: float = param(30.0, unit="deg", doc="right turn per conflict", gt=0, le=180)

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
    ):
        """own_velocity (N, 2) m/s; rel_position, rel_velocity (N, K, 2) m, m/s; valid
        (N, K) bool; max_heading_change (N,) rad → heading_change (N,) rad, conflict (N,)."""
        p = self.params
        r = np.asarray(rel_position, dtype=float)
        v = np.asarray(rel_velocity, dtype=float)
        vv = np.einsum("nki,nki->nk", v, v)
        rv = np.einsum("nki,nki->nk", r, v)
        t = np.clip(np.where(vv > 0, -rv / np.where(vv > 0, vv, 1.0), 0.0), 0.0, p.lookahead_s)
        d = r + v * t[..., None]
        near = np.hypot(d[..., 0], d[..., 1]) < p.r_safe * (1.0 + p.margin)
        conflict = (near & np.asarray(valid, dtype=bool)).any(axis=1)
        turn = np.minimum(np.radians(p.turn_deg), np.asarray(max_heading_change, dtype=float))
        return ResolverOutput(np.where(conflict, -turn, 0.0), conflict)


@register("autopilot", "orbit")
class OrbitAutopilot(Autopilot):
    """Circles at ``turn_rate_deg`` (clipped to each aircraft's limit)."""

    @dataclass(frozen=True)
    class Params:
        turn_rate_deg: float = param(1.5, unit="deg/s", doc="CCW positive", ge=-180, le=180)

    def __init__(self, members, specs, context, params):
        self.members = np.asarray(members, dtype=np.int64)
        self.rate = np.radians(params.turn_rate_deg)

    def turn_rate(self, state):
        lim = state.max_turn_rate[self.members]
        return np.clip(np.full(self.members.size, self.rate), -lim, lim)

    def desired_heading(self, state):
        return np.full(self.members.size, np.nan)  # nothing to resume toward

    def after_step(self, state):
        return np.zeros(self.members.size, dtype=bool)  # never finishes

    def progress(self, state):
        return np.full(self.members.size, np.nan)  # no plan
