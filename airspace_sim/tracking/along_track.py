"""Coordinated turn with along-track acceleration: an EKF mode with the speed change in the state.

The coordinated turn with the turn rate in the state (:mod:`.coordinated_turn`; the paper
carries Ω in ``[x, vx, y, vy, Ω]`` but only uses known rates) changes the heading but not
the speed. Recorded flights change speed too (wind in turns, speed changes): what is left
once the turn rate is known (``docs/tracking.md``, "How far from the floor"). This mode
adds the along-track (tangential) acceleration ``a`` (m/s²) to the state,
``[x, vx, y, vy, Ω, a]``: over a step the heading turns at Ω and the speed changes at
``a``, both constant, i.e. with ``e = v/|v|`` the along-track direction

    v(t) = (|v| + a t) R(Ωt) e,   so over T:
    p' = p + A v + a B e,   v' = R(ΩT) v + a T R(ΩT) e,   Ω' = Ω,   a' = a,

with ``R(θ)`` the rotation by θ, ``A = ∫₀ᵀ R(Ωt) dt = [[s, −c], [c, s]]`` (``s``, ``c`` of
:func:`.coordinated_turn.ct_terms`) and ``B = ∫₀ᵀ t R(Ωt) dt = [[b_s, −b_c], [b_c, b_s]]``,
``b_s = T sin ΩT/Ω − (1 − cos ΩT)/Ω²``, ``b_c = sin ΩT/Ω² − T cos ΩT/Ω`` (``T²/2`` and
``ΩT³/3`` as Ω → 0). Ω and ``a`` are random walks (``Q_ΩΩ = σ_Ω² T``, ``Q_aa = σ_t² T``). It
extends the paper's §II state (Ω carried, never estimated there) and the coordinated turn
with the rate estimated (Bar-Shalom, Li & Kirubarajan 2001, §11.7.2) by the tangential
acceleration of the curvilinear-motion model (tangential and normal accelerations, here
the normal one ``Ω|v|``; Best & Norton 1997, as surveyed by Li & Jilkov 2003, "Survey of
maneuvering target tracking I").

The mode is an extended Kalman filter: the mean goes through ``f``, the covariance through
its Jacobian at the mixed estimate; ``∂e/∂v = (I − e eᵀ)/|v|`` (with ``|v|`` floored at
:data:`._kernels.CTA_MIN_SPEED`). In an IMM every mode then has the 6-state layout: the
linear modes carry ``a`` pinned at 0 (or as a random walk), like Ω in the CV modes. The IMM
kernel (:mod:`._kernels`, ``_cta_predict``) runs the mode per tracker in SIMD lanes; the
numpy functions here serve look-ahead predictions (:func:`predict`) and tests.
"""

from __future__ import annotations

import numpy as np

from airspace_sim.tracking._kernels import CTA_MIN_SPEED, _cta_terms

#: State size of the layout ``[x, vx, y, vy, Ω, a]``.
N_STATE = 6
#: Index of the along-track acceleration (m/s²) in the state.
ALONG_TRACK = 5

_terms = np.vectorize(lambda w, T: _cta_terms(w, T), otypes=[float] * 10)


def transition(x, T: float):
    """``f(x)`` and its Jacobian for states ``x`` (R, 6) over ``T`` s: (R, 6), (R, 6, 6)."""
    x = np.asarray(x, dtype=float)
    s, c, ds, dc, co, si, bs, bc, dbs, dbc = _terms(x[:, 4], T)
    vx, vy, a = x[:, 1], x[:, 3], x[:, 5]
    sp = np.hypot(vx, vy)
    fast = sp > CTA_MIN_SPEED
    d = np.where(fast, sp, CTA_MIN_SPEED)
    ex, ey = vx / d, vy / d
    # ∂e/∂v: (I − e eᵀ)/|v|, or I / CTA_MIN_SPEED below the floor
    d11 = np.where(fast, (1.0 - ex * ex) / d, 1.0 / d)
    d12 = np.where(fast, -ex * ey / d, 0.0)
    d22 = np.where(fast, (1.0 - ey * ey) / d, 1.0 / d)
    bex, bey = bs * ex - bc * ey, bc * ex + bs * ey
    rex, rey = T * (co * ex - si * ey), T * (si * ex + co * ey)
    fx = np.stack(
        [x[:, 0] + s * vx - c * vy + a * bex, co * vx - si * vy + a * rex,
         x[:, 2] + c * vx + s * vy + a * bey, si * vx + co * vy + a * rey, x[:, 4], a], axis=1,
    )  # fmt: skip
    J = np.zeros(x.shape[:1] + (6, 6))
    J[:, 0, 0] = J[:, 2, 2] = J[:, 4, 4] = J[:, 5, 5] = 1.0
    J[:, 0, 1] = s + a * (bs * d11 - bc * d12)
    J[:, 0, 3] = -c + a * (bs * d12 - bc * d22)
    J[:, 0, 4] = ds * vx - dc * vy + a * (dbs * ex - dbc * ey)
    J[:, 0, 5] = bex
    J[:, 1, 1] = co + a * T * (co * d11 - si * d12)
    J[:, 1, 3] = -si + a * T * (co * d12 - si * d22)
    J[:, 1, 4] = -T * (si * vx + co * vy) - a * T * rey
    J[:, 1, 5] = rex
    J[:, 2, 1] = c + a * (bc * d11 + bs * d12)
    J[:, 2, 3] = s + a * (bc * d12 + bs * d22)
    J[:, 2, 4] = dc * vx + ds * vy + a * (dbc * ex + dbs * ey)
    J[:, 2, 5] = bey
    J[:, 3, 1] = si + a * T * (si * d11 + co * d12)
    J[:, 3, 3] = co + a * T * (si * d12 + co * d22)
    J[:, 3, 4] = T * (co * vx - si * vy) + a * T * rex
    J[:, 3, 5] = rey
    return fx, J


def predict(x, P, Q, T: float, steps, offset=None):
    """EKF predictions of states x (R, 6), covariances P (R, 6, 6) at ``steps`` (S,)
    positive increasing step counts of ``T`` s, process noise Q (6, 6) and offset u (6,)
    per step: xs (R, S, 6), Ps (R, S, 6, 6)."""
    x = np.array(x, dtype=float)
    P = np.array(P, dtype=float)
    u = np.zeros(N_STATE) if offset is None else np.asarray(offset, dtype=float)
    R = x.shape[0]
    xs = np.empty((R, len(steps), N_STATE))
    Ps = np.empty((R, len(steps), N_STATE, N_STATE))
    want = 0
    for k in range(1, int(steps[-1]) + 1 if len(steps) else 1):
        fx, J = transition(x, T)
        x = fx + u
        P = J @ P @ np.swapaxes(J, -1, -2) + Q
        P = 0.5 * (P + np.swapaxes(P, -1, -2))
        if k == steps[want]:
            xs[:, want], Ps[:, want] = x, P
            want += 1
    return xs, Ps
