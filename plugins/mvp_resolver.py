"""Resolver plugin ``"mvp"``: BlueSky's Modified Voltage Potential, heading only (a peer baseline).

MVP (Hoekstra et al. 2002; BlueSky's default resolution method) pushes each ownship's
velocity away from every intruder's closest point of approach (CPA) just far enough that the
CPA distance becomes ``r_safe·(1 + margin)``, and sums the pushes over intruders. For a
conflict pair with relative position ``r = p_int − p_own`` and velocity ``v = v_int − v_own``,
CPA time ``t = −r·v / |v|²`` and CPA displacement ``d = r + v t``, the push is

    Δv_own = −(r_safe (1 + margin) − |d|) / t · d̂

(an ownship flying ``v_own + Δv_own`` has ``d' = d + (r_safe(1+margin) − |d|) d̂``). Fixed-wing
aircraft cannot change speed much, so — as anchors.md says a fair peer must be — this version
keeps the speed and turns toward the heading of ``v_own + ΣΔv``, clipped to the turn limit.
Exactly head-on (``|d|`` ≈ 0) it turns right, as the rules of the air say.

A pair is in conflict when ``0 < t < lookahead_s`` and ``|d| < r_safe (1 + margin)``, or when
it is already closer than ``r_safe`` and still closing. Use with ``[resolver] kind = "mvp"``;
shipped as ``airspace_sim_plugins.mvp_resolver`` through the package's own entry point.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from airspace_sim.avoidance.resolvers import ResolverOutput
from airspace_sim.geometry import wrap_angle
from airspace_sim.parts import Resolver, param
from airspace_sim.registry import register


@register("resolver", "mvp")
class MVPResolver(Resolver):
    """Heading-only Modified Voltage Potential over all intruders (see the module docstring).

    Constructed as ``MVPResolver(MVPResolver.Params(...))``; the loader fills ``r_safe``,
    ``lookahead_s`` and ``margin`` from the scenario.
    """

    @dataclass(frozen=True)
    class Params:
        r_safe: float = param(3000.0, unit="m", doc="safety radius", gt=0, le=1e6)
        lookahead_s: float = param(120.0, unit="s", doc="conflict look-ahead", gt=0, le=3600)
        margin: float = param(0.1, doc="extra fraction of r_safe kept clear", ge=0, le=10)
        min_time: float = param(
            1.0, unit="s", doc="floor of the CPA time in the push (no division by ~0)", gt=0
        )

    def pair_conflicts(self, rel_position, rel_velocity, valid):
        """CPA time (N, K), displacement (N, K, 2) and conflict flags (N, K)."""
        r = np.asarray(rel_position, dtype=float)
        v = np.asarray(rel_velocity, dtype=float)
        p = self.params
        vv = np.einsum("...i,...i->...", v, v)
        rv = np.einsum("...i,...i->...", r, v)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(vv > 1e-12, -rv / vv, 0.0)
        d = r + v * t[..., None]
        dist_cpa = np.hypot(d[..., 0], d[..., 1])
        dist_now = np.hypot(r[..., 0], r[..., 1])
        r_clear = p.r_safe * (1.0 + p.margin)
        closing = t > 0
        conflict = (
            valid & closing & (((t < p.lookahead_s) & (dist_cpa < r_clear)) | (dist_now < p.r_safe))
        )
        return t, d, conflict

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
        vo = np.asarray(own_velocity, dtype=float).reshape(-1, 2)
        n = vo.shape[0]
        r = np.asarray(rel_position, dtype=float).reshape(n, -1, 2)
        v = np.asarray(rel_velocity, dtype=float).reshape(n, -1, 2)
        valid = np.asarray(valid, dtype=bool).reshape(n, -1)
        mx = np.broadcast_to(np.asarray(max_heading_change, dtype=float), (n,))
        t, d, pair = self.pair_conflicts(r, v, valid)
        dist = np.hypot(d[..., 0], d[..., 1])
        # Direction of the CPA displacement; head-on (|d| ~ 0): left of the line of sight,
        # so that the push (−d̂) turns the ownship right.
        r_hat = r / np.maximum(np.hypot(r[..., 0], r[..., 1]), 1e-9)[..., None]
        left = np.stack([-r_hat[..., 1], r_hat[..., 0]], axis=-1)
        d_hat = np.where((dist > 1.0)[..., None], d / np.maximum(dist, 1e-9)[..., None], left)
        p = self.params
        intrusion = np.maximum(p.r_safe * (1.0 + p.margin) - dist, 0.0)
        push = -(intrusion / np.maximum(t, p.min_time))[..., None] * d_hat
        dv = np.where(pair[..., None], push, 0.0).sum(axis=1)
        new_v = vo + dv
        heading_change = np.arctan2(new_v[:, 1], new_v[:, 0]) - np.arctan2(vo[:, 1], vo[:, 0])
        heading_change = wrap_angle(heading_change)
        conflict = pair.any(axis=1)
        heading_change = np.where(conflict, np.clip(heading_change, -mx, mx), 0.0)
        return ResolverOutput(heading_change, conflict)
