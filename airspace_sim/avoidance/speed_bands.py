"""``"bands-flown-speed"``: the as-flown band search with speed as a second control.

Heading-only resolution has one way out of a conflict: turn. An ownship that may change its
ground speed (``AircraftSpec.speed_range`` > 0) has another, as DAIDALUS' speed bands and
BlueSky's MVP (heading and speed) give it. For an ownship in conflict every candidate heading ψ
of ``"bands-flown"`` is also judged at target speeds spread evenly over the ownship's limits,
each flown as it would be: turning at the turn rate until ψ and accelerating at the
acceleration limit until the target speed, then straight
(:func:`~airspace_sim.avoidance.cpa_speed.cpa_min_ratio_speed`; intruders straight). A
candidate keeps its current speed when that is clear as flown; else it takes the clear speed
nearest the current one; else the speed of largest as-flown ratio, when that beats the
current speed's by more than ``speed_margin``. Every rule of ``"bands-flown"`` (open sides,
fallbacks for boxed ownships) then runs on those ratios, so a heading that is clear only at
another speed counts as clear, and the first clear heading in the preference order may be
ψ = 0 at another speed: a speed change instead of a turn. With ``speed_when_boxed`` only an
ownship with no heading clear as flown at its current speed is offered other speeds.

The CDA policy flies the speed of the heading it commits (``candidate_speed``), keeps it while
the aircraft flies the advice or a held heading, and lets the aircraft return to its own speed
once it flies its autopilot again (:class:`~airspace_sim.world.policy.AvoidancePolicy`).
Detection is ``"bands"``' straight CPA test at the current heading and speed, so the world's
prefilter holds. Distances m, speeds m/s, accelerations m/s², angles rad CCW positive.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from airspace_sim import registry
from airspace_sim.avoidance.bands import CLEAR_TOLERANCE
from airspace_sim.avoidance.cpa_speed import cpa_min_ratio_speed
from airspace_sim.avoidance.flown_bands import (
    DEFAULT_TURN_RATE,
    FlownBandsResolver,
    radius_rows,
)
from airspace_sim.parts import param


def speed_grid(limits, steps):
    """(N, 2·steps + 1) target speeds, m/s, evenly from each row's lowest to highest speed
    (``limits`` (N, 2) m/s)."""
    limits = np.asarray(limits, dtype=float)
    frac = np.linspace(0.0, 1.0, 2 * int(steps) + 1)
    return limits[:, :1] + (limits[:, 1:] - limits[:, :1]) * frac[None, :]


def speed_choice(current_ratio, ratio, grid, current_speed, margin):
    """``(ratio (N, C), speed (N, C))``: per candidate heading, the as-flown ratio and ground
    speed it is flown with (module docstring).

    current_ratio (N, C) the candidates' as-flown ratio at the current speed; ratio (N, C, P)
    at the target speeds ``grid`` (N, P) m/s; current_speed (N,) m/s; margin ≥ 0.
    """
    n, c = current_ratio.shape
    here = np.broadcast_to(np.asarray(current_speed, dtype=float)[:, None], (n, c))
    keep = current_ratio >= 1.0 - CLEAR_TOLERANCE
    clear = ratio >= 1.0 - CLEAR_TOLERANCE
    # the clear speed nearest the current one
    gap = np.abs(grid - np.asarray(current_speed, dtype=float)[:, None])[:, None, :]
    nearest = np.argmin(np.where(clear, gap, np.inf), axis=2)
    has_clear = clear.any(axis=2)
    top = np.argmax(np.where(np.isnan(ratio), -np.inf, ratio), axis=2)
    pick = np.where(has_clear, nearest, top)
    picked = np.take_along_axis(ratio, pick[..., None], axis=2)[..., 0]
    better = has_clear | (picked > current_ratio + margin)
    use = ~keep & better & np.isfinite(current_ratio)
    speeds = np.broadcast_to(grid[:, None, :], ratio.shape)
    chosen = np.take_along_axis(speeds, pick[..., None], axis=2)[..., 0]
    return np.where(use, picked, current_ratio), np.where(use, chosen, here)


@registry.register("resolver", "bands-flown-speed")
class SpeedFlownBandsResolver(FlownBandsResolver):
    """``"bands-flown"`` that may also change the ownship's speed (module docstring)."""

    @dataclass(frozen=True)
    class Params(FlownBandsResolver.Params):
        speed_steps: int = param(
            2,
            doc="target speeds judged on each side of the middle of the ownship's speed "
            "limits (2·speed_steps + 1 in all, the limits included)",
            ge=1,
            le=20,
        )
        speed_margin: float = param(
            0.05,
            doc="where no speed is clear as flown, the as-flown ratio gain another speed "
            "needs over the current one to be advised",
            ge=0.0,
        )
        speed_when_boxed: bool = param(
            False,
            doc="judge other speeds only for an ownship with no heading clear as flown at its "
            "current speed (speed as the boxed ownship's way out; a heading change first)",
        )

    advises_speed = True

    def speed_axis(
        self, flown, conflict, vo, r, v, valid, safe, usable, radius, turn_rate, limits, accel
    ):
        """``(ratio (N, C), speed (N, C) m/s)`` of :func:`speed_choice` on the rows in
        conflict whose limits allow a speed change; the current speed elsewhere."""
        n = vo.shape[0]
        current = np.hypot(vo[:, 0], vo[:, 1])
        speeds = np.broadcast_to(current[:, None], flown.shape).copy()
        if limits is None or accel is None or r.shape[1] == 0:
            return flown, speeds
        limits = np.asarray(limits, dtype=float).reshape(n, 2)
        wanted = conflict & (limits[:, 1] > limits[:, 0])
        if self.params.speed_when_boxed:
            wanted &= ~np.any(np.where(usable, flown, -np.inf) >= 1.0 - CLEAR_TOLERANCE, axis=1)
        rows = np.flatnonzero(wanted)
        if rows.size == 0:
            return flown, speeds
        rate = DEFAULT_TURN_RATE if turn_rate is None else turn_rate
        rate = np.broadcast_to(np.asarray(rate, dtype=float), (n,))[rows]
        acc = np.broadcast_to(np.asarray(accel, dtype=float), (n,))[rows]
        grid = speed_grid(limits[rows], self.params.speed_steps)
        ratio = cpa_min_ratio_speed(
            vo[rows],
            r[rows],
            v[rows],
            valid[rows],
            safe[rows],
            grid,
            radius_rows(radius, rows),
            self.params.lookahead_s,
            rate,
            acc,
        )
        ratio = np.where(usable[rows][..., None], ratio, -np.inf)
        got, chosen = speed_choice(
            flown[rows], ratio, grid, current[rows], self.params.speed_margin
        )
        out = flown.copy()
        out[rows] = got
        speeds[rows] = chosen
        return out, speeds
