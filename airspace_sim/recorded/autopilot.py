"""The ``"recorded"`` autopilot: aircraft that fly their recorded trajectories in the world.

Each member carries a :class:`Recording` (``AircraftSpec.recording``: a
:class:`~airspace_sim.recorded.flights.Flight` and the flight time at world time 0). The
autopilot is kinematic (:attr:`airspace_sim.parts.Autopilot.kinematic`): at every world
step it gives each member the velocity that takes its body from where it is to the
recording's position one step later (cubic Hermite between samples, as
:meth:`Flight.sample`), so the pymunk bodies follow the data to rounding and collide, are
surveyed and tracked like any other aircraft. A member is in the
world from the first step at or after its first sample to the last step at or before its
last one, and out of it during gaps longer than the flight's ``max_gap_s``. No resolver or
agent steers it.

All members are sampled together by a :class:`~airspace_sim.recorded.flights.Timeline`
(concatenated arrays, one forward-only pointer per flight): a step costs O(k) array work,
not a Python call per flight.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from airspace_sim.errors import UserError
from airspace_sim.parts import Autopilot, NoParams
from airspace_sim.recorded.flights import Flight, Timeline
from airspace_sim.registry import register


@dataclass(frozen=True, eq=False)
class Recording:
    """What one recorded aircraft flies: ``flight`` from flight time ``offset_s`` (s,
    the flight's ``t_s`` at world time 0) on."""

    flight: Flight
    offset_s: float = 0.0


@register("autopilot", "recorded")
class RecordedAutopilot(Autopilot):
    """Flies each member along its :class:`Recording` (module docstring)."""

    Params = NoParams
    kinematic = True

    def __init__(self, members, specs, context, params=None):
        self.members = np.asarray(members, dtype=np.int64)
        recordings = []
        for s in specs:
            rec = getattr(s, "recording", None)
            if not isinstance(rec, Recording):
                raise UserError(
                    f"aircraft {s.id!r}: autopilot 'recorded' needs a recording (aircraft "
                    f"come from a scenario's [recorded] section or `airspace-sim replay`)"
                )
            recordings.append(rec)
        self.recordings = recordings
        self.dt = float(context.dt)
        self._samples = Timeline([r.flight for r in recordings], [r.offset_s for r in recordings])
        self._cache = (None, None)
        self.modes = None

    def _at(self, step: int):
        if self._cache[0] != step:
            self._cache = (step, self._samples.at(step * self.dt))
        return self._cache[1]

    def presence(self, state):
        return self._at(state.step)

    def velocity(self, state):
        present, pos, vel = self._at(state.step + 1)
        here = state.positions[self.members]
        # the chord to the next recorded position: the body lands on the recording, so
        # rounding never accumulates; a member about to leave keeps its recorded velocity
        return np.where(present[:, None], (pos - here) / self.dt, vel)

    def turn_rate(self, state):
        return np.zeros(self.members.size)

    def desired_heading(self, state):
        return np.full(self.members.size, np.nan)

    def after_step(self, state):
        return np.zeros(self.members.size, dtype=bool)

    def progress(self, state):
        return np.full(self.members.size, np.nan)
