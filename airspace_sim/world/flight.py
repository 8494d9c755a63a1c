"""Kernels of the world's commands and motion phases (:mod:`.world`, phases 1 and 2).

A small world's step is hundreds of numpy calls on arrays of a few rows, each costing
about as much as the arithmetic of the whole array (``docs/env-speed.md``); these kernels
do the elementwise parts of the two phases in one pass each. They compute every value as
the numpy statement they replace does, bit for bit: the transcendentals (``sin``, ``cos``,
``arctan2``) stay numpy's, computed between the kernels and passed in (numba's ``math.sin``
can differ from numpy's SIMD ``sin`` in the last bit); what the kernels do themselves is
IEEE arithmetic, ``%`` (the same ``fmod``-based floored remainder as numpy's
``remainder``) and comparisons, with numpy's ``clip`` and ``where`` semantics spelled out.
``tests/test_world_flight.py`` holds the numpy statements and checks the kernels against
them. Every cached kernel that calls :func:`wrap` or :func:`clip_array_bounds` is in this
module, the route autopilot's (:func:`route_turns`) and the env's (:func:`relative_bearings`)
included: numba's on-disk cache of a kernel does not see edits of helpers in other modules.
"""

from __future__ import annotations

import numpy as np
from numba import njit

#: what ``np.sinc`` puts for a zero argument (π·x replaced by eps)
EPS = float(np.finfo(float).eps)
_PI = float(np.pi)
_TWO_PI = 2.0 * float(np.pi)


@njit(cache=True, inline="always")
def clip_array_bounds(x, lo, hi):  # pragma: no cover - compiled
    """``np.clip(x, lo, hi)`` for one element of float arrays ``lo``, ``hi``: NaN kept,
    else ``x > lo ? x : lo``, then ``< hi ? : hi`` (numpy's loop: the same signed zeros)."""
    if x != x:
        return x
    y = x if x > lo else lo
    return y if y < hi else hi


@njit(cache=True, inline="always")
def wrap(a):  # pragma: no cover - compiled
    """:func:`airspace_sim.geometry.wrap_angle` of one angle, rad: ``(a + π) % 2π − π``."""
    return (a + _PI) % _TWO_PI - _PI


@njit(cache=True)
def turn_commands(rate, hr, agent, max_rate, active, out):  # pragma: no cover - compiled
    """The end of the commands phase, (N,) rad/s into ``out``: ``hr`` where ``agent``
    (the RL agents' commands), else ``rate`` (autopilots and CDA policy), clipped to
    ±``max_rate``, 0 for inactive aircraft: ``np.where(agent, hr, rate)``, ``np.clip(.,
    -max_rate, max_rate)``, ``[~active] = 0``."""
    for i in range(rate.size):
        r = hr[i] if agent[i] else rate[i]
        r = clip_array_bounds(r, -max_rate[i], max_rate[i])
        out[i] = r if active[i] else 0.0


@njit(cache=True)
def arc_terms(rate, headings, dt, turn, mid, y):  # pragma: no cover - compiled
    """The motion phase's arguments of numpy's trigonometry, (N,) each: ``turn = rate·dt``
    rad, ``mid = heading + turn/2`` rad (the chord's heading) and ``y = π·(turn/2π)``
    (``np.sinc``'s argument of ``turn/2π``, eps at 0)."""
    for i in range(rate.size):
        t = rate[i] * dt
        turn[i] = t
        mid[i] = headings[i] + 0.5 * t
        v = _PI * (t / _TWO_PI)
        y[i] = EPS if v == 0.0 else v


@njit(cache=True)
def chords(
    speeds, sin_y, y, cos_mid, sin_mid, active, headings, turn, dt, v, new_headings, flown
):  # pragma: no cover - compiled
    """The motion phase's elementwise rest, from numpy's ``sin(y)``, ``cos(mid)``,
    ``sin(mid)``: ``v`` (N, 2) m/s the chord velocity ``speed·(sin y / y)`` at ``mid`` (0
    for inactive aircraft), ``new_headings`` (N,) rad ``wrap(heading + turn)``, ``flown``
    (N,) m ``speed·dt`` (0 for inactive aircraft)."""
    for i in range(speeds.size):
        chord = speeds[i] * (sin_y[i] / y[i])
        if active[i]:
            v[i, 0] = chord * cos_mid[i]
            v[i, 1] = chord * sin_mid[i]
            flown[i] = speeds[i] * dt
        else:
            v[i, 0] = 0.0
            v[i, 1] = 0.0
            flown[i] = 0.0
        new_headings[i] = wrap(headings[i] + turn[i])


@njit(cache=True)
def velocity_rows(speeds, cos_h, sin_h, active, v):  # pragma: no cover - compiled
    """``v`` (N, 2) m/s ← ``speed·(cos h, sin h)`` from numpy's ``cos_h``, ``sin_h``, 0 for
    inactive aircraft."""
    for i in range(speeds.size):
        if active[i]:
            v[i, 0] = speeds[i] * cos_h[i]
            v[i, 1] = speeds[i] * sin_h[i]
        else:
            v[i, 0] = 0.0
            v[i, 1] = 0.0


@njit(cache=True)
def pair_flags(i, j, flag):  # pragma: no cover - compiled
    """``flag`` (N,) bool ← True for every aircraft of the pairs ``(i, j)`` (P,), else
    False."""
    flag[:] = False
    for p in range(i.size):
        flag[i[p]] = True
        flag[j[p]] = True


@njit(cache=True)
def agent_masks(hr, controlled, avoid, moved, agent, flies_resolver):  # pragma: no cover
    """The commands phase's masks from the RL agents' commands ``hr`` (N,) rad/s (NaN:
    built-in): ``agent`` (N,) ← controlled and finite (the command is flown),
    ``flies_resolver`` (N,) ← ``avoid & ~moved & ~agent``. Returns True if an entry of
    ``hr`` is infinite (a user error)."""
    inf = False
    for i in range(hr.size):
        h = hr[i]
        if np.isinf(h):
            inf = True
        a = controlled[i] and np.isfinite(h)
        agent[i] = a
        flies_resolver[i] = avoid[i] and not moved[i] and not a
    return inf


@njit(cache=True)
def route_turns(
    heading_to, hold, heading0, members, headings, max_rate, dt, desired, rate
):  # pragma: no cover - compiled
    """:meth:`~airspace_sim.world.autopilots.RouteAutopilot.commands` of k members:
    ``desired`` (k,) rad ← ``heading0`` where ``hold`` else numpy's ``heading_to`` (bearing
    to the target), ``rate`` (k,) rad/s ← ``clip(wrap(desired − heading) / dt, ±max_rate)``
    (the autopilot's ``_toward``); ``headings`` and ``max_rate`` (N,) indexed by
    ``members``."""
    for a in range(members.size):
        i = members[a]
        des = heading0[a] if hold[a] else heading_to[a]
        desired[a] = des
        rate[a] = clip_array_bounds(wrap(des - headings[i]) / dt, -max_rate[i], max_rate[i])


@njit(cache=True)
def relative_bearings(bearing, idx, heading, out):  # pragma: no cover - compiled
    """``out`` (A,) rad ← ``wrap_angle(bearing[idx] − heading)``: the bearing to the
    waypoint relative to the heading of each ownship (``bearing`` (N,), ``heading`` (A,)),
    with :func:`wrap` (numpy's ``wrap_angle`` bit for bit)."""
    for k in range(idx.size):
        out[k] = wrap(bearing[idx[k]] - heading[k])
