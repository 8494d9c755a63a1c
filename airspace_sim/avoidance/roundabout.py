"""Right-of-way band search: an implicit convention every aircraft follows (issue 13).

``"bands"`` resolves every ownship against every intruder, so in a pair both turn, each
flying the whole detour, and in a crowd everyone's escape is blocked by everyone else's.
Here each pair agrees, without talking, on who gives way, from the two velocities alone:

    s = (v_own × v_int) / (|v_own|·|v_int|)   (sine of the angle from own track to theirs)

The ownship *gives way* to an intruder whose track is turned counter-clockwise from its
own (``s > sin(parallel_angle)``: in a converging pair, the intruder crossing from its
right, the rules of the air) and *stands on* against one turned clockwise
(``s < −sin(parallel_angle)``). ``s`` is antisymmetric (``v_i × v_j = −v_j × v_i``), so in
every crossing pair exactly one aircraft gives way; near-parallel pairs (head-on,
overtaking, ``|s| ≤ sin(parallel_angle)``) both give way, as under the rules of the air.
On the converging ring (BlueSky's super conflict) each aircraft gives way to its
neighbours on one side only, and all of them turning right to pass behind the intruder
from their right make the roundabout the centralised plan (:mod:`.oracle`) flies.

A stand-on ownship still resolves against an intruder whose loss of the clear radius
``r_safe·(1 + margin)`` at the current headings is less than ``standon_s`` ahead (the
give-way aircraft may be boxed in, or see the ownship late): a safety net, not the rule.
The band search itself is :func:`~airspace_sim.avoidance.bands.band_search` on the
intruders the ownship resolves against (the ``"bands"`` kernels, unchanged).

How the intruders move while the ownship turns by a candidate ψ (``intruder_turn``):
``"straight"`` as tracked (``"bands"``' reading); ``"same"``: it turns by ψ too, the
implicit coordination of a symmetric scene (everyone offset the same way, the centralised
plan's roundabout): the relative velocity is the tracked one rotated by ψ
(:func:`co_rotated_min_ratio`, band edges in closed form in
:func:`co_rotated_boundaries`); ``"mutual"``: only where the intruder gives way too.
Intruders inside ``standon_s`` are always judged straight.

Recovery (``recover_by_time``): where a side has no clear heading, ``"bands"`` takes the
candidate of the largest minimum CPA distance ratio; this one takes the candidate whose
first loss of the clear radius comes latest (ties: the larger ratio), which leaves the
most time for the picture to change (the others to manoeuvre, the next alert to open a
gap). Angles radians CCW from east, distances metres, times seconds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from airspace_sim import registry
from airspace_sim.avoidance.bands import (
    CLEAR_TOLERANCE,
    band_choice,
    bands_from_ratio,
    exact_boundary_candidates,
    preferred_candidates,
)
from airspace_sim.avoidance.cpa import cpa_min_ratio
from airspace_sim.avoidance.cpa_turning import cpa_min_ratio_turning
from airspace_sim.avoidance.resolvers import BandsResolver, ResolverOutput, _arrays
from airspace_sim.geometry import rotate, wrap_angle
from airspace_sim.parts import param


def give_way(own_velocity, rel_velocity, valid, parallel_angle, intruder=False):
    """(N, K) bool: the ownship gives way to intruder ``k`` (module docstring); with
    ``intruder``, the intruder gives way to the ownship (the same rule from its side).

    own_velocity (N, 2) m/s; rel_velocity (N, K, 2) intruder minus ownship, m/s; valid
    (N, K) bool; parallel_angle rad. False on invalid slots.
    """
    vo = np.asarray(own_velocity, dtype=float)[:, None, :]
    vi = np.asarray(rel_velocity, dtype=float) + vo
    cross = vo[..., 0] * vi[..., 1] - vo[..., 1] * vi[..., 0]
    if intruder:
        cross = -cross
    norm = np.hypot(vo[..., 0], vo[..., 1]) * np.hypot(vi[..., 0], vi[..., 1])
    # a stationary intruder (norm 0) has no track to defer to: give way
    stand_on = cross < -math.sin(parallel_angle) * norm
    return np.asarray(valid, dtype=bool) & ~(stand_on & (norm > 0))


def time_to_loss(rel_position, rel_velocity, radius):
    """Time (s) until the range first falls to ``radius`` (m) at constant velocities.

    rel_position, rel_velocity (..., 2) m, m/s; radius float or (...) m. 0 where already
    inside, ``inf`` where the relative track never comes within ``radius``: the first root
    of ``|r + t·v| = radius``, ``t ≥ 0``. Shape (...).
    """
    r = np.asarray(rel_position, dtype=float)
    v = np.asarray(rel_velocity, dtype=float)
    a = np.einsum("...i,...i->...", v, v)
    b = np.einsum("...i,...i->...", r, v)
    c = np.einsum("...i,...i->...", r, r) - np.asarray(radius, dtype=float) ** 2
    disc = b * b - a * c
    with np.errstate(invalid="ignore", divide="ignore"):
        t = (-b - np.sqrt(np.maximum(disc, 0.0))) / a
    t = np.where((disc >= 0) & (b < 0) & (a > 0), t, np.inf)
    return np.where(c <= 0, 0.0, t)


def candidate_time_to_loss(own_velocity, rel_position, rel_velocity, valid, psi, radius, horizon):
    """(N, C) min over valid intruders of :func:`time_to_loss` with the ownship's heading
    turned by ``psi`` (N, C) rad at once, capped at ``horizon`` s (NaN candidates: −inf).

    own_velocity (N, 2) m/s; rel_position, rel_velocity (N, K, 2) m, m/s; valid (N, K).
    """
    vo = np.asarray(own_velocity, dtype=float)
    r = np.asarray(rel_position, dtype=float)
    vi = np.asarray(rel_velocity, dtype=float) + vo[:, None, :]
    psi = np.asarray(psi, dtype=float)
    turned = rotate(np.broadcast_to(vo[:, None, :], psi.shape + (2,)), np.nan_to_num(psi))
    v_rel = vi[:, None, :, :] - turned[:, :, None, :]  # (N, C, K, 2)
    t = time_to_loss(r[:, None, :, :], v_rel, radius)
    t = np.where(np.asarray(valid, dtype=bool)[:, None, :], t, np.inf)
    t = np.minimum(t.min(axis=-1, initial=np.inf), horizon)
    return np.where(np.isnan(psi), -np.inf, t)


def co_rotated_min_ratio(rel_position, rel_velocity, valid, psi, radius, lookahead_s, rows=64):
    """(N, C) min over valid intruders of CPA distance / ``radius`` over ``[0, T]`` when the
    ownship *and* the intruder both turn by ``psi`` (N, C) rad: the relative velocity is
    ``rel_velocity`` rotated by ψ (its length unchanged). ``inf`` without a valid intruder,
    ``-inf`` for NaN candidates. rel_position, rel_velocity (N, K, 2) m, m/s; valid (N, K);
    radius m; evaluated ``rows`` ownships at a time (memory ~ rows·C·K).
    """
    r = np.asarray(rel_position, dtype=float)
    v0 = np.asarray(rel_velocity, dtype=float)
    valid = np.asarray(valid, dtype=bool)
    psi = np.asarray(psi, dtype=float)
    out = np.full(psi.shape, np.inf)
    speed2 = np.einsum("nki,nki->nk", v0, v0)
    for a in range(0, psi.shape[0], rows):
        sl = slice(a, a + rows)
        v = rotate(v0[sl, None], np.nan_to_num(psi[sl])[:, :, None])  # (n, C, K, 2)
        rv = np.einsum("nki,ncki->nck", r[sl], v)
        with np.errstate(invalid="ignore", divide="ignore"):
            t = np.clip(-rv / speed2[sl, None], 0.0, lookahead_s)
        t = np.where(speed2[sl, None] > 0, t, 0.0)
        d = np.hypot(r[sl, None, :, 0] + t * v[..., 0], r[sl, None, :, 1] + t * v[..., 1])
        d = np.where(valid[sl, None], d / radius, np.inf)
        out[sl] = d.min(axis=-1, initial=np.inf)
    return np.where(np.isnan(psi), -np.inf, out)


def co_rotated_boundaries(rel_position, rel_velocity, valid, radius, lookahead_s):
    """(N, 4K) rad: where the co-rotated CPA distance (:func:`co_rotated_min_ratio`, one
    intruder) crosses ``radius``: the two tangents ``∠v(ψ) = ∠(−r) ± asin(ρ/|r|)`` and the
    two roots of ``|r + T·v(ψ)| = ρ``; NaN where none (inside, invalid, no root)."""
    r = np.asarray(rel_position, dtype=float)
    v0 = np.asarray(rel_velocity, dtype=float)
    dist = np.hypot(r[..., 0], r[..., 1])
    speed = np.hypot(v0[..., 0], v0[..., 1])
    away = np.arctan2(-r[..., 1], -r[..., 0])
    heading = np.arctan2(v0[..., 1], v0[..., 0])
    T = lookahead_s
    with np.errstate(invalid="ignore", divide="ignore"):
        half = np.arcsin(radius / dist)
        cos_end = (radius**2 - dist**2 - (T * speed) ** 2) / (2 * T * dist * speed)
        end = np.arccos(cos_end)
    toward = away + np.pi  # the direction of r
    parts = [away - half, away + half, toward - end, toward + end]
    out = np.stack([wrap_angle(p - heading) for p in parts], axis=-1)  # (N, K, 4)
    ok = (np.asarray(valid, dtype=bool) & (dist > radius) & (speed > 0))[..., None]
    out = np.where(ok & np.isfinite(out), out, np.nan)
    return out.reshape(out.shape[0], -1)


@registry.register("resolver", "bands-roundabout")
class RoundaboutBandsResolver(BandsResolver):
    """``"bands"`` against the intruders this ownship gives way to (module docstring)."""

    @dataclass(frozen=True)
    class Params(BandsResolver.Params):
        parallel_angle: float = param(
            float(np.radians(10.0)),
            unit="rad",
            doc="tracks within this of parallel or opposite: both give way",
            ge=0,
            le=float(np.pi / 2),
        )
        standon_s: float = param(
            30.0,
            unit="s",
            doc="a stand-on ownship resolves too when the loss is this close",
            ge=0,
            le=3600.0,
        )
        recover_by_time: bool = param(
            False, doc="no clear heading on a side: the one whose loss comes latest"
        )
        intruder_turn: str = param(
            "straight",
            doc="how a non-urgent intruder is assumed to move while the ownship turns by ψ: "
            "straight (as tracked), same (it turns by ψ too), mutual (same where it also "
            "gives way)",
            choices=("straight", "same", "mutual"),
        )

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
    ):
        p = self.params
        vo, r, v, valid, mx = _arrays(
            own_velocity, rel_position, rel_velocity, valid, max_heading_change
        )
        radius = p.r_safe * (1.0 + p.margin)
        urgent = valid & (time_to_loss(r, v, radius) <= p.standon_s)
        gives = give_way(vo, v, valid, p.parallel_angle)
        considered = gives | urgent
        modes = self._mode_ratio(vo, r, considered, mode_predictions)
        if p.intruder_turn == "straight" and modes is None:  # bands on the considered ones
            out = super().resolve(
                vo, r, v, considered, mx, turn_rate=turn_rate, committed_side=committed_side
            )
        else:
            co = considered & ~urgent if p.intruder_turn != "straight" else np.zeros_like(valid)
            if p.intruder_turn == "mutual":
                # the intruder gives way to this ownship too (a near-parallel pair)
                co &= give_way(vo, v, valid, p.parallel_angle, intruder=True)
            out = self._co_search(
                vo, r, v, considered & ~co, co, mx, committed_side, modes, turn_rate
            )
        if p.recover_by_time and out.best_blocked is not None:
            out.best_blocked = self._latest_loss(
                vo, r, v, considered, out.candidates, out.first_clear, out.best_blocked
            )
        return out

    def _mode_ratio(self, vo, r, considered, mode_predictions):
        """None, or a function of the candidates (N, C) rad giving a (N, C) ratio every
        candidate must also reach (a mode-aware resolver's judgement of the intruders'
        predicted paths, ``"bands-modes"``); this resolver is not mode-aware."""
        return None

    def _co_search(self, vo, r, v, straight, co, mx, committed_side, modes=None, turn_rate=None):
        """The band search with the ``straight`` intruders as tracked and the ``co`` ones
        turning by the candidate too (:func:`co_rotated_min_ratio`), and with ``modes``
        (:meth:`_mode_ratio`) that ratio as well; the choice, the preference order and the
        side outputs are those of :func:`~airspace_sim.avoidance.bands.band_search`
        (``full=True``). With ``model_turn`` the straight intruders are judged against the
        candidate as flown at ``turn_rate`` (the others as if turned at once)."""
        p = self.params
        n = vo.shape[0]
        radius = p.r_safe * (1.0 + p.margin)
        extra = None
        if p.exact_candidates and r.shape[1] > 0:
            extra = np.concatenate(
                [
                    exact_boundary_candidates(vo, r, v, straight, radius, p.lookahead_s),
                    co_rotated_boundaries(r, v, co, radius, p.lookahead_s),
                ],
                axis=1,
            )
        cand = preferred_candidates(mx, p.resolution, extra, p.left_penalty)
        usable = ~np.isnan(cand)
        safe = np.where(usable, cand, 0.0)
        if p.model_turn and turn_rate is not None:
            ratio = cpa_min_ratio_turning(
                vo, r, v, straight, safe, radius, p.lookahead_s, turn_rate
            )
        else:
            ratio = cpa_min_ratio(vo, r, v, straight, safe, radius, p.lookahead_s)
        ratio = np.minimum(
            ratio,
            co_rotated_min_ratio(r, v, co, safe, radius, p.lookahead_s),
        )
        if modes is not None:
            ratio = np.minimum(ratio, modes(safe))
        ratio = np.where(usable, ratio, -np.inf)
        both = straight | co
        ratio0 = cpa_min_ratio(vo, r, v, both, np.zeros((n, 1)), radius, p.lookahead_s)[:, 0]
        conflict = ~(ratio0 >= 1.0 - CLEAR_TOLERANCE)
        wanted = np.ones((n, 2), dtype=bool)
        if committed_side is not None:
            side = np.broadcast_to(np.asarray(committed_side, dtype=float), (n,))
            wanted = np.stack([side <= 0, side >= 0], axis=1)
        band, first, best = bands_from_ratio(cand, ratio, usable, wanted)
        rows = np.arange(n)
        choice = band_choice(
            first, best, lambda idx: np.where(idx >= 0, ratio[rows, np.maximum(idx, 0)], -np.inf)
        )
        psi = np.where(conflict, cand[rows, choice], 0.0)
        return ResolverOutput(
            psi, conflict, cand, band, min_ratio=ratio, first_clear=first, best_blocked=best
        )

    def _latest_loss(self, vo, r, v, valid, cand, first_clear, best_blocked):
        """``best_blocked`` (n, 2) re-chosen by the latest first loss of the clear radius
        (ties: the ``"bands"`` choice), on the rows and sides where it was asked for."""
        p = self.params
        out = best_blocked.copy()
        rows = np.nonzero((best_blocked >= 0).any(axis=1))[0]
        if rows.size == 0:
            return out
        c = cand[rows]
        t = candidate_time_to_loss(
            vo[rows], r[rows], v[rows], valid[rows], c, p.r_safe * (1 + p.margin), p.lookahead_s
        )
        for col, mask in enumerate((c <= 0, c >= 0)):
            want = best_blocked[rows, col] >= 0
            score = np.where(mask & ~np.isnan(c), t, -np.inf)
            pick = np.argmax(score, axis=1)
            # keep the ratio choice unless a candidate's loss is strictly later
            keep = score[np.arange(rows.size), np.maximum(best_blocked[rows, col], 0)]
            better = score[np.arange(rows.size), pick] > keep
            out[rows, col] = np.where(want & better, pick, best_blocked[rows, col])
        return out
