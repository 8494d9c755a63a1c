"""Reciprocal band search: implicit coordination for aircraft that all run the same rule.

``"bands"`` judges each candidate heading as if the intruder kept its velocity. When the
intruder runs the same resolver it turns too, and two ownships each taking the whole
avoidance fly twice the detour they need (and, turning the same way at once, can turn into
each other's escape). The reciprocal reading (van den Berg et al. 2011, ORCA's "each takes
half the responsibility") assumes the intruder makes the mirror of the ownship's change:
with a share ``s`` of the avoidance, candidate velocity ``v_c`` counts in the relative test
as ``v_own + (v_c − v_own)/s``. For a heading change ψ of an ownship at speed ``|v_own|``
that is exactly the band search of an ownship with velocity ``v_own / s`` against an
intruder velocity ``v_int + v_own (1/s − 1)``, relative velocity unchanged at ψ = 0
(:func:`~airspace_sim.avoidance.bands.band_search` takes ``rel_velocity`` and the own
velocity, so the kernels are reused untouched). ``share = 1`` is ``"bands"``; ``0.5`` the
symmetric reciprocal rule. Only sound when intruders do run it (cooperative traffic).
"""

from __future__ import annotations

from dataclasses import dataclass

from airspace_sim.avoidance.resolvers import BandsResolver
from airspace_sim.parts import param


class ReciprocalBandsResolver(BandsResolver):
    """``"bands"`` with the reciprocal share of the avoidance (module docstring)."""

    @dataclass(frozen=True)
    class Params(BandsResolver.Params):
        share: float = param(
            0.5, doc="fraction of the avoidance this ownship takes (1: bands)", gt=0, le=1
        )

    def _search(self, vo, r, v, valid, mx, r_safe, turn_rate=None, committed_side=None):
        # the ownship's velocity scaled by 1/share, relative velocities as tracked
        return super()._search(
            vo / self.params.share, r, v, valid, mx, r_safe, turn_rate, committed_side
        )
