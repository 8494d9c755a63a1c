"""Built-in autopilots: what each aircraft flies when nobody (resolver, agent) overrides it.

An autopilot drives a *group* of aircraft at once (all aircraft with the same autopilot
name), with arrays, never one Python object per aircraft in the step loop. Registered with
:func:`airspace_sim.registry.register` as ``"straight"``, ``"route"`` and ``"markov"``; each
is a class fitting :class:`airspace_sim.parts.Autopilot` (methods, shapes, units and the
capabilities ``has_plan``, ``has_modes``; constructed as ``cls(members, specs, context,
params)``). ``state`` is a :class:`FlightState` of the *whole* world; use ``members`` to
index it. All angles radians CCW from east, distances metres, times seconds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from airspace_sim.dynamics.markov import mode_cdf, next_modes
from airspace_sim.dynamics.presets import Preset
from airspace_sim.geometry import wrap_angle
from airspace_sim.parts import Autopilot, NoParams
from airspace_sim.registry import register
from airspace_sim.world import streams
from airspace_sim.world.flight import route_turns


@dataclass
class FlightState:
    """The world's true kinematic state, read-only for autopilots (N aircraft)."""

    positions: np.ndarray  #: (N, 2) m
    headings: np.ndarray  #: (N,) rad
    speeds: np.ndarray  #: (N,) m/s
    max_turn_rate: np.ndarray  #: (N,) rad/s
    dt: float  #: s
    step: int  #: index of the step about to be flown (turn_rate) or just flown (after_step)


@dataclass
class AutopilotContext:
    """What an autopilot may need besides its aircraft."""

    dt: float  #: world step, s
    preset: Preset  #: dynamics preset at the world's dt (Markov chain, turn rates)
    keys: np.ndarray  #: (N,) uint64 per-aircraft random keys (see :mod:`.streams`)
    start_positions: np.ndarray  #: (N, 2) m


def _toward(target_heading, state, members):
    h = state.headings[members]
    lim = state.max_turn_rate[members]
    return np.clip(wrap_angle(target_heading - h) / state.dt, -lim, lim)


@dataclass
class _Legs:
    """What a :class:`RouteAutopilot` derives from ``index`` and ``done`` (k members)."""

    w: np.ndarray  #: (k,) int, waypoint column of the current leg
    target: np.ndarray  #: (k, 2) m, the waypoint flown to
    start: np.ndarray  #: (k, 2) m, where the leg starts
    leg: np.ndarray  #: (k, 2) m, target − start
    length: np.ndarray  #: (k,) m
    hold: np.ndarray  #: (k,) bool, no waypoint ahead: hold the initial heading
    ahead: np.ndarray  #: (k,) bool, a waypoint ahead
    tail: np.ndarray  #: (k,) m, route length from the target waypoint to the last one


@register("autopilot", "straight")
class StraightAutopilot(Autopilot):
    """Holds the initial heading (and turns back to it after an avoidance manoeuvre)."""

    Params = NoParams
    has_plan = True

    def __init__(self, members, specs, context: AutopilotContext, params=None):
        self.members = np.asarray(members, dtype=np.int64)
        self.heading = np.radians([s.heading_deg for s in specs]).astype(float)
        self.start = context.start_positions[self.members].copy()
        self.modes = None

    def desired_heading(self, state):
        return self.heading

    def turn_rate(self, state):
        return _toward(self.heading, state, self.members)

    def after_step(self, state):
        return np.zeros(self.members.size, dtype=bool)

    def progress(self, state):
        d = state.positions[self.members] - self.start
        return d[:, 0] * np.cos(self.heading) + d[:, 1] * np.sin(self.heading)


@register("autopilot", "route")
class RouteAutopilot(Autopilot):
    """Flies direct to each waypoint in turn, within the turn-rate limit.

    A waypoint is reached when the aircraft is within one step's travel of it or has passed
    abeam of it (on the far side of the line through it perpendicular to the leg). After the
    last waypoint the aircraft has *finished* and leaves the world. With no waypoints it
    behaves like ``"straight"``.
    """

    Params = NoParams
    has_plan = True

    def __init__(self, members, specs, context: AutopilotContext, params=None):
        self.members = m = np.asarray(members, dtype=np.int64)
        n = m.size
        self.count = np.array([len(s.waypoints) for s in specs], dtype=np.int64)
        W = max(int(self.count.max(initial=0)), 1)
        self.wp = np.zeros((n, W, 2))
        for a, s in enumerate(specs):
            if s.waypoints:
                self.wp[a, : len(s.waypoints)] = np.asarray(s.waypoints, dtype=float)
        self.start = context.start_positions[m].copy()
        self.heading0 = np.radians([s.heading_deg for s in specs]).astype(float)
        self.index = np.zeros(n, dtype=np.int64)
        # prev[a, w]: where leg w starts (the start position for the first leg)
        self.prev = np.concatenate([self.start[:, None, :], self.wp[:, :-1]], axis=1)
        leg = np.linalg.norm(self.wp - self.prev, axis=-1)  # (n, W)
        leg[np.arange(W)[None, :] >= self.count[:, None]] = 0.0
        # tail[a, w]: route length from waypoint w to the last one
        after = np.concatenate([leg[:, 1:], np.zeros((n, 1))], axis=1)
        self.tail = np.cumsum(after[:, ::-1], axis=1)[:, ::-1]
        self.planned = leg.sum(axis=1)
        self.done = np.zeros(n, dtype=bool)
        self.modes = None
        self._rows = np.arange(n)
        self._no_waypoints = bool((self.count == 0).any())
        self._every_row = bool(np.array_equal(m, self._rows))  # members are 0..k-1
        self._legs = None  # _Legs of the current index and done; see _target
        # (FlightState, (k,) rad) of the last desired_heading: turn_rate asks for it and the
        # world again with the same state object (a new one every phase)
        self._desired = None

    def __setstate__(self, state):
        """Unpickle; the kept leg geometry is derived state, rebuilt (also for an autopilot
        pickled before it was kept, e.g. in an older checkpoint)."""
        self.__dict__.update(state)
        self._rows = np.arange(self.members.size)
        self._no_waypoints = bool((self.count == 0).any())
        self._every_row = bool(np.array_equal(self.members, self._rows))
        self._legs = self._desired = None

    def _positions(self, state) -> np.ndarray:
        """(k, 2) m, the members' positions: the world's array itself when the members
        are all its aircraft in order (the same values as the gather)."""
        if self._every_row and state.positions.shape[0] == self._rows.size:
            return state.positions
        return state.positions[self.members]

    def _target(self):
        """``(target, leg start)`` (k, 2) m of each member's current leg. What depends only
        on ``index`` and ``done`` is kept (:attr:`_legs`) until :meth:`after_step` moves an
        index: the world and the env read it about six times a step."""
        if self._legs is None:
            w = np.minimum(self.index, self.wp.shape[1] - 1)
            tgt, prev = self.wp[self._rows, w], self.prev[self._rows, w]
            leg = tgt - prev
            self._legs = _Legs(
                w,
                tgt,
                prev,
                leg,
                np.hypot(leg[:, 0], leg[:, 1]),
                (self.count == 0) | self.done,
                (self.count > 0) & ~self.done,
                self.tail[self._rows, w],
            )
        return self._legs.target, self._legs.start

    def desired_heading(self, state):
        last = self._desired
        if last is not None and last[0] is state:  # the world asks twice per FlightState
            return last[1]
        tgt, _ = self._target()
        d = tgt - state.positions[self.members]
        h = np.arctan2(d[:, 1], d[:, 0])
        out = np.where(self._legs.hold, self.heading0, h)
        out.flags.writeable = False
        self._desired = (state, out, None)
        return out

    def turn_rate(self, state):
        if type(self).desired_heading is not RouteAutopilot.desired_heading:
            # a subclass's own desired heading, flown as before
            return _toward(self.desired_heading(state), state, self.members)
        return self.commands(state)[0]

    def commands(self, state):
        """``(turn_rate, desired_heading)`` (k,) rad/s and rad in one numba pass
        (:func:`~airspace_sim.world.flight.route_turns`) after numpy's ``arctan2`` of the
        bearings: the values of :meth:`desired_heading` and ``_toward`` bit for bit. The
        world reads both."""
        last = self._desired
        if last is not None and last[0] is state and last[2] is not None:
            return last[2], last[1]
        tgt, _ = self._target()
        d = tgt - self._positions(state)
        heading_to = np.arctan2(d[:, 1], d[:, 0])
        desired = np.empty(self.members.size)
        rate = np.empty(self.members.size)
        route_turns(
            heading_to, self._legs.hold, self.heading0, self.members, state.headings,
            state.max_turn_rate, state.dt, desired, rate,
        )  # fmt: skip
        desired.flags.writeable = False
        self._desired = (state, desired, rate)
        return rate, desired

    def after_step(self, state):
        """Waypoint capture (the class docstring's rule), at most one waypoint per member
        and step checked twice, in one numba pass (:func:`_capture`); returns (k,) bool
        finished."""
        index = self.index.copy()
        if _capture(
            state.positions, self.members, state.speeds, state.dt, self.wp, self.prev,
            self.count, index, self.done,
        ):  # fmt: skip
            self.index = index
            self._legs = self._desired = None
        return self.done.copy()

    def after_step_reference(self, state):
        """:meth:`after_step` as numpy statements (the reference the kernel is tested
        against)."""
        pos = state.positions[self.members]
        step_len = state.speeds[self.members] * state.dt
        for _ in range(2):  # a step can at most reach one waypoint; twice for safety
            tgt, prev = self._target()
            to_wp = tgt - pos
            near = np.hypot(to_wp[:, 0], to_wp[:, 1]) <= step_len
            passed = np.einsum("ij,ij->i", to_wp, tgt - prev) < 0.0
            hit = (near | passed) & ~self.done & (self.count > 0)
            if not hit.any():  # nothing moved: a second pass would find the same
                break
            self.index = self.index + hit
            self.done |= hit & (self.index >= self.count)
            self._legs = self._desired = None
        return self.done.copy()

    def progress(self, state):
        return self._progress(state.positions[self.members])

    def _progress(self, pos):
        """:meth:`progress` at the members' positions ``pos`` (k, 2) m."""
        tgt, _ = self._target()
        remaining = np.linalg.norm(tgt - pos, axis=1) + self._legs.tail
        out = np.where(self.done, self.planned, self.planned - remaining)
        return self._progress_no_waypoints(pos, out)

    def _progress_no_waypoints(self, pos, out):
        """``out`` with the members without waypoints given their progress along the
        initial heading, like "straight"."""
        if not self._no_waypoints:
            return out
        d = pos - self.start
        along = d[:, 0] * np.cos(self.heading0) + d[:, 1] * np.sin(self.heading0)
        return np.where(self.count == 0, along, out)

    def route_geometry(self, state):
        """Where each member stands on its route, by this autopilot's own capture rule.

        Returns ``(index, done, cross_track, bearing, distance)``, each (k,) over the
        members: ``index`` int, the waypoint being flown to (its number of waypoints once
        finished); ``done`` bool, finished (the last waypoint reached: the aircraft leaves
        the world); ``cross_track`` m, signed distance from the line of the current leg
        (from the previous waypoint, or the start position, to ``index``), + left of it
        (CCW); ``bearing`` rad CCW from east, from the aircraft to the waypoint;
        ``distance`` m to the waypoint. With no waypoint ahead (finished, or no waypoints)
        ``cross_track`` and ``bearing`` are 0 and ``distance`` NaN.

        Read it after :meth:`after_step` of the same step (as the world does), so that
        ``index`` belongs to the positions in ``state``.
        """
        return self._route_geometry(state.positions[self.members])

    def route_state(self, state):
        """:meth:`route_geometry` and :meth:`progress` in one call (the env reads both
        every step): ``(index, done, cross_track, bearing, distance, progress)``. One
        numba pass (:func:`_route_state_rows`) after numpy's ``arctan2`` of the bearings;
        the same values as :meth:`route_geometry` and :meth:`progress` bit for bit."""
        pos = self._positions(state)
        tgt, prev = self._target()
        legs = self._legs
        d = tgt - pos
        bearing = np.arctan2(d[:, 1], d[:, 0])
        out = np.empty((4, pos.shape[0]))
        _route_state_rows(
            pos, tgt, prev, legs.leg, legs.length, legs.ahead, legs.tail, self.planned,
            self.done, bearing, out,
        )  # fmt: skip
        progress = self._progress_no_waypoints(pos, out[3])
        return self.index.copy(), self.done.copy(), out[0], out[1], out[2], progress

    def _route_geometry(self, pos):
        """:meth:`route_geometry` at the members' positions ``pos`` (k, 2) m."""
        tgt, prev = self._target()
        ahead, leg, length = self._legs.ahead, self._legs.leg, self._legs.length
        rel = pos - prev
        with np.errstate(invalid="ignore", divide="ignore"):
            cross = np.where(
                length > 1e-9, (leg[:, 0] * rel[:, 1] - leg[:, 1] * rel[:, 0]) / length, 0.0
            )
        d = tgt - pos
        bearing = np.arctan2(d[:, 1], d[:, 0])
        distance = np.hypot(d[:, 0], d[:, 1])
        return (
            self.index.copy(),
            self.done.copy(),
            np.where(ahead, cross, 0.0),
            np.where(ahead, bearing, 0.0),
            np.where(ahead, distance, np.nan),
        )


@njit(cache=True)
def _capture(pos, members, speeds, dt, wp, prev, count, index, done):  # pragma: no cover
    """:meth:`RouteAutopilot.after_step_reference` of k members in one pass, ``index`` and
    ``done`` (k,) updated in place: up to two captures per member, each ``|to_wp| ≤ speed·dt``
    (the C library's ``hypot``, as numpy's) or ``to_wp · (target − leg start) < 0`` (two
    products and one sum, as numpy's ``einsum`` of two terms). ``pos`` and ``speeds``
    (N,) indexed by ``members``; ``wp``, ``prev`` (k, W, 2) m. Returns whether an index
    moved."""
    moved = False
    W = wp.shape[1]
    for a in range(members.size):
        i = members[a]
        step_len = speeds[i] * dt
        for _ in range(2):
            if done[a] or count[a] <= 0:
                break
            w = min(index[a], W - 1)
            tx, ty = wp[a, w, 0], wp[a, w, 1]
            dx, dy = tx - pos[i, 0], ty - pos[i, 1]
            near = math.hypot(dx, dy) <= step_len
            passed = dx * (tx - prev[a, w, 0]) + dy * (ty - prev[a, w, 1]) < 0.0
            if not (near or passed):
                break
            index[a] += 1
            moved = True
            if index[a] >= count[a]:
                done[a] = True
    return moved


@njit(cache=True)
def _route_state_rows(
    pos, target, start, leg, length, ahead, tail, planned, done, bearing, out
):  # pragma: no cover - compiled
    """:meth:`RouteAutopilot.route_state`'s rows of k members: ``out`` (4, k) ← cross-track
    m, bearing rad, distance m, progress m, from the positions ``pos``, the legs' target,
    start, vector (k, 2) m and length (k,) m, ``ahead`` and ``done`` (k,) bool, ``tail``
    and ``planned`` (k,) m and numpy's ``bearing`` (k,) rad to the target. Each value as
    :meth:`RouteAutopilot._route_geometry` and :meth:`RouteAutopilot._progress` compute it
    (``hypot`` is the C library's in both; ``norm`` of two components is ``sqrt(x² + y²)``)."""
    for a in range(pos.shape[0]):
        dx, dy = target[a, 0] - pos[a, 0], target[a, 1] - pos[a, 1]
        if ahead[a]:
            if length[a] > 1e-9:
                rx, ry = pos[a, 0] - start[a, 0], pos[a, 1] - start[a, 1]
                out[0, a] = (leg[a, 0] * ry - leg[a, 1] * rx) / length[a]
            else:
                out[0, a] = 0.0
            out[1, a] = bearing[a]
            out[2, a] = math.hypot(dx, dy)
        else:
            out[0, a], out[1, a], out[2, a] = 0.0, 0.0, np.nan
        remaining = math.sqrt(dx * dx + dy * dy) + tail[a]
        out[3, a] = planned[a] if done[a] else planned[a] - remaining


@register("autopilot", "markov")
class MarkovAutopilot(Autopilot):
    """The paper's jump-Markov pilot (§II): modes straight / left / right at the preset's turn
    rates, the mode chain Π of the preset at the world's dt, drawn per aircraft from its own
    counter-based stream (:mod:`.streams`). Turn rates are clipped to the aircraft's limit.

    ``modes[a]`` is the mode in effect over the last step (truth convention of
    :mod:`airspace_sim.dynamics.truth`).
    """

    Params = NoParams
    has_modes = True

    def __init__(self, members, specs, context: AutopilotContext, params=None):
        self.members = np.asarray(members, dtype=np.int64)
        self.keys = context.keys[self.members]
        self.rates = np.asarray(context.preset.turn_rates, dtype=float)
        self.cdf = mode_cdf(context.preset.transition_matrix)
        u = streams.uniform(self.keys, streams.INITIAL_MODE, 0)
        self.modes = next_modes(mode_cdf(context.preset.mu0()[None, :]), np.zeros_like(u, int), u)
        self._last_step = -1

    def desired_heading(self, state):
        return np.full(self.members.size, np.nan)

    def turn_rate(self, state):
        if state.step != self._last_step:  # draw the mode of the coming step once
            self._last_step = state.step
            u = streams.uniform(self.keys, streams.MODE, state.step)
            self.modes = next_modes(self.cdf, self.modes, u)
        lim = state.max_turn_rate[self.members]
        return np.clip(self.rates[self.modes], -lim, lim)

    def after_step(self, state):
        return np.zeros(self.members.size, dtype=bool)

    def progress(self, state):
        return np.full(self.members.size, np.nan)
