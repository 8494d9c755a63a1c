"""``"bands-flown-intent"``: the as-flown band search with each equipped intruder predicted
along its broadcast intent (intent-based conflict resolution).

Every other band resolver predicts an intruder straight at its tracked velocity (state-based
prediction). In dense traffic where everyone avoids, that prediction is wrong exactly where
it matters: the intruder is turning to the heading its own resolver advised, and the traced
losses of ``"bands-flown"`` (``docs/resolvers.md``, seventh to twelfth parts) are pairs that
each judged the other straight while both manoeuvred. Predicting the intruder's *observed*
turn (``"bands-flown-turns"``, the track's Ω) did not help: the estimate lags the turn and
says nothing of where it ends.

Here every aircraft that flies the CDA policy broadcasts the heading it is steering to, as
ADS-B's target state report (DO-260B) or an ACAS coordination message would carry it: the
heading its resolver advised while it is in conflict, its autopilot's desired heading while
it flies its route (a turn back included), its current heading while it holds
(:attr:`~airspace_sim.world.policy.AvoidancePolicy.intent_heading`). The ownship predicts each
such intruder from its track: turning at the intruder's own turn limit from the track's
heading to the intent, then straight
(:func:`~airspace_sim.avoidance.cpa_intruder_turning.cpa_min_ratio_intruder_turning`), and
judges its candidates as flown against that path alone; an intruder without intent (not
equipped, or an RL agent) is predicted straight. The conflict test at the current heading
stays the straight one (the world's prefilter holds, and an ownship is not released by an
intent that may change at the next step); the sides open at once and the boxed fallbacks'
short horizon stay straight too. Everything else is ``"bands-flown"``'s. The intents are one
step old (what the intruder steered to when the world last moved), as a broadcast would be.

Trusting every intent lets each aircraft leave part of a resolution to the others, and when
all do it at once nobody turns enough: on the converging rings of 64 and 100 aircraft the
ring jams (``docs/resolvers.md``, twelfth part). Which intents are used is therefore a
choice: all of them (default), a share of each intended turn (``intent_share``), only those
held for a while (``intent_min_age_s``), only on ownships with few conflicts
(``intent_max_conflicts``), or a priority order in which the ownship uses only the intents of
the aircraft that plan before it and predicts the others straight, as prioritized planning
does (Erdmann & Lozano-Pérez 1987): by aircraft index (``priority``), by who committed to
its intent first (``priority_by_age``, ties by index), or by the pair's geometry
(``priority_by_crossing``: the intruder that reaches the crossing of the two straight tracks
first is relied on, the other predicted straight; no pair relies on each other, and the
near-parallel neighbours of a converging ring not at all; ``scenarios/dense_random.toml``
runs this one, ``docs/resolvers.md`` thirteenth part). ``trust_intent = false`` judges each
candidate against the worse of the straight and the intended path instead.
Distances m, times s, angles rad CCW positive.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from airspace_sim import registry
from airspace_sim.avoidance.bands import CLEAR_TOLERANCE
from airspace_sim.avoidance.cpa import cpa_pair_ratios
from airspace_sim.avoidance.flown_bands import (
    DEFAULT_TURN_RATE,
    FlownBandsResolver,
    IntruderTurns,
)
from airspace_sim.parts import param


def crossing_times(vo, r, v):
    """``(t_own (n, k) s, t_intruder (n, k) s)``: when the ownship (at the origin, velocity
    ``vo`` (n, 2) m/s) and each intruder (relative position ``r`` (n, k, 2) m, relative
    velocity ``v`` (n, k, 2) m/s) reach the point where their straight tracks cross (negative:
    passed it; NaN where the tracks are within 10° of parallel, which have no crossing to
    order)."""
    vi = v + vo[:, None, :]
    own = np.broadcast_to(vo[:, None, :], vi.shape)
    det = own[..., 0] * vi[..., 1] - own[..., 1] * vi[..., 0]
    norm = np.linalg.norm(own, axis=-1) * np.linalg.norm(vi, axis=-1)
    crossing = np.abs(det) > np.sin(np.radians(10.0)) * norm
    det = np.where(crossing, det, np.nan)
    t_own = (r[..., 0] * vi[..., 1] - r[..., 1] * vi[..., 0]) / det
    t_intruder = (r[..., 0] * own[..., 1] - r[..., 1] * own[..., 0]) / det
    return t_own, t_intruder


def intent_turns(intent, turn_limit):
    """``(omega (n, k) rad/s, turn_s (n, k) s)``: turning toward each intruder's intent
    (``intent`` (n, k) rad, the heading change from its track's heading to the heading it
    steers to; NaN or 0: straight) at its turn limit (``turn_limit`` (n, k) rad/s; not
    finite or ≤ 0: straight)."""
    intent = np.nan_to_num(np.asarray(intent, dtype=float))
    limit = np.asarray(turn_limit, dtype=float)
    ok = np.isfinite(limit) & (limit > 0.0)
    rate = np.where(ok, limit, 1.0)
    omega = np.where(ok, np.sign(intent) * rate, 0.0)
    turn_s = np.where(ok, np.abs(intent) / rate, 0.0)
    return omega, turn_s


@registry.register("resolver", "bands-flown-intent")
class IntentFlownBandsResolver(FlownBandsResolver):
    """``"bands-flown"`` with each equipped intruder predicted along its intent (module
    docstring)."""

    @dataclass(frozen=True)
    class Params(FlownBandsResolver.Params):
        trust_intent: bool = param(
            True,
            doc="judge candidates against each intruder's intended path alone (false: "
            "against the smaller of its straight and intended paths' ratios)",
        )
        intent_share: float = param(
            1.0,
            doc="the fraction of each intruder's intended heading change it is predicted to "
            "make (1: all of it; 0: straight)",
            ge=0.0,
            le=1.0,
        )
        intent_max_conflicts: int = param(
            0,
            doc="use intents only on ownships with at most this many intruders in conflict "
            "(straight test at the current heading); more: all predicted straight (0: always)",
            ge=0,
        )
        intent_min_age_s: float = param(
            0.0,
            unit="s",
            doc="use an intruder's intent only once it has held this long (0: always)",
            ge=0.0,
        )
        priority: bool = param(
            False,
            doc="prioritized planning: use only the intents of intruders of a lower aircraft "
            "index than the ownship's, and predict the others straight",
        )
        priority_by_age: bool = param(
            False,
            doc="prioritized planning by who committed first: use only the intents held "
            "longer than the ownship's own (equal ages: the lower aircraft index first)",
        )
        priority_by_crossing: bool = param(
            False,
            doc="prioritized planning by the pair's crossing: use an intruder's intent only "
            "when it reaches the point where the two straight tracks cross at least "
            "crossing_margin_s before the ownship (near-parallel tracks: straight)",
        )
        crossing_margin_s: float = param(
            5.0,
            unit="s",
            doc="how much earlier an intruder must reach the crossing for its intent to count "
            "(priority_by_crossing)",
            ge=0.0,
        )

    uses_intruder_intent = True
    uses_aircraft_ids = True

    def intruder_turns(self, n, k, turn_rate, intruders):
        """Each intruder turning to its intent at its turn limit, candidates judged against
        that path alone; None without intruders or intents."""
        intent = intruders["intent"]
        if intent is None or k == 0:
            return None
        rate = DEFAULT_TURN_RATE if turn_rate is None else turn_rate
        rate = np.broadcast_to(np.asarray(rate, dtype=float), (n,))
        if self.params.priority:
            own, ids = intruders["aircraft_ids"], intruders["intruder_ids"]
            if own is None:
                return None
            ahead = (ids >= 0) & (ids < np.asarray(own)[:, None])
            intent = np.where(ahead, intent, 0.0)
        if self.params.priority_by_age:
            own, ids = intruders["aircraft_ids"], intruders["intruder_ids"]
            age, mine = intruders["intent_age_s"], intruders["own_intent_age_s"]
            if own is None or age is None or mine is None:
                return None
            mine = np.asarray(mine, dtype=float)[:, None]
            older = (age > mine) | ((age == mine) & (ids < np.asarray(own)[:, None]))
            intent = np.where((ids >= 0) & older, intent, 0.0)
        if self.params.priority_by_crossing:
            vo, r, v = intruders["geometry"][:3]
            t_own, t_intruder = crossing_times(vo, r, v)
            first = t_own - t_intruder > self.params.crossing_margin_s
            intent = np.where(first, intent, 0.0)
        if self.params.intent_min_age_s > 0.0:
            age = intruders["intent_age_s"]
            held = age is not None and np.asarray(age) >= self.params.intent_min_age_s
            intent = np.where(held, intent, 0.0)
        if self.params.intent_max_conflicts > 0:
            vo, r, v, valid, radius = intruders["geometry"]
            alone = cpa_pair_ratios(
                vo, r, v, valid, np.zeros((n, 1)), radius, self.params.lookahead_s
            )[:, :, 0]
            count = (alone < 1.0 - CLEAR_TOLERANCE).sum(axis=1)
            intent = np.where((count <= self.params.intent_max_conflicts)[:, None], intent, 0.0)
        omega, turn_s = intent_turns(
            self.params.intent_share * np.asarray(intent), intruders["turn_limit"]
        )
        return IntruderTurns(rate, omega, turn_s, detects=False, replaces=self.params.trust_intent)
