"""``"bands-flown-paired"``: two boxed ownships in conflict with each other pick their headings
together (explicit pairwise coordination).

Every rule of ``"bands-flown"`` decides on one ownship's picture, predicting each intruder
straight. Traced on ``dense_random`` (``docs/resolvers.md``, seventh and eleventh parts), the
losses left are pairs of aircraft in conflict with each other and each *boxed* (committed to
a side, no heading clear as flown on either), each squeezed between the other and a third
aircraft: each holds the heading that is best against everyone with the other flying
straight, most often ψ ≈ 0 at a ratio ≈ 0.9, while a turn by both (often both to the same
side of their own heading) would have cleared them. Neither can find it alone: the other's
turn is not in its picture.

Here such pairs are resolved from one shared evaluation, as ACAS X coordinates the senses
of two equipped aircraft (its resolution advisories are exchanged over a data link; this
rule likewise assumes that the pair's resolvers see each other's rows, i.e. cooperative,
equipped traffic running the same resolver). For a pair of boxed rows ``(i, j)`` that
track each other:

- ``others_i[a]``: the as-flown minimum CPA ratio of ``i``'s candidate ``a`` against its
  intruders except ``j`` (third aircraft straight, as everywhere in ``"bands-flown"``), and
  ``others_j[b]`` likewise;
- ``mutual[a, b]``: the minimum distance ratio of ``i`` flying ``a`` and ``j`` flying ``b``,
  both as flown (turning at its own rate to the heading, then straight), from ``i``'s track
  of ``j`` (:func:`~airspace_sim.avoidance.cpa_intruder_turning.cpa_min_ratio_intruder_turning`
  with the intruder's turn set by ``b``);
- the pair's score ``min(others_i[a], others_j[b], mutual[a, b])``. If some ``(a, b)`` is
  clear (score ≥ 1), the clear one of smallest ``|ψ_a| + |ψ_b|``; else the one of largest
  score. It replaces the two rows' own boxed picks when it beats their score, judged the
  same way, by more than ``pair_margin`` (and, with ``pair_min_score``, only when its score
  is at least that: 1 keeps the joint pick to pairs it clears).

Rows are paired greedily, most urgent first (smallest straight CPA ratio of the pair at
ψ = 0, from the lower row's track), each row at most once. The picks are reported as each
row's best blocked candidate on its committed side, which the CDA policy flies while it stays
boxed (the side label kept, as with ``boxed_best_both``). Everything else is
``"bands-flown"``'s. Measured on ``dense_random`` and the rings (``docs/resolvers.md``,
twelfth part), it loses no fewer pairs than ``"bands-flown"``: the third aircraft caps the
pair's best score where each row's own pick was. Distances m, times s, angles rad CCW
positive.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from airspace_sim import registry
from airspace_sim.avoidance.bands import CLEAR_TOLERANCE
from airspace_sim.avoidance.cpa import cpa_pair_ratios
from airspace_sim.avoidance.cpa_intruder_turning import cpa_min_ratio_intruder_turning
from airspace_sim.avoidance.cpa_turning import cpa_min_ratio_turning
from airspace_sim.avoidance.flown_bands import (
    DEFAULT_TURN_RATE,
    FlownBandsResolver,
)
from airspace_sim.parts import param


def mutual_pairs(rows, aircraft_ids, intruder_ids, valid, urgency):
    """Disjoint pairs of ``rows`` that track each other, most urgent first.

    rows (N,) bool, the rows that may be paired; aircraft_ids (N,) int, each row's aircraft;
    intruder_ids (N, K) int, each slot's aircraft (−1: none); valid (N, K) bool; urgency
    (N, K), smaller is more urgent (the pair's key is the lower row's slot). Returns
    ``(i, k, j, l)`` (P,) int arrays each: row ``i``'s slot ``k`` is row ``j``'s aircraft
    and row ``j``'s slot ``l`` row ``i``'s, with ``i < j``.
    """
    n = aircraft_ids.shape[0]
    ids = np.asarray(aircraft_ids, dtype=np.int64)
    intruder_ids = np.asarray(intruder_ids, dtype=np.int64)
    row_of = np.full(int(max(ids.max(initial=-1), intruder_ids.max(initial=-1))) + 1, -1)
    row_of[ids] = np.arange(n)
    partner = np.where(valid & (intruder_ids >= 0), row_of[np.maximum(intruder_ids, 0)], -1)
    ii, kk = np.nonzero(rows[:, None] & (partner > np.arange(n)[:, None]))
    jj = partner[ii, kk]
    keep = rows[jj]
    ii, kk, jj = ii[keep], kk[keep], jj[keep]
    back = valid[jj] & (intruder_ids[jj] == ids[ii][:, None])  # (M, K): j's slot of i
    has = back.any(axis=1)
    ii, kk, jj, ll = ii[has], kk[has], jj[has], np.argmax(back[has], axis=1)
    # greedy matching, most urgent first: sequential by nature, over the few candidate pairs
    used = np.zeros(n, dtype=bool)
    take = []
    for m in np.argsort(urgency[ii, kk], kind="stable"):
        if not (used[ii[m]] or used[jj[m]]):
            used[ii[m]] = used[jj[m]] = True
            take.append(m)
    take = np.array(take, dtype=np.int64)
    return ii[take], kk[take], jj[take], ll[take]


def mutual_ratio(
    own_velocity, rel_position, rel_velocity, own_candidates, other_candidates, radius,
    lookahead_s, own_turn_rate, other_turn_rate,
):  # fmt: skip
    """(P, A, B) minimum distance / ``radius`` over ``[0, lookahead_s]`` of P pairs of
    aircraft, the first flying ``own_candidates`` (P, A) rad and the second
    ``other_candidates`` (P, B) rad, each turning at its own rate (``own_turn_rate``,
    ``other_turn_rate`` (P,) rad/s) to its new heading, then straight.

    own_velocity (P, 2) m/s; rel_position, rel_velocity (P, 2) the second minus the first, m
    and m/s; radius (P,) m. NaN candidates give NaN. One kernel call, a row per (pair, b)."""
    other = np.asarray(other_candidates, dtype=float)
    own = np.asarray(own_candidates, dtype=float)
    p, b = other.shape
    rep = lambda a: np.repeat(np.asarray(a, dtype=float), b, axis=0)  # noqa: E731
    rate = rep(other_turn_rate)
    turn = np.where(np.isnan(other), 0.0, other).reshape(p * b)
    out = cpa_min_ratio_intruder_turning(
        rep(own_velocity),
        rep(rel_position)[:, None, :],
        rep(rel_velocity)[:, None, :],
        np.ones((p * b, 1), dtype=bool),
        rep(own),
        rep(radius)[:, None],
        lookahead_s,
        rep(own_turn_rate),
        (np.sign(turn) * rate)[:, None],
        (np.abs(turn) / rate)[:, None],
    ).reshape(p, b, own.shape[1])
    return np.where(np.isnan(other)[:, :, None], np.nan, out).transpose(0, 2, 1)


def pair_choice(others_i, others_j, mutual, own_candidates, other_candidates):
    """``(a (P,), b (P,), score (P,))``: each pair's pick of the module docstring and its
    score; ``others_i`` (P, A), ``others_j`` (P, B), ``mutual`` (P, A, B) ratios (NaN or
    −inf: unusable), candidates (P, A), (P, B) rad."""
    score = pair_scores(others_i, others_j, mutual)
    p, a_n, b_n = score.shape
    clear = score >= 1.0 - CLEAR_TOLERANCE
    turn = np.abs(own_candidates)[:, :, None] + np.abs(other_candidates)[:, None, :]
    smallest = np.argmin(np.where(clear, turn, np.inf).reshape(p, -1), axis=1)
    largest = np.argmax(score.reshape(p, -1), axis=1)
    flat = np.where(clear.any(axis=(1, 2)), smallest, largest)
    a, b = np.unravel_index(flat, (a_n, b_n))
    return a, b, score.reshape(p, -1)[np.arange(p), flat]


def pair_scores(others_i, others_j, mutual):
    """(P, A, B) the pairs' scores ``min(others_i[a], others_j[b], mutual[a, b])`` (−inf
    where any is NaN)."""
    score = np.minimum(np.minimum(others_i[:, :, None], others_j[:, None, :]), mutual)
    return np.where(np.isnan(score), -np.inf, score)


@registry.register("resolver", "bands-flown-paired")
class PairedFlownBandsResolver(FlownBandsResolver):
    """``"bands-flown"`` whose boxed pairs pick their headings together (module docstring)."""

    @dataclass(frozen=True)
    class Params(FlownBandsResolver.Params):
        pair_margin: float = param(
            0.05,
            doc="the pair's joint pick replaces the two rows' own boxed picks when its score "
            "(minimum as-flown ratio) beats theirs by more than this",
            ge=0.0,
        )
        pair_min_score: float = param(
            0.0,
            doc="the joint pick replaces the rows' own picks only when its score is at least "
            "this (1: only a pick that clears the pair; 0: whenever it beats them)",
            ge=0.0,
        )

    uses_aircraft_ids = True

    def coordinate(self, best, boxed, cand, usable, committed_side, geometry, ids):
        """``best`` (N, 2) with each boxed pair's joint pick on both rows' committed sides
        (``boxed`` (N,) bool; ``geometry`` ``(vo, r, v, valid, radius, turn_rate)`` as given
        to :meth:`resolve`; ``ids`` ``(aircraft_ids (N,), intruder_ids (N, K))``)."""
        vo, r, v, valid, radius, turn_rate = geometry
        n = vo.shape[0]
        rate = DEFAULT_TURN_RATE if turn_rate is None else turn_rate
        rate = np.broadcast_to(np.asarray(rate, dtype=float), (n,))
        # the pair's turns are flown at finite rates; a row that turns at once is left alone
        boxed = boxed & np.isfinite(rate) & (rate > 0.0)
        if boxed.sum() < 2:
            return best
        aircraft_ids, intruder_ids = ids
        radius = np.broadcast_to(np.asarray(radius, dtype=float), valid.shape)
        urgency = cpa_pair_ratios(
            vo, r, v, valid, np.zeros((n, 1)), radius, self.params.lookahead_s
        )[:, :, 0]
        side = np.broadcast_to(np.asarray(committed_side, dtype=float), (n,))
        i, k, j, l = mutual_pairs(boxed, aircraft_ids, intruder_ids, valid, urgency)
        if i.size == 0:
            return best
        p = i.size
        safe = np.where(usable, cand, np.nan)
        # each row of a pair against its intruders but the other, as flown: one kernel call
        rows, slots = np.concatenate([i, j]), np.concatenate([k, l])
        alone = valid[rows].copy()
        alone[np.arange(2 * p), slots] = False
        others = cpa_min_ratio_turning(
            vo[rows], r[rows], v[rows], alone, np.where(usable[rows], cand[rows], 0.0),
            radius[rows], self.params.lookahead_s, rate[rows],
        )  # fmt: skip
        others = np.where(usable[rows], others, -np.inf)
        others_i, others_j = others[:p], others[p:]
        mutual = mutual_ratio(
            vo[i], r[i, k], v[i, k], safe[i], safe[j], radius[i, k], self.params.lookahead_s,
            rate[i], rate[j],
        )  # fmt: skip
        a, b, score = pair_choice(others_i, others_j, mutual, safe[i], safe[j])
        col_i, col_j = (side[i] > 0).astype(np.int64), (side[j] > 0).astype(np.int64)
        now_a, now_b = best[i, col_i], best[j, col_j]
        # the rows' own picks scored the same way (−inf where a row has none)
        now = pair_scores(others_i, others_j, mutual)[
            np.arange(p), np.maximum(now_a, 0), np.maximum(now_b, 0)
        ]
        now = np.where((now_a >= 0) & (now_b >= 0), now, -np.inf)
        swap = (score > now + self.params.pair_margin) & (score >= self.params.pair_min_score)
        best = best.copy()
        best[i[swap], col_i[swap]] = a[swap]
        best[j[swap], col_j[swap]] = b[swap]
        return best
