"""The ``"recorded"`` autopilot: aircraft that fly their recorded trajectories in the world.

Each member carries a :class:`Recording` (``AircraftSpec.recording``: a
:class:`~airspace_sim.recorded.flights.Flight` and the flight time at world time 0). The
autopilot is kinematic (:attr:`airspace_sim.parts.Autopilot.kinematic`): at every world
step it gives each member the velocity that takes its body from where it is to the
recording's position one step later (cubic Hermite between samples,
:func:`~airspace_sim.recorded.flights.hermite`), so the pymunk bodies follow the data to
rounding and collide, are surveyed and tracked like any other aircraft. A member is in the
world from the first step at or after its first sample to the last step at or before its
last one, and out of it during gaps longer than the flight's ``max_gap_s``. No resolver or
agent steers it.

All members are sampled together from concatenated arrays with one pointer per flight that
only moves forward (world time only grows): a step costs O(k), not a Python call per flight.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from airspace_sim.errors import UserError
from airspace_sim.parts import Autopilot, NoParams
from airspace_sim.recorded.flights import Flight, hermite
from airspace_sim.registry import register


@dataclass(frozen=True, eq=False)
class Recording:
    """What one recorded aircraft flies: ``flight`` from flight time ``offset_s`` (s,
    the flight's ``t_s`` at world time 0) on."""

    flight: Flight
    offset_s: float = 0.0


class _Samples:
    """k flights' samples concatenated, in world time, with a forward-only segment pointer."""

    def __init__(self, recordings: list[Recording]):
        flights = [r.flight for r in recordings]
        n = np.array([len(f) for f in flights], dtype=np.int64)
        self.first = np.concatenate([[0], np.cumsum(n)[:-1]]).astype(np.int64)
        self.last = self.first + n - 1
        offsets = np.repeat([r.offset_s for r in recordings], n)
        cat = lambda name: np.concatenate([getattr(f, name) for f in flights])  # noqa: E731
        self.t = cat("t_s") - offsets
        self.x, self.y, self.vx, self.vy = cat("x_m"), cat("y_m"), cat("vx"), cat("vy")
        self.max_gap = np.array([f.max_gap_s for f in flights], dtype=float)
        self.ptr = None

    def _seek(self, t: float) -> None:
        """Move each pointer to the segment holding ``t`` (the last one after the end)."""
        if self.ptr is None:  # first call: binary search per flight
            self.ptr = np.array(
                [
                    a
                    + max(
                        0, min(int(np.searchsorted(self.t[a : b + 1], t, "right")) - 1, b - a - 1)
                    )
                    for a, b in zip(self.first, self.last)
                ],
                dtype=np.int64,
            )
        while True:
            move = (self.ptr < self.last - 1) & (self.t[np.minimum(self.ptr + 1, self.last)] <= t)
            if not move.any():
                return
            self.ptr += move

    def at(self, t: float):
        """``(present (k,) bool, positions (k, 2) m, velocities (k, 2) m/s)`` at world
        time ``t`` s; positions and velocities are the recording's wherever it has two
        samples around ``t`` (held at the ends)."""
        self._seek(t)
        i = self.ptr
        j = i + 1
        t0, t1 = self.t[i], self.t[j]
        on_sample = (t == t0) | (t == t1)  # the edges of a gap have data
        inside = (t >= self.t[self.first]) & (t <= self.t[self.last])
        present = inside & ((t1 - t0 <= self.max_gap) | on_sample)
        x, vx = hermite(t, t0, t1, self.x[i], self.x[j], self.vx[i], self.vx[j])
        y, vy = hermite(t, t0, t1, self.y[i], self.y[j], self.vy[i], self.vy[j])
        return present, np.stack([x, y], axis=1), np.stack([vx, vy], axis=1)


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
        self._samples = _Samples(recordings)
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
