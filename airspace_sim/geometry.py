"""Plane geometry shared by every package: angle wrapping, rotation, coordinated-turn arcs.

Angles in radians, counter-clockwise from east (negative = clockwise, a right turn).
"""

from __future__ import annotations

import numpy as np


def wrap_angle(a):
    """Angles wrapped to ``[−π, π)``, radians, elementwise (any shape)."""
    return (np.asarray(a, dtype=float) + np.pi) % (2.0 * np.pi) - np.pi


def rotate(v, angle):
    """Vectors ``v`` (..., 2) rotated CCW by ``angle`` (broadcastable to ``(...)``), radians."""
    v = np.asarray(v, dtype=float)
    c, s = np.cos(angle), np.sin(angle)
    return np.stack([c * v[..., 0] - s * v[..., 1], s * v[..., 0] + c * v[..., 1]], axis=-1)


def turn_terms(omega, t):
    """``sin(ωt)/ω`` and ``(1 − cos ωt)/ω`` (broadcast shapes), exact at ``ω = 0``.

    A coordinated turn at rate ω (rad/s) from velocity ``(vx, vy)`` moves by
    ``(vx·s − vy·c, vy·s + vx·c)`` in ``t`` seconds (paper §II, the CT model ``A_q``).
    Uses ``sin(u)/u = sinc(u/π)`` and ``(1 − cos u)/u = sin(u/2)·sinc(u/2π)``, both smooth
    through ``u = 0``.
    """
    t = np.asarray(t, dtype=float)
    wt = np.asarray(omega, dtype=float) * t
    return t * np.sinc(wt / np.pi), t * np.sin(wt / 2.0) * np.sinc(wt / (2.0 * np.pi))


def coordinated_turn_positions(x, times_s):
    """Positions of states ``x`` (P, 5) ``[x, vx, y, vy, Ω]`` flown as coordinated turns at
    their own Ω for ``times_s`` (S,) seconds: (P, S, 2) metres."""
    x = np.asarray(x, dtype=float)
    s, c = turn_terms(x[:, 4:5], np.asarray(times_s, dtype=float)[None, :])
    px = x[:, 0:1] + x[:, 1:2] * s - x[:, 3:4] * c
    py = x[:, 2:3] + x[:, 3:4] * s + x[:, 1:2] * c
    return np.stack([px, py], axis=-1)
