"""Conflict detection and avoidance (CDA) for every ownship at once.

Each step, for every active ownship that avoids (``AircraftSpec.avoid``) or is an RL agent
(advice is part of its observation):

1. its tracks are gathered into padded arrays ``(n_own, K, ·)`` (intruder slot ``k`` of
   ownship ``o``; ``valid`` marks used slots) with ``rel_position = track position − own
   true position`` and ``rel_velocity = track velocity − own true velocity`` (world frame);
2. the scenario's resolver (``registry.get("resolver", scenario.resolver.kind)``) returns
   ``heading_change`` (``|·| ≤ max_turn_rate·dt``) and ``conflict``;
3. the world turns an avoiding ownship that is in conflict by ``heading_change`` this step;
   otherwise it flies its autopilot, but a turn back toward the autopilot's desired heading
   (resuming the route once clear) is made only if that turn is itself clear
   (:func:`airspace_sim.avoidance.resume_heading_change`, same CPA test and margin as the
   bands), else the heading is held. With resolver ``"none"`` nothing is overridden.

Resolver keyword arguments are built from the scenario (``r_safe`` from
``separation.r_safe``, ``lookahead_s`` from ``resolver.lookahead``, ``margin``, ``dt`` = the
world step) for those the resolver's constructor accepts, then ``resolver.params`` on top.
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass

import numpy as np

from airspace_sim import registry


def build_resolver(scenario, dt: float):
    """The scenario's resolver object, with the keyword arguments it accepts."""
    factory = registry.get("resolver", scenario.resolver.kind)
    offered = dict(r_safe=scenario.separation.r_safe, lookahead_s=scenario.resolver.lookahead,
                   margin=scenario.resolver.margin, dt=dt)
    try:
        params = inspect.signature(factory).parameters
        takes_any = any(p.kind is p.VAR_KEYWORD for p in params.values())
    except (TypeError, ValueError):
        params, takes_any = {}, True
    extra = dict(scenario.resolver.params)
    # Most specific first; a factory taking **params may forward to a constructor that
    # rejects some of them, so retry with fewer.
    tries = (("r_safe", "lookahead_s", "margin", "dt"), ("r_safe", "lookahead_s", "margin"),
             ("r_safe", "lookahead_s"), ("r_safe",), ())
    last = None
    for names in tries:
        kwargs = {k: offered[k] for k in names if takes_any or k in params}
        kwargs.update(extra)
        try:
            return factory(**kwargs)
        except TypeError as exc:
            if "keyword" not in str(exc):
                raise
            last = exc
    raise last


@dataclass
class Encounters:
    """Tracks of the resolver-running ownships as padded arrays.

    owners : (n_own,) aircraft index of each row; rows : (n_own, K) track row or −1;
    rel_position, rel_velocity : (n_own, K, 2) m, m/s; valid : (n_own, K) bool.
    """

    owners: np.ndarray
    rows: np.ndarray
    rel_position: np.ndarray
    rel_velocity: np.ndarray
    valid: np.ndarray

    def subset(self, mask: np.ndarray) -> "Encounters":
        return Encounters(self.owners[mask], self.rows[mask], self.rel_position[mask],
                          self.rel_velocity[mask], self.valid[mask])


def gather(track_owner, track_x, positions, velocities, runs) -> Encounters:
    """Padded per-ownship arrays of the tracks whose owner has ``runs[owner]`` True."""
    sel = np.flatnonzero(runs[track_owner]) if track_owner.size else np.zeros(0, np.int64)
    if sel.size == 0:
        z = np.zeros((0, 0, 2))
        return Encounters(np.zeros(0, np.int64), np.zeros((0, 0), np.int64), z, z.copy(),
                          np.zeros((0, 0), bool))
    own = track_owner[sel]
    order = np.argsort(own, kind="stable")
    sel, own = sel[order], own[order]
    owners, start, counts = np.unique(own, return_index=True, return_counts=True)
    K = int(counts.max())
    local = np.repeat(np.arange(owners.size), counts)
    slot = np.arange(sel.size) - np.repeat(start, counts)
    rows = np.full((owners.size, K), -1, dtype=np.int64)
    rows[local, slot] = sel
    x = track_x[sel]
    rp = np.zeros((owners.size, K, 2))
    rv = np.zeros((owners.size, K, 2))
    rp[local, slot] = x[:, (0, 2)] - positions[own]
    rv[local, slot] = x[:, (1, 3)] - velocities[own]
    return Encounters(owners, rows, rp, rv, rows >= 0)


class Avoidance:
    """The scenario's resolver applied to gathered encounters."""

    def __init__(self, scenario, dt: float):
        self.kind = scenario.resolver.kind
        self.resolver = build_resolver(scenario, dt)
        self.r_safe = float(scenario.separation.r_safe)
        self.lookahead = float(scenario.resolver.lookahead)
        self.margin = float(scenario.resolver.margin)
        p = scenario.resolver.params
        self.r_safe = float(p.get("r_safe", self.r_safe))
        self.lookahead = float(p.get("lookahead_s", self.lookahead))
        self.margin = float(p.get("margin", self.margin))
        #: whether advice overrides the autopilot ("none" only reports conflicts)
        self.overrides = self.kind != "none"

    def advise(self, enc: Encounters, velocities, max_heading_change, n: int):
        """(advice (n,) rad, conflict (n,) bool) for all aircraft (0 / False off ``enc``)."""
        advice = np.zeros(n)
        conflict = np.zeros(n, dtype=bool)
        if enc.owners.size:
            out = self.resolver.resolve(velocities[enc.owners], enc.rel_position,
                                        enc.rel_velocity, enc.valid,
                                        max_heading_change[enc.owners])
            advice[enc.owners] = np.asarray(out.heading_change, dtype=float)
            conflict[enc.owners] = np.asarray(out.conflict, dtype=bool)
        return advice, conflict

    def resume_clear(self, enc: Encounters, velocities, turn, max_heading_change) -> np.ndarray:
        """For the ownships of ``enc``: is the heading change ``turn`` (n_own,) clear?"""
        from airspace_sim.avoidance import resume_heading_change

        if enc.owners.size == 0:
            return np.zeros(0, dtype=bool)
        vo = velocities[enc.owners]
        desired = np.arctan2(vo[:, 1], vo[:, 0]) + turn
        _, clear = resume_heading_change(vo, desired, enc.rel_position, enc.rel_velocity,
                                         enc.valid, max_heading_change[enc.owners],
                                         r_safe=self.r_safe, lookahead_s=self.lookahead,
                                         margin=self.margin)
        return np.asarray(clear, dtype=bool)
