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
    row_of = np.full(int(ids.max(initial=-1)) + 1, -1, dtype=np.int64)
    row_of[ids] = np.arange(n)
    found = []
    for i in np.flatnonzero(rows):
        for k in np.flatnonzero(valid[i] & (intruder_ids[i] >= 0)):
            target = int(intruder_ids[i, k])
            j = int(row_of[target]) if target < row_of.size else -1
            if j <= i or not rows[j]:
                continue
            back = np.flatnonzero(valid[j] & (intruder_ids[j] == ids[i]))
            if back.size:
                found.append((urgency[i, k], i, k, j, int(back[0])))
    found.sort(key=lambda f: f[0])
    used = np.zeros(n, dtype=bool)
    out = []
    for _, i, k, j, l in found:
        if not (used[i] or used[j]):
            used[i] = used[j] = True
            out.append((i, k, j, l))
    cols = np.array(out, dtype=np.int64).reshape(-1, 4)
    return cols[:, 0], cols[:, 1], cols[:, 2], cols[:, 3]


def mutual_ratio(
    own_velocity, rel_position, rel_velocity, own_candidates, other_candidates, radius,
    lookahead_s, own_turn_rate, other_turn_rate,
):  # fmt: skip
    """(A, B) minimum distance / ``radius`` over ``[0, lookahead_s]`` of two aircraft, the
    first flying ``own_candidates`` (A,) rad and the second ``other_candidates`` (B,) rad,
    each turning at its own rate (rad/s) to its new heading, then straight.

    own_velocity (2,) m/s; rel_position, rel_velocity (2,) the second minus the first, m and
    m/s; radius m. NaN candidates give NaN."""
    other = np.asarray(other_candidates, dtype=float)
    b = other.size
    rate = float(other_turn_rate)
    turn = np.where(np.isnan(other), 0.0, other)
    out = cpa_min_ratio_intruder_turning(
        np.broadcast_to(np.asarray(own_velocity, dtype=float), (b, 2)),
        np.broadcast_to(np.asarray(rel_position, dtype=float), (b, 1, 2)),
        np.broadcast_to(np.asarray(rel_velocity, dtype=float), (b, 1, 2)),
        np.ones((b, 1), dtype=bool),
        np.broadcast_to(np.asarray(own_candidates, dtype=float), (b, np.size(own_candidates))),
        radius,
        lookahead_s,
        np.full(b, float(own_turn_rate)),
        (np.sign(turn) * rate)[:, None],
        (np.abs(turn) / rate)[:, None],
    )
    return np.where(np.isnan(other)[:, None], np.nan, out).T


def pair_choice(others_i, others_j, mutual, own_candidates, other_candidates):
    """``(a, b, score)``: the pair's pick of the module docstring and its score; ``others_i``
    (A,), ``others_j`` (B,), ``mutual`` (A, B) ratios (NaN or −inf: unusable), candidates
    (A,), (B,) rad."""
    score = np.minimum(np.minimum(others_i[:, None], others_j[None, :]), mutual)
    score = np.where(np.isnan(score), -np.inf, score)
    clear = score >= 1.0 - CLEAR_TOLERANCE
    if clear.any():
        turn = np.abs(own_candidates)[:, None] + np.abs(other_candidates)[None, :]
        flat = np.argmin(np.where(clear, turn, np.inf))
    else:
        flat = np.argmax(score)
    a, b = np.unravel_index(flat, score.shape)
    return int(a), int(b), float(score[a, b])


def pair_score(others_i, others_j, mutual, a, b):
    """The pair's score at candidates ``a``, ``b`` (−inf where either is −1)."""
    if a < 0 or b < 0:
        return -np.inf
    s = min(others_i[a], others_j[b], mutual[a, b])
    return -np.inf if np.isnan(s) else float(s)


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
        best = best.copy()
        safe = np.where(usable, cand, np.nan)
        for i, k, j, l in zip(*mutual_pairs(boxed, aircraft_ids, intruder_ids, valid, urgency)):
            others = []
            for row, slot in ((i, k), (j, l)):
                alone = valid[row].copy()
                alone[slot] = False
                ratio = cpa_min_ratio_turning(
                    vo[row : row + 1], r[row : row + 1], v[row : row + 1], alone[None],
                    np.where(usable[row], cand[row], 0.0)[None], radius[row : row + 1],
                    self.params.lookahead_s, rate[row : row + 1],
                )[0]  # fmt: skip
                others.append(np.where(usable[row], ratio, -np.inf))
            mutual = mutual_ratio(
                vo[i], r[i, k], v[i, k], safe[i], safe[j], radius[i, k], self.params.lookahead_s,
                rate[i], rate[j],
            )  # fmt: skip
            col_i, col_j = int(side[i] > 0), int(side[j] > 0)
            a, b, score = pair_choice(others[0], others[1], mutual, safe[i], safe[j])
            now = pair_score(others[0], others[1], mutual, best[i, col_i], best[j, col_j])
            if score > now + self.params.pair_margin and score >= self.params.pair_min_score:
                best[i, col_i], best[j, col_j] = a, b
        return best
