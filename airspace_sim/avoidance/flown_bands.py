"""Band search with the sides judged at once and the heading on a side judged as flown.

``"bands"`` judges a candidate ψ as if the heading changed at once. In dense random traffic
its losses come 15–35 s after detection (``docs/resolvers.md``), when a 3°/s turn to ψ takes
a good part of the time left and sweeps through headings the search found blocked; judging
candidates as flown (``"bands"``' ``model_turn``: turning at the turn rate until ψ is
reached, then straight, :func:`~airspace_sim.avoidance.cpa_turning.cpa_min_ratio_turning`)
gave fewer losses and shorter paths there, but on the converging ring it lets neighbours
take opposite sides: an ownship whose right side has no heading clear *as flown* commits
left under the CDA policy's right-of-way preference, its neighbour commits right, and the
two turn into each other (ring of 64, seed 0: 8 losses, all such pairs).

``"bands-flown"`` separates the two questions:

- *which sides are open* is ``"bands"``' answer: a side (``ψ ≤ 0``, ``ψ ≥ 0``, ``ψ < 0``: the
  columns of ``first_clear``) is open when some candidate on it is clear at once, so the
  CDA policy commits the same sides as under ``"bands"`` for the same picture;
- *which heading on an open side* is judged as flown: the first candidate in ``"bands"``'
  preference order that is clear at once and as flown, else the one of largest as-flown
  minimum CPA ratio among the side's clear-at-once candidates; it is reported as that
  side's first clear candidate.

On a side with no clear candidate the best blocked one is the candidate of largest as-flown
ratio (``model_turn``'s).

With ``fresh_sides_only`` everything is ``model_turn``'s (first clear as flown, else best as
flown) except one thing: for an ownship not yet committed to a side, a side that is open at
once but has no heading clear as flown reports its best as-flown heading as its first clear
one, so the policy commits the side ``"bands"`` would (:func:`fresh_flown_sides`); once
committed, the ownship flies ``model_turn``'s heading on that side.

With ``switch_below`` (a ratio in (0, 1], 0: off) an ownship committed to a side that has no
heading clear as flown, while the other side has one, is sent to the other side when the
committed side's best as-flown minimum CPA ratio is below ``switch_below``
(:func:`switch_boxed_sides`): the committed side's best blocked candidate is reported as the
other side's first clear one, which the CDA policy then flies (it keeps the side label; under
its right preference a left-committed ownship already goes back right when a strictly right
heading is clear). Traced on ``dense_random`` (``loss_trace.py dense:8``), most losses of
``fresh_sides_only`` had an ownship committed right fly its right side's best blocked
heading (often ψ = 0, ratio 0.5–0.8) for 10–30 s while a left heading was clear as flown.
On the converging ring that fights the fresh rule (a fresh ownship commits the side open at
once, the next step finds it boxed as flown and switches); ``switch_blocked_at_once`` keeps
a committed side that is still open at once.

With ``boxed_best_both`` an ownship committed to a side while *neither* side has a heading
clear as flown (boxed on both sides) flies the best as-flown candidate over both sides (the
largest as-flown minimum CPA ratio; the committed side's own best is kept on ties) instead
of its committed side's best (:func:`best_of_both_when_boxed`); the side label is kept.
Traced on ``fresh:ao`` (``results/loss_trace_switch_s21.txt``), every remaining dense loss
had one aircraft boxed on both sides for 5 s or more. With ``boxed_margin`` (≥ 0) the best of
both sides is taken only when its as-flown ratio beats the committed side's best by more
than the margin (a stateless hysteresis: on the symmetric ring the boxed sides' bests differ
little and the plain rule flips sides from step to step).

With ``boxed_horizon_s`` (H > 0) the boxed ownship ranks candidates first by their as-flown
ratio over H (capped at 1), then over the look-ahead, so the imminent intruder is cleared
first: the look-ahead ratio cannot tell a conflict 15 s away from one 90 s away, and the
traced dense losses of the plain rule were pairs holding ψ ≈ 0 because a third, later aircraft
capped the turn that cleared the imminent one. Only candidates whose look-ahead ratio is at
least ``1 − boxed_horizon_guard`` times the committed side's best are ranked so: clear for H seconds
and then at a ratio near 0 is no escape (``docs/resolvers.md``, seventh and ninth parts).

With ``boxed_hold_heading`` the boxed ownship measures those gains against the heading it was
advised at the last detection (``held_heading_change``, which the CDA policy keeps), not its
committed side's best: a heading hysteresis. Traced on the 300-ring under a decaying resume
clearance, a knot of boxed aircraft changed advice every few steps (ψ ≈ 0, +43°, 0, +37°, …)
and lost 14 pairs (``docs/resolvers.md``, ninth part).

``"bands-flown-turns"`` (:class:`TurnAwareFlownBandsResolver`) also predicts each intruder
turning at its track's estimated rate for ``intruder_turn_s``; measured on ``dense_random`` it
flies longer detours than ``"bands-flown"`` and loses no fewer pairs (``docs/resolvers.md``,
tenth part).

Detection is ``"bands"``' straight CPA test at the current heading (the world's prefilter
holds; not for ``"bands-flown-turns"``). Distances m, velocities m/s, times s, angles rad CCW
positive.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from airspace_sim import registry
from airspace_sim.avoidance.bands import (
    CLEAR_TOLERANCE,
    at_once_ratios,
    band_choice,
    bands_from_ratio,
    wanted_sides,
)
from airspace_sim.avoidance.cpa_intruder_turning import cpa_min_ratio_intruder_turning
from airspace_sim.avoidance.cpa_turning import cpa_min_ratio_turning
from airspace_sim.avoidance.resolvers import BandsResolver, ResolverOutput, _arrays
from airspace_sim.parts import param

#: rad/s: the ownship's turn rate when the caller gives none (the shipped 3°/s limit)
DEFAULT_TURN_RATE = math.radians(3.0)


class IntruderTurns(NamedTuple):
    """How a resolver predicts its intruders' turns (:meth:`FlownBandsResolver.intruder_turns`).

    rate (n,) rad/s, the ownship's turn rate; omega (n, k) rad/s, each intruder's turn rate,
    flown for ``turn_s`` s (scalar or (n, k)), then straight; ``detects``: the conflict test
    also uses the turned prediction (the world's prefilter then does not hold); ``replaces``:
    a candidate's as-flown ratio is the turned prediction's alone (else the smaller of it and
    the straight one's)."""

    rate: np.ndarray
    omega: np.ndarray
    turn_s: object
    detects: bool
    replaces: bool


def side_masks(candidates):
    """The candidates (N, C) rad on each side: ``(ψ ≤ 0, ψ ≥ 0, ψ < 0)``, (N, C) bool each
    (the columns of ``first_clear``; NaN on none)."""
    return candidates <= 0, candidates >= 0, candidates < 0


def open_at_once(candidates, clear):
    """(N, 3) bool: the sides of :func:`side_masks` with a candidate clear at once
    (``clear`` (N, C) bool)."""
    return np.stack([(clear & mask).any(axis=1) for mask in side_masks(candidates)], axis=1)


def flown_sides(candidates, clear, flown, wanted):
    """``(first_clear (N, 3), best_blocked (N, 2))`` of the module docstring's choice.

    candidates (N, C) rad in preference order (NaN: unused); clear (N, C) bool, clear at
    once; flown (N, C) as-flown minimum CPA ratio (−inf where unused); wanted (N, 2) bool,
    the sides (ψ ≤ 0, ψ ≥ 0) whose best blocked candidate is asked for. Indices into
    ``candidates``, −1: none.
    """
    n = candidates.shape[0]
    usable = ~np.isnan(candidates)
    good = clear & (flown >= 1.0 - CLEAR_TOLERANCE)
    first = np.full((n, 3), -1, dtype=np.int64)
    best = np.full((n, 2), -1, dtype=np.int64)
    opened = open_at_once(candidates, clear)
    for col, mask in enumerate(side_masks(candidates)):
        open_ = opened[:, col]
        fine = good & mask
        top = np.argmax(np.where(clear & mask, flown, -np.inf), axis=1)
        first[:, col] = np.where(
            fine.any(axis=1), np.argmax(fine, axis=1), np.where(open_, top, -1)
        )
        if col < 2:
            side = mask & usable
            blocked = ~open_ & side.any(axis=1) & wanted[:, col]
            best[:, col] = np.where(blocked, np.argmax(np.where(side, flown, -np.inf), axis=1), -1)
    return first, best


def fresh_flown_sides(candidates, clear, flown, wanted, committed_side=None):
    """``(first_clear (N, 3), best_blocked (N, 2))`` judged as flown (``"bands"``'
    ``model_turn``: the first candidate clear as flown, else the best as-flown one), except
    that for an ownship with no committed side (``committed_side`` (N,) 0, or None: all) a
    side that is open at once but has no heading clear as flown reports its best as-flown
    candidate as its first clear one, so the CDA policy commits the side ``"bands"`` would.
    Arguments as in :func:`flown_sides`."""
    usable = ~np.isnan(candidates)
    _, first, best = bands_from_ratio(candidates, flown, usable, wanted)
    n = candidates.shape[0]
    fresh = np.ones(n, dtype=bool)
    if committed_side is not None:
        fresh = np.broadcast_to(np.asarray(committed_side, dtype=float), (n,)) == 0
    opened = open_at_once(candidates, clear)
    for col, mask in enumerate(side_masks(candidates)):
        side = mask & usable
        top = np.argmax(np.where(side, flown, -np.inf), axis=1)
        lift = fresh & (first[:, col] < 0) & opened[:, col]
        first[:, col] = np.where(lift, top, first[:, col])
        if col < 2:
            best[:, col] = np.where(lift, -1, best[:, col])
    return first, best


def switch_boxed_sides(
    first_clear, best_blocked, ratio, committed_side, switch_below, open_at_once=None
):
    """``best_blocked`` (N, 2) with the committed side's entry replaced by the other side's
    first clear candidate where the committed side (``committed_side`` (N,) −1 right,
    +1 left, 0 none) has no clear candidate, the other side has one, and the committed
    side's best blocked candidate has ``ratio`` (N, C) below ``switch_below``; a new array.
    ``first_clear`` (N, 3) and ``best_blocked`` (N, 2) indices as in
    :func:`flown_sides` (−1: none). With ``open_at_once`` (N, 2) bool (the sides ψ ≤ 0,
    ψ ≥ 0 with a candidate clear at once) a committed side still open at once is kept."""
    best = best_blocked.copy()
    side = np.broadcast_to(np.asarray(committed_side, dtype=float), (best.shape[0],))
    rows = np.arange(best.shape[0])
    for value, col, other in ((-1.0, 0, 1), (1.0, 1, 0)):
        b = best[:, col]
        score = np.where(b >= 0, ratio[rows, np.maximum(b, 0)], np.inf)
        boxed = (side == value) & (first_clear[:, col] < 0) & (first_clear[:, other] >= 0)
        if open_at_once is not None:
            boxed &= ~open_at_once[:, col]
        swap = boxed & (b >= 0) & (score < switch_below)
        best[:, col] = np.where(swap, first_clear[:, other], b)
    return best


def boxed_rows(first_clear, usable, committed_side):
    """(N,) bool: committed ownships (``committed_side`` (N,) ≠ 0) with no clear candidate on
    either side (``first_clear`` (N, 3) columns 0 and 1 both −1) and some usable one
    (``usable`` (N, C))."""
    side = np.broadcast_to(np.asarray(committed_side, dtype=float), (first_clear.shape[0],))
    boxed = (first_clear[:, 0] < 0) & (first_clear[:, 1] < 0) & usable.any(axis=1)
    return boxed & (side != 0)


def held_candidate(candidates, usable, held_heading_change, tolerance):
    """(N,) index of the usable candidate nearest ``held_heading_change`` (N,) rad, −1 where
    that is NaN or no usable candidate of ``candidates`` (N, C) rad (``usable`` (N, C)) is
    within ``tolerance`` rad of it."""
    held = np.asarray(held_heading_change, dtype=float)[:, None]
    gap = np.where(usable & np.isfinite(held), np.abs(candidates - held), np.inf)
    at = np.argmin(gap, axis=1)
    near = gap[np.arange(gap.shape[0]), at] <= tolerance
    return np.where(near, at, -1)


def best_of_both_when_boxed(
    first_clear,
    best_blocked,
    ratio,
    usable,
    committed_side,
    margin=0.0,
    imminent=None,
    guard=0.0,
    incumbent=None,
    hold_margin=None,
):
    """``best_blocked`` (N, 2) with the committed side's entry (``committed_side`` (N,) −1
    right, +1 left, 0 none) replaced by the candidate of largest ``ratio`` (N, C) over both
    sides (``usable`` (N, C)) where neither side has a clear candidate (``first_clear`` (N, 3)
    columns 0 and 1 both −1) and that candidate's ratio is above the committed side's best
    blocked one's by more than ``margin`` (≥ 0; 0: strictly above); a new array. Indices as in
    :func:`flown_sides`.

    With ``imminent`` (N, C) (the as-flown ratio over a short horizon) candidates are ranked
    first by ``min(imminent, 1)``, then by ``ratio``, among those whose ``ratio`` is at least
    ``1 − guard`` times the committed side's best's (``guard`` in [0, 1]; clear for the short
    horizon and then far worse is no escape): the top one is the candidate of largest ``ratio`` among those within
    ``CLEAR_TOLERANCE`` of the largest ``min(imminent, 1)``, and it replaces the committed
    side's best when its ``min(imminent, 1)`` beats that one's by more than ``margin``, or ties
    it and its ``ratio`` beats by more than ``margin``. Where no candidate is short of 1 over
    the short horizon this is the rule without ``imminent``.

    With ``incumbent`` (N,) (candidate indices, −1: none) the incumbent a boxed row keeps
    unless beaten is that candidate where given, not the committed side's best (a heading
    hysteresis: the ownship holds the heading it was advised until a candidate gains by
    more than ``hold_margin``, None: ``margin``)."""
    best = best_blocked.copy()
    n = best.shape[0]
    side = np.broadcast_to(np.asarray(committed_side, dtype=float), (n,))
    rows = np.arange(n)
    score = np.where(usable, ratio, -np.inf)
    if imminent is None:
        first_key = np.where(usable, 1.0, -np.inf)
    else:
        first_key = np.where(usable, np.minimum(imminent, 1.0), -np.inf)
    boxed = boxed_rows(first_clear, usable, committed_side)
    for value, col in ((-1.0, 0), (1.0, 1)):
        b = best[:, col]
        gain = margin
        if incumbent is not None:
            held = boxed & (side == value) & (incumbent >= 0)
            b = np.where(held, incumbent, b)
            gain = np.where(held, margin if hold_margin is None else hold_margin, margin)
        at = np.maximum(b, 0)
        own_first = np.where(b >= 0, first_key[rows, at], -np.inf)
        own = np.where(b >= 0, score[rows, at], -np.inf)
        finite = np.isfinite(own)
        floor = np.where(finite, (1.0 - guard) * np.where(finite, own, 0.0), -np.inf)
        key = (
            first_key if imminent is None else np.where(score >= floor[:, None], first_key, -np.inf)
        )
        near = key >= key.max(axis=1, keepdims=True) - CLEAR_TOLERANCE
        top = np.argmax(np.where(near, score, -np.inf), axis=1)
        top_first, top_score = first_key[rows, top], score[rows, top]
        beats = (top_first > own_first + gain) | (
            (top_first >= own_first - CLEAR_TOLERANCE) & (top_score > own + gain)
        )
        mine = boxed & (side == value)
        best[:, col] = np.where(mine & beats, top, np.where(mine, b, best[:, col]))
    return best


def radius_rows(radius, rows):
    """The clear radius of ``rows`` (an index array): ``radius`` itself when it is one
    number for every slot, else its (N, K) array's rows."""
    return radius if np.ndim(radius) == 0 else np.asarray(radius)[rows]


def as_flown_on_rows(
    base,
    rows,
    own_velocity,
    rel_position,
    rel_velocity,
    valid,
    safe,
    usable,
    radius,
    lookahead_s,
    turn_rate,
):
    """``base`` (N, C) with the ``rows`` (N,) bool replaced by the as-flown minimum CPA ratio
    over ``lookahead_s`` of the candidates ``safe`` (N, C) rad (−inf where not ``usable``
    (N, C)); a new array. Arrays as in :func:`cpa_min_ratio_turning` (``radius`` m, a number
    or (N, K)); ``turn_rate`` rad/s, scalar or (N,), None: :data:`DEFAULT_TURN_RATE`."""
    out = np.array(base, dtype=float, copy=True)
    idx = np.flatnonzero(rows)
    if idx.size and rel_position.shape[1] > 0:
        n = own_velocity.shape[0]
        rate = DEFAULT_TURN_RATE if turn_rate is None else turn_rate
        rate_rows = np.broadcast_to(np.asarray(rate, dtype=float), (n,))[idx]
        ratio = cpa_min_ratio_turning(
            own_velocity[idx],
            rel_position[idx],
            rel_velocity[idx],
            valid[idx],
            safe[idx],
            radius_rows(radius, idx),
            lookahead_s,
            rate_rows,
        )
        out[idx] = np.where(usable[idx], ratio, -np.inf)
    return out


@registry.register("resolver", "bands-flown")
class FlownBandsResolver(BandsResolver):
    """``"bands"``' open sides, the heading on a side judged as flown (module docstring)."""

    @dataclass(frozen=True)
    class Params(BandsResolver.Params):
        fresh_sides_only: bool = param(
            False,
            doc="judge everything as flown (model_turn) but which sides are open to an "
            "ownship not yet committed to one",
        )
        switch_below: float = param(
            0.0,
            doc="send an ownship whose committed side has no clear heading to the other "
            "side's first clear one when the committed side's best as-flown ratio is below "
            "this (0: never)",
            ge=0.0,
            le=1.0,
        )
        switch_blocked_at_once: bool = param(
            False,
            doc="with switch_below: switch only when the committed side has no heading "
            "clear at once either",
        )
        boxed_best_both: bool = param(
            False,
            doc="a committed ownship with no heading clear as flown on either side flies the "
            "best as-flown candidate of both sides, not its committed side's best",
        )
        boxed_margin: float = param(
            0.0,
            doc="with boxed_best_both: take the best of both sides only when its as-flown "
            "ratio beats the committed side's best by more than this (0: any gain)",
            ge=0.0,
        )
        boxed_horizon_s: float = param(
            0.0,
            doc="with boxed_best_both: rank the candidates of a boxed ownship first by their "
            "as-flown ratio over this many seconds (capped at 1), then over the look-ahead "
            "(0: over the look-ahead only)",
            ge=0.0,
        )
        boxed_horizon_guard: float = param(
            0.7,
            doc="with boxed_horizon_s: rank over the short horizon only the candidates whose "
            "look-ahead ratio is at least (1 - this) times the committed side's best",
            ge=0.0,
            le=1.0,
        )
        boxed_hold_heading: bool = param(
            False,
            doc="with boxed_best_both: a boxed ownship keeps the candidate nearest the heading "
            "it was advised at the last detection unless another beats it by more than "
            "boxed_hold_margin (instead of measuring the gain against its committed side's "
            "best)",
        )
        boxed_hold_margin: float = param(
            0.1,
            doc="with boxed_hold_heading: the gain (as-flown ratio) a candidate needs over "
            "the held heading to replace it",
            ge=0.0,
        )

    uses_held_heading = True

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
        held_heading_change=None,
        intruder_turn_rate=None,
        speed_limits=None,
        max_acceleration=None,
        aircraft_ids=None,
        intruder_ids=None,
        intruder_intent=None,
        intruder_turn_limit=None,
        intruder_intent_age_s=None,
        own_intent_age_s=None,
    ):
        p = self.params
        vo, r, v, valid, mx = _arrays(
            own_velocity, rel_position, rel_velocity, valid, max_heading_change
        )
        n = vo.shape[0]
        radius, cand, usable, ratio, conflict = at_once_ratios(
            vo, r, v, valid, mx, p, self.clear_radius(vo, r, v, valid)
        )
        safe = np.where(usable, cand, 0.0)
        clear = usable & (ratio >= 1.0 - CLEAR_TOLERANCE)
        turning = self.intruder_turns(
            n,
            r.shape[1],
            turn_rate,
            {
                "turn_rate": intruder_turn_rate,
                "intent": intruder_intent,
                "turn_limit": intruder_turn_limit,
                "intent_age_s": intruder_intent_age_s,
                "own_intent_age_s": own_intent_age_s,
                "aircraft_ids": aircraft_ids,
                "intruder_ids": intruder_ids,
                "geometry": (vo, r, v, valid, radius),
            },
        )
        if turning is not None and turning.detects:
            ahead = cpa_min_ratio_intruder_turning(
                vo, r, v, valid, np.zeros((n, 1)), radius, p.lookahead_s, *turning[:3]
            )[:, 0]
            conflict = conflict | ~(ahead >= 1.0 - CLEAR_TOLERANCE)
        # as flown only where the choice matters (a clear ownship keeps ψ = 0): the at-once
        # ratio elsewhere; rows whose turned prediction replaces it are judged below instead
        replaced = turning is not None and turning.replaces
        flown = as_flown_on_rows(
            ratio, conflict & ~replaced, vo, r, v, valid, safe, usable, radius, p.lookahead_s,
            turn_rate,
        )  # fmt: skip
        if turning is not None:
            rate, omega, turn_s = turning[:3]
            rows = np.flatnonzero(conflict)
            if rows.size:
                turned = cpa_min_ratio_intruder_turning(
                    vo[rows],
                    r[rows],
                    v[rows],
                    valid[rows],
                    safe[rows],
                    radius_rows(radius, rows),
                    p.lookahead_s,
                    rate[rows],
                    omega[rows],
                    turn_s if np.ndim(turn_s) == 0 else turn_s[rows],
                )
                if not turning.replaces:
                    turned = np.minimum(flown[rows], turned)
                flown[rows] = np.where(usable[rows], turned, -np.inf)
        flown, speeds = self.speed_axis(
            flown, conflict, vo, r, v, valid, safe, usable, radius, turn_rate,
            speed_limits, max_acceleration,
        )  # fmt: skip
        wanted = wanted_sides(committed_side, n)
        if self.params.fresh_sides_only:
            first, best = fresh_flown_sides(cand, clear, flown, wanted, committed_side)
        else:
            first, best = flown_sides(cand, clear, flown, wanted)
        if p.switch_below > 0.0 and committed_side is not None:
            at_once = open_at_once(cand, clear)[:, :2] if p.switch_blocked_at_once else None
            best = switch_boxed_sides(first, best, flown, committed_side, p.switch_below, at_once)
        if p.boxed_best_both and committed_side is not None:
            imminent = None
            if p.boxed_horizon_s > 0.0:
                # +inf off the boxed rows: nothing is short there, so the plain rule holds
                imminent = as_flown_on_rows(
                    np.full(cand.shape, np.inf),
                    boxed_rows(first, usable, committed_side),
                    vo,
                    r,
                    v,
                    valid,
                    safe,
                    usable,
                    radius,
                    p.boxed_horizon_s,
                    turn_rate,
                )
            incumbent = None
            if p.boxed_hold_heading and held_heading_change is not None:
                held = np.broadcast_to(np.asarray(held_heading_change, dtype=float), (n,))
                incumbent = held_candidate(cand, usable, held, p.resolution)
            best = best_of_both_when_boxed(
                first,
                best,
                flown,
                usable,
                committed_side,
                p.boxed_margin,
                imminent,
                p.boxed_horizon_guard,
                incumbent,
                p.boxed_hold_margin,
            )
        if aircraft_ids is not None and committed_side is not None:
            best = self.coordinate(
                best,
                boxed_rows(first, usable, committed_side),
                cand,
                usable,
                committed_side,
                (vo, r, v, valid, radius, turn_rate),
                (np.asarray(aircraft_ids), np.asarray(intruder_ids)),
            )
        idx = np.arange(n)
        choice = band_choice(
            first, best, lambda i: np.where(i >= 0, flown[idx, np.maximum(i, 0)], -np.inf)
        )
        return ResolverOutput(
            cand[idx, choice],
            conflict,
            cand,
            clear,
            min_ratio=flown,
            first_clear=first,
            best_blocked=best,
            speed_target=None if speeds is None else speeds[idx, choice],
            candidate_speed=speeds,
        )

    def clear_radius(self, vo, r, v, valid):
        """None: every slot is judged against ``r_safe·(1 + margin)`` (a subclass may return
        an (N, K) clear radius, m)."""
        return None

    def coordinate(self, best, boxed, cand, usable, committed_side, geometry, ids):
        """``best`` (N, 2): this resolver decides each row on its own picture
        (:class:`~airspace_sim.avoidance.paired_bands.PairedFlownBandsResolver` picks boxed
        pairs' headings together)."""
        return best

    def speed_axis(
        self, flown, conflict, vo, r, v, valid, safe, usable, radius, turn_rate, limits, accel
    ):
        """``(flown, None)``: this resolver changes headings only
        (:class:`~airspace_sim.avoidance.speed_bands.SpeedFlownBandsResolver` returns each
        candidate's ratio with its best speed and that speed, (N, C) m/s)."""
        return flown, None

    def intruder_turns(self, n, k, turn_rate, intruders):
        """None: this resolver predicts intruders straight (:class:`TurnAwareFlownBandsResolver`
        and :class:`~airspace_sim.avoidance.intent_bands.IntentFlownBandsResolver` return an
        :class:`IntruderTurns`). ``intruders``: :meth:`resolve`'s keyword arguments about
        intruders by name, ``intruder_`` dropped (``turn_rate``, ``intent``, ``turn_limit``,
        ``intent_age_s``; ``own_intent_age_s``, ``aircraft_ids`` and ``intruder_ids`` as
        they are), and ``geometry``: ``(vo, r, v, valid, radius)`` as judged."""
        return None


@registry.register("resolver", "bands-flown-turns")
class TurnAwareFlownBandsResolver(FlownBandsResolver):
    """``"bands-flown"`` that also sees each intruder's turn: the conflict test and the
    as-flown candidates are judged against every intruder both straight and turning at its
    track's estimated turn rate (the state's Ω, clipped to the ownship's own turn limit) for
    ``intruder_turn_s``, then straight (the smaller ratio counts;
    :func:`~airspace_sim.avoidance.cpa_intruder_turning.cpa_min_ratio_intruder_turning`).
    Traced on ``dense_random`` (``docs/resolvers.md``, ninth and tenth parts), some of the
    losses left were pairs whose straight miss closed while one aircraft turned for a third;
    measured there (tenth part), the turned prediction adds alerts for aircraft whose
    avoidance turns end soon, and longer detours, with no fewer losses. The conflict is no
    longer the straight test alone, so the world's prefilter is off; the boxed ownship's
    short-horizon ranking (``boxed_horizon_s``) still predicts intruders straight."""

    @dataclass(frozen=True)
    class Params(FlownBandsResolver.Params):
        intruder_turn_s: float = param(
            20.0,
            unit="s",
            doc="how long each intruder is predicted to keep turning at its estimated rate "
            "(0: straight, as bands-flown)",
            ge=0.0,
            le=600.0,
        )

    prefilter = False
    uses_intruder_turn_rate = True

    def intruder_turns(self, n, k, turn_rate, intruders):
        """Each intruder turning at its track's rate for ``intruder_turn_s`` (also in the
        conflict test; the straight prediction kept too), or None without intruders or turn
        rates."""
        turn_s = self.params.intruder_turn_s
        intruder_turn_rate = intruders["turn_rate"]
        if turn_s <= 0.0 or intruder_turn_rate is None or k == 0:
            return None
        rate = DEFAULT_TURN_RATE if turn_rate is None else turn_rate
        rate = np.broadcast_to(np.asarray(rate, dtype=float), (n,))
        # a track's turn-rate estimate beyond the ownship's own limit is noise
        omega = np.nan_to_num(np.asarray(intruder_turn_rate, dtype=float))
        omega = np.clip(omega, -rate[:, None], rate[:, None])
        return IntruderTurns(rate, omega, turn_s, detects=True, replaces=False)
