"""Conflict detection and avoidance (CDA) for every ownship at once.

Each step, for every active ownship that avoids (``AircraftSpec.avoid``) or is an RL agent
(advice is part of its observation):

1. its tracks are gathered into padded arrays ``(n_own, K, ·)`` (intruder slot ``k`` of
   ownship ``o``; ``valid`` marks used slots) with ``rel_position = track position − own
   true position`` and ``rel_velocity = track velocity − own true velocity`` (world frame);
2. the scenario's resolver (``registry.get("resolver", scenario.resolver.kind)``) searches
   ``±resolver.search_deg`` for a clear heading and returns ``heading_change`` and
   ``conflict``; only tracks older than ``resolver.confirm_s`` are used (a two-point track's
   first velocities are poor). The turn side is committed for the whole conflict episode
   (``resolver.turn_preference``, default "right", :class:`Avoidance`), which stops
   ownships flip-flopping on noisy estimates;
3. an avoiding ownship in conflict turns toward that heading by at most
   ``max_turn_rate·dt`` this step; otherwise it flies its autopilot, but a turn back toward
   the autopilot's desired heading (resuming the route once clear) is made only if that
   turn keeps clear by ``r_safe·(1 + margin + resume_margin)`` over the look-ahead
   (:func:`airspace_sim.avoidance.resume_heading_change`), else the heading is held. With
   ``resume_decay_s`` set, ``resume_margin`` shrinks linearly to 0 over that many seconds
   off the route (``World.off_route_s``). With resolver ``"none"`` nothing is overridden
   (conflicts are still reported).

Why these defaults: on converging rings (32 aircraft, IMM tracks from σ = 50 m) the plain
nearest-clear choice within the one-step turn limit gave about 20 losses of separation;
fresh tracks (velocity errors up to 80 m/s) and left/right flip-flopping caused most of
them. On rings of 64 (seeds 0–4) the remaining losses came from aircraft turning back
toward their route into traffic or chasing a receding clear heading late in the
encounter: with ``resume_margin`` 0.2 seeds 0–4 gave 0, 1, 3, 4, 4 losses; 0.5 and 1.0 one
loss on some of seeds 5–9; 1.5 none on seeds 0–9 (min separation ≥ 3350 m; extra path
about 40% instead of 20–27%, mean avoidance turn 45° instead of ~200°). Rings of 100: 1
loss in seeds 0–4; of 200: 5, 1, 8 losses on seeds 0–2 (0.2 gave 25, 31), no NMAC. With
the return to the right side (:class:`Avoidance`): rings of 64 still 0 on seeds 0–9, of 100
0 on seeds 0–4, of 200 3, 0, 1 on seeds 0–2 (min separation 1747, 3137, 2689 m), no NMAC;
``dense_random`` with its then 120 s look-ahead, seeds 0–4: 13, 2, 19, 17, 14 losses (18, 6,
13, 20, 19 before). See ``tests/test_world_ring.py``.

Random traffic is the opposite regime: it never disperses, so an aircraft holding its
heading until the wide resume clearance opened could wait for ever. On ``dense_random``
(60 aircraft, 100 km sector, 600 s) with look-ahead 120 s and no decay, seeds 0–15 gave
272 losses, 8 NMAC, extra path 969% and 43 of 60 aircraft still flying at the end, many
far outside the sector. Over 8 seeds: ``resume_decay_s`` 60 brought the extra path to
64% but more losses (traffic stays in the sector); a 60 s look-ahead with it 62 losses;
45 s with ``resume_decay_s`` 30 (and ``traffic.spawn_clear_s`` 120, so no pair starts in a
conflict too close to resolve) 28 losses, no NMAC, 12.8% extra path. Seeds 0–15 with
those settings (``scenarios/dense_random.toml``), after off-route time stopped counting
atan2 rounding in route rates as a turn back: 56 losses, 0 NMAC, 12.7% extra path, 3.5
aircraft still flying (no resolver: 871 losses, 47 NMAC); varying one setting at a time,
decay 15 s 61 losses, 60 s 77 (3 NMAC), look-ahead 60 s 103, 120 s 237 (7 NMAC). The
same decay on rings with the 120 s look-ahead gave 487 losses over the 18 ring runs above
instead of 4, so it is off by default.

Resolvers whose ``resolve`` accepts ``turn_rate`` get each ownship's turn-rate limit
(rad/s); ``"bands"`` with ``model_turn=True`` then judges each candidate heading as flown
(turning at that rate, then straight). Measured on rings of 64 with the defaults above it
gave more losses (2, 1, 3, 4, 2) and much longer paths, so it is off by default.

Resolver keyword arguments are built from the scenario (``r_safe`` from
``separation.r_safe``, ``lookahead_s`` from ``resolver.lookahead``, ``margin``, ``dt`` = the
world step) for those the resolver's constructor accepts, then ``resolver.params`` on top.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from airspace_sim.avoidance.bands import CLEAR_TOLERANCE, cpa_min_ratio
from airspace_sim.errors import UserError


def build_resolver(scenario, dt: float):
    """The scenario's resolver (:func:`airspace_sim.avoidance.resolvers.build_resolver`)."""
    from airspace_sim.avoidance.resolvers import build_resolver as build

    return build(scenario)


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

    def subset(self, mask: np.ndarray) -> Encounters:
        return Encounters(
            self.owners[mask],
            self.rows[mask],
            self.rel_position[mask],
            self.rel_velocity[mask],
            self.valid[mask],
        )

    def compact(self, keep: np.ndarray) -> Encounters:
        """Only the slots with ``keep`` (n_own, K) True, packed to the left, K shrunk."""
        keep = keep & self.valid
        n = self.owners.size
        K = int(keep.sum(axis=1).max(initial=0))
        order = np.argsort(~keep, axis=1, kind="stable")[:, :K]  # kept slots first
        take = lambda a: np.take_along_axis(a, order.reshape(n, K, *([1] * (a.ndim - 2))), axis=1)
        valid = take(keep)
        return Encounters(
            self.owners,
            np.where(valid, take(self.rows), -1),
            np.where(valid[..., None], take(self.rel_position), 0.0),
            np.where(valid[..., None], take(self.rel_velocity), 0.0),
            valid,
        )


def reachable(
    enc: Encounters, own_velocity, radius: float, lookahead: float, step: float = 10.0
) -> np.ndarray:
    """(n_own, K) bool: could the intruder come within ``radius`` during the look-ahead for
    SOME heading of the ownship (own speed kept, intruder straight)?

    ``|r + v_i t − v_o(ψ) t| ≥ |r + v_i t| − |v_o| t``; the right side is sampled every
    ``step`` seconds and lowered by its Lipschitz bound ``(|v_i| + |v_o|)·step/2``, so the
    test never drops an intruder that could matter (the band search's result is the same
    up to which exact boundary candidates it tries).
    """
    vo = np.asarray(own_velocity, dtype=float)[:, None, :]
    vi = enc.rel_velocity + vo
    so = np.hypot(vo[..., 0], vo[..., 1])  # (n, 1)
    t = np.arange(0.0, lookahead + step, step)
    t[-1] = min(t[-1], lookahead)
    px = enc.rel_position[..., 0:1] + vi[..., 0:1] * t
    py = enc.rel_position[..., 1:2] + vi[..., 1:2] * t
    f = np.hypot(px, py) - so[..., None] * t
    slack = (np.hypot(vi[..., 0], vi[..., 1]) + so) * step / 2.0
    return (f.min(axis=-1) - slack < radius) & enc.valid


def gather(track_owner, track_x, positions, velocities, runs) -> Encounters:
    """Padded per-ownship arrays of the tracks whose owner has ``runs[owner]`` True."""
    sel = np.flatnonzero(runs[track_owner]) if track_owner.size else np.zeros(0, np.int64)
    if sel.size == 0:
        z = np.zeros((0, 0, 2))
        return Encounters(
            np.zeros(0, np.int64), np.zeros((0, 0), np.int64), z, z.copy(), np.zeros((0, 0), bool)
        )
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
    """The scenario's resolver applied to gathered encounters, with the world's CDA policy.

    Policy (``scenario.resolver``): the resolver searches ``±search_deg`` for a clear heading
    (its ``max_heading_change`` argument); the world turns toward the chosen heading at most
    ``max_turn_rate·dt`` per step. ``turn_preference`` fixes the side of the turn for a whole
    conflict episode (until the ownship is clear): ``"right"`` takes the nearest clear
    heading on the right if there is one within the search range (else on the left),
    ``"nearest"`` the resolver's choice; afterwards the committed side is kept while it has
    a clear heading, and remembered for ``side_memory_s`` after the conflict ends (so a
    conflict flag flickering on noisy tracks does not flip the side). When the committed
    side has no clear heading, a resolver that reports ``min_ratio`` (``"bands"``) gets the
    best heading on that side (largest minimum CPA ratio) and the side is kept; otherwise
    the resolver's choice is used and the side follows it. (Flipping let two ownships of a
    late encounter on the ring of 200 switch sides at the same step and collide.) Under
    ``"right"`` a left commitment is only the fallback: the ownship returns to the right as
    soon as the right has a clear heading. (In the demo scenario one ownship committed left
    because a Markov intruder blocked its right, its neighbour went right, and the two
    turned into each other chasing a receding clear heading: NMAC, min separation ~0 m.
    Returning to the right gave 0 LoS there, and 0 instead of 1 LoS on rings of 100, seeds
    0-4.) Without commitment (``"none"``), or for resolvers that return no band, the
    resolver's advice is used as is. Only tracks older than ``confirm_s`` are used.
    """

    PREFERENCES = ("right", "nearest", "none")

    def __init__(self, scenario, dt: float):
        spec = scenario.resolver
        self.kind = spec.kind
        self.resolver = build_resolver(scenario, dt)
        p = spec.params
        self.r_safe = float(p.get("r_safe", scenario.separation.r_safe))
        self.lookahead = float(p.get("lookahead_s", spec.lookahead))
        self.margin = float(p.get("margin", spec.margin))
        self.search_range = np.radians(float(spec.search_deg))
        self.resume_margin = float(spec.resume_margin)
        self.resume_decay_s = None if spec.resume_decay_s is None else float(spec.resume_decay_s)
        self.confirm_steps = math.ceil(float(spec.confirm_s) / dt - 1e-9)
        if spec.turn_preference not in self.PREFERENCES:
            raise UserError(
                f"{scenario.source}: resolver.turn_preference: expected one of "
                f"{', '.join(self.PREFERENCES)}, got {spec.turn_preference!r}"
            )
        if not (0.0 <= spec.search_deg <= 180.0):
            raise UserError(
                f"{scenario.source}: resolver.search_deg: expected 0..180 degrees, "
                f"got {spec.search_deg!r}"
            )
        self.preference = spec.turn_preference
        self.memory_steps = math.ceil(float(spec.side_memory_s) / dt - 1e-9)
        self._clear_for = None  # steps each aircraft has been clear of conflict
        self.dt = float(dt)
        # capabilities the resolver declares (airspace_sim.parts.Resolver)
        self._takes_turn_rate = self.resolver.uses_turn_rate
        self._takes_modes = self.resolver.uses_mode_predictions
        horizon = (
            self.lookahead
            if spec.probability_horizon_s is None
            else float(spec.probability_horizon_s)
        )
        S = int(spec.probability_samples)
        #: seconds ahead at which mode predictions are sampled (mode-aware resolvers)
        self.prediction_times_s = horizon * np.arange(1, S + 1) / S
        #: whether advice overrides the autopilot ("none" only reports conflicts)
        self.overrides = self.kind != "none"

    def advise(
        self,
        enc: Encounters,
        velocities,
        max_heading_change,
        n: int,
        side=None,
        mode_predictions=None,
    ):
        """(advice (n,) rad, conflict (n,) bool) for all aircraft (0 / False off ``enc``).

        ``side`` (n,) float, updated in place: the committed turn side of each aircraft
        (−1 right, +1 left, 0 none). ``mode_predictions(enc, times_s)`` gives a resolver
        whose ``resolve`` takes ``mode_predictions`` (``"bands-probabilistic"``) the tracks'
        mode-conditioned predictions at ``probability_samples`` times over
        ``probability_horizon_s`` (:meth:`World.mode_predictions`).
        """
        advice = np.zeros(n)
        conflict = np.zeros(n, dtype=bool)
        if enc.owners.size and self.resolver.prefilter:
            # bands turn only ownships whose current heading is not clear: find those with
            # the resolver's own CPA test (C = 1) and run the band search on them alone
            vo = velocities[enc.owners]
            ratio0 = cpa_min_ratio(
                vo,
                enc.rel_position,
                enc.rel_velocity,
                enc.valid,
                np.zeros((enc.owners.size, 1)),
                self.r_safe * (1.0 + self.margin),
                self.lookahead,
            )[:, 0]
            enc = enc.subset(~(ratio0 >= 1.0 - CLEAR_TOLERANCE))
            # and only on the intruders some heading could bring within the clear radius
            enc = enc.compact(
                reachable(
                    enc, velocities[enc.owners], self.r_safe * (1.0 + self.margin), self.lookahead
                )
            )
        if enc.owners.size:
            mx = max_heading_change[enc.owners]
            kw = {"turn_rate": mx / self.dt} if self._takes_turn_rate else {}
            if self._takes_modes and mode_predictions is not None:
                pred = mode_predictions(enc, self.prediction_times_s)
                if pred is not None:
                    kw["mode_predictions"] = pred
            out = self.resolver.resolve(
                velocities[enc.owners],
                enc.rel_position,
                enc.rel_velocity,
                enc.valid,
                np.maximum(mx, self.search_range),
                **kw,
            )
            psi = np.asarray(out.heading_change, dtype=float)
            c = np.asarray(out.conflict, dtype=bool)
            if (
                side is not None
                and self.preference != "none"
                and getattr(out, "band", None) is not None
            ):
                mr = getattr(out, "min_ratio", None)
                psi, new_side = self._commit(
                    psi,
                    c,
                    side[enc.owners],
                    np.asarray(out.candidates),
                    np.asarray(out.band),
                    None if mr is None else np.asarray(mr),
                )
                side[enc.owners] = new_side
            advice[enc.owners] = np.clip(psi, -mx, mx)
            conflict[enc.owners] = c
        if side is not None:
            # forget the committed side once clear for side_memory_s
            if self._clear_for is None or self._clear_for.shape != (n,):
                self._clear_for = np.zeros(n, dtype=np.int64)
            self._clear_for = np.where(conflict, 0, self._clear_for + 1)
            side[self._clear_for >= max(self.memory_steps, 1)] = 0.0
        return advice, conflict

    def _commit(self, psi, conflict, side, cand, band, min_ratio=None):
        """Heading changes and sides under the turn preference (see the class docstring).

        ``cand`` (n, C) candidates sorted by the resolver's preference, ``band`` (n, C) clear.
        """
        rows = np.arange(psi.size)

        def first_clear(mask):
            ok = band & mask
            return ok.any(axis=1), cand[rows, np.argmax(ok, axis=1)]

        new_side = side.copy()
        fresh = conflict & (side == 0)
        if self.preference == "right":
            has_r, pick_r = first_clear(cand <= 0)
            has_l, pick_l = first_clear(cand >= 0)
            psi = np.where(fresh & has_r, pick_r, np.where(fresh & ~has_r & has_l, pick_l, psi))
            new_side = np.where(
                fresh, np.where(has_r, -1.0, np.where(has_l, 1.0, np.sign(psi))), new_side
            )
            # left is only the fallback: back to the convention's side as soon as a strictly
            # right heading is clear (one ownship left and one right can turn into each other)
            back = conflict & (side > 0) & first_clear(cand < 0)[0]
            side = np.where(back, -1.0, side)
            new_side = np.where(back, -1.0, new_side)
        else:
            new_side = np.where(fresh, np.sign(psi), new_side)
        kept = conflict & (side != 0)
        on_side = cand * side[:, None] >= 0
        has_s, pick_s = first_clear(on_side)
        psi = np.where(kept & has_s, pick_s, psi)
        if min_ratio is not None:
            # no clear heading on the committed side: the best one on that side, side kept
            # (two ownships flipping sides at once can turn into each other)
            score = np.where(on_side & ~np.isnan(cand), min_ratio, -np.inf)
            best = cand[rows, np.argmax(score, axis=1)]
            psi = np.where(kept & ~has_s, best, psi)
        else:
            new_side = np.where(kept & ~has_s, np.sign(psi), new_side)
        return psi, np.where(conflict, new_side, side)

    def resume_clear(
        self, enc: Encounters, velocities, turn, max_heading_change, off_route_s=None
    ) -> np.ndarray:
        """For the ownships of ``enc``: is the heading change ``turn`` (n_own,) clear?

        ``off_route_s`` (N,) seconds each aircraft has been off its autopilot; the extra
        ``resume_margin`` shrinks linearly to 0 over ``resume_decay_s`` of it.
        """
        from airspace_sim.avoidance import resume_heading_change

        if enc.owners.size == 0:
            return np.zeros(0, dtype=bool)
        vo = velocities[enc.owners]
        desired = np.arctan2(vo[:, 1], vo[:, 0]) + turn
        extra = np.full(enc.owners.size, self.resume_margin)
        if off_route_s is not None and self.resume_decay_s is not None:
            left = 1.0 - np.asarray(off_route_s)[enc.owners] / max(self.resume_decay_s, 1e-9)
            extra *= np.clip(left, 0.0, 1.0)
        _, clear = resume_heading_change(
            vo,
            desired,
            enc.rel_position,
            enc.rel_velocity,
            enc.valid,
            max_heading_change[enc.owners],
            r_safe=self.r_safe,
            lookahead_s=self.lookahead,
            margin=self.margin + extra,
        )
        return np.asarray(clear, dtype=bool)
