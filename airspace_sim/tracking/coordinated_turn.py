"""Coordinated turn with the turn rate in the state: the IMM's nonlinear (EKF) mode.

The paper carries Ω in the state ``[x, vx, y, vy, Ω]`` but only uses modes with a known
rate. In an *estimated-rate* mode the turn rate is the state's own Ω, a random walk, and
the motion is the coordinated turn at that rate (Bar-Shalom, Li & Kirubarajan 2001,
§11.7.2; Li & Jilkov 2003, "Survey of maneuvering target tracking I", §4.2.1):

    x' = x + s vx − c vy,   vx' = cos(ΩT) vx − sin(ΩT) vy,
    y' = y + c vx + s vy,   vy' = sin(ΩT) vx + cos(ΩT) vy,   Ω' = Ω,

with ``s = sin(ΩT)/Ω``, ``c = (1 − cos ΩT)/Ω`` (:func:`airspace_sim.geometry.turn_terms`).
The mode is an extended Kalman filter: the mean goes through ``f`` and the covariance
through its Jacobian at the mixed estimate, whose Ω column holds ``∂s/∂Ω``, ``∂c/∂Ω``.
The IMM kernel (:mod:`._kernels`) evaluates both per tracker with :func:`ct_terms`; the
numpy functions here serve look-ahead predictions (:func:`predict`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

#: Below this |ΩT| (rad) the terms use their Taylor series (error ~|ΩT|⁵ relative).
_SMALL = 1e-3


@njit(cache=True, error_model="numpy")
def ct_terms(omega, T):
    """``s, c, ∂s/∂Ω, ∂c/∂Ω, cos ΩT, sin ΩT`` for turn rate ``omega`` (rad/s) over ``T`` s.

    A scalar numba version of :func:`airspace_sim.geometry.turn_terms` (which is numpy)
    with the two derivatives the Jacobian needs; exact through ``Ω = 0`` by series.
    """
    u = omega * T
    co = math.cos(u)
    si = math.sin(u)
    if abs(u) < _SMALL:
        u2 = u * u
        s = T * (1.0 - u2 / 6.0)
        c = T * u * (0.5 - u2 / 24.0)
        ds = T * T * u * (-1.0 / 3.0 + u2 / 30.0)
        dc = T * T * (0.5 - u2 / 8.0)
    else:
        s = si / omega
        c = (1.0 - co) / omega
        ds = (u * co - si) / (omega * omega)
        dc = (u * si - (1.0 - co)) / (omega * omega)
    return s, c, ds, dc, co, si


@njit(cache=True, error_model="numpy")
def _ct_terms(omega, T):
    """:func:`ct_terms` for every rate of ``omega`` (R,): six (R,) arrays, compiled (the
    smoother calls this for every tracker and mode at every step)."""
    out = np.empty((6, omega.size))
    for r in range(omega.size):
        out[0, r], out[1, r], out[2, r], out[3, r], out[4, r], out[5, r] = ct_terms(omega[r], T)
    return out[0], out[1], out[2], out[3], out[4], out[5]


def transition(x, T: float):
    """``f(x)`` and its Jacobian for states ``x`` (R, 5) over ``T`` s: (R, 5), (R, 5, 5)."""
    x = np.asarray(x, dtype=float)
    s, c, ds, dc, co, si = _ct_terms(np.ascontiguousarray(x[:, 4]), float(T))
    vx, vy = x[:, 1], x[:, 3]
    fx = np.stack(
        [x[:, 0] + s * vx - c * vy, co * vx - si * vy, x[:, 2] + c * vx + s * vy,
         si * vx + co * vy, x[:, 4]], axis=1,
    )  # fmt: skip
    J = np.zeros(x.shape[:1] + (5, 5))
    J[:, 0, 0] = J[:, 2, 2] = J[:, 4, 4] = 1.0
    J[:, 0, 1], J[:, 0, 3], J[:, 0, 4] = s, -c, ds * vx - dc * vy
    J[:, 1, 1], J[:, 1, 3], J[:, 1, 4] = co, -si, -T * (si * vx + co * vy)
    J[:, 2, 1], J[:, 2, 3], J[:, 2, 4] = c, s, dc * vx + ds * vy
    J[:, 3, 1], J[:, 3, 3], J[:, 3, 4] = si, co, T * (co * vx - si * vy)
    return fx, J


def predict(x, P, Q, T: float, steps):
    """EKF predictions of states x (R, 5), covariances P (R, 5, 5) at ``steps`` (S,)
    positive increasing step counts of ``T`` s, process noise Q (5, 5) per step:
    xs (R, S, 5), Ps (R, S, 5, 5)."""
    x = np.array(x, dtype=float)
    P = np.array(P, dtype=float)
    R = x.shape[0]
    xs = np.empty((R, len(steps), 5))
    Ps = np.empty((R, len(steps), 5, 5))
    want = 0
    for k in range(1, int(steps[-1]) + 1 if len(steps) else 1):
        fx, J = transition(x, T)
        x = fx
        P = J @ P @ np.swapaxes(J, -1, -2) + Q
        P = 0.5 * (P + np.swapaxes(P, -1, -2))
        if k == steps[want]:
            xs[:, want], Ps[:, want] = x, P
            want += 1
    return xs, Ps
