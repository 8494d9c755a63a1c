"""Mode-conditioned predictions at a few chosen times ahead (paper §VI, assumption 4).

A resolver that weighs intruder manoeuvres (``bands-probabilistic``) needs, for every track,
each mode's own prediction ``x ← F_j x + u_j``, ``P ← F_j P F_jᵀ + Q_j`` at S sample times
over its horizon. :meth:`IMM.predict_modes` stores every step (B·M·steps·n² numbers:
0.2 GB for 3000 tracks over 120 steps); here the k-step maps are formed once per mode,

    x_k = Φ_k x + c_k,   P_k = Φ_k P Φ_kᵀ + Q_k,
    Φ_k = F^k,  c_k = F c_{k−1} + u,  Q_k = F Q_{k−1} Fᵀ + Q   (Φ_0 = I, c_0 = 0, Q_0 = 0),

and applied only at the S requested steps and only to the requested rows (R·M·S·n²).
"""

from __future__ import annotations

import numpy as np

from airspace_sim.errors import UserError


def step_maps(F, Q, U, steps):
    """The k-step maps ``(Φ_k, c_k, Q_k)`` of each mode at the step counts ``steps``.

    F, Q : (M, n, n); U : (M, n); steps : (S,) positive ints, increasing.
    Returns Phi (M, S, n, n), c (M, S, n), Qk (M, S, n, n).
    """
    F, Q, U = (np.asarray(a, dtype=float) for a in (F, Q, U))
    M, n = F.shape[0], F.shape[1]
    S = len(steps)
    Phi_s = np.empty((M, S, n, n))
    c_s = np.empty((M, S, n))
    Q_s = np.empty((M, S, n, n))
    Phi = np.broadcast_to(np.eye(n), (M, n, n)).copy()
    c = np.zeros((M, n))
    Qk = np.zeros((M, n, n))
    Ft = np.swapaxes(F, -1, -2)
    want = 0
    for k in range(1, int(steps[-1]) + 1):
        # a loop over the horizon on M small matrices: cheap next to the rows
        Phi = F @ Phi
        c = np.einsum("mij,mj->mi", F, c) + U
        Qk = F @ Qk @ Ft + Q
        if k == steps[want]:
            Phi_s[:, want], c_s[:, want] = Phi, c
            Q_s[:, want] = 0.5 * (Qk + np.swapaxes(Qk, -1, -2))
            want += 1
    return Phi_s, c_s, Q_s


def predict_modes_at(F, Q, U, x_modes, P_modes, steps):
    """Each mode's own model propagated ``steps`` (S,) steps ahead, without mixing.

    F, Q : (M, n, n); U : (M, n); x_modes : (R, M, n); P_modes : (R, M, n, n).
    Returns xs (R, M, S, n), Ps (R, M, S, n, n): equal (to rounding) to
    ``IMM.predict_modes(max(steps))`` at the indices ``steps − 1``.
    """
    steps = _check_steps(steps)
    xm = np.asarray(x_modes, dtype=float)
    Pm = np.asarray(P_modes, dtype=float)
    if steps.size == 0:
        R, M, n = xm.shape
        return np.empty((R, M, 0, n)), np.empty((R, M, 0, n, n))
    Phi, c, Qk = step_maps(F, Q, U, steps)
    xs = np.einsum("msij,rmj->rmsi", Phi, xm) + c[None]
    PhiP = np.einsum("msij,rmjk->rmsik", Phi, Pm)
    Ps = np.einsum("rmsik,mslk->rmsil", PhiP, Phi) + Qk[None]
    Ps = 0.5 * (Ps + np.swapaxes(Ps, -1, -2))
    return xs, Ps


def _check_steps(steps) -> np.ndarray:
    s = np.asarray(steps)
    if s.ndim != 1 or (s.size and not np.issubdtype(s.dtype, np.integer)):
        raise UserError(f"predict_modes_at: steps must be a 1-d array of integers, got {steps!r}")
    s = s.astype(np.int64)
    if s.size and (s[0] < 1 or np.any(np.diff(s) <= 0)):
        raise UserError(
            f"predict_modes_at: steps must be positive and increasing, got {s.tolist()}"
        )
    return s


def relative_positions(xs, Ps, times_s, own_position=None, own_velocity=None):
    """Position parts of mode predictions, relative to an ownship flying straight.

    xs (R, M, S, n), Ps (R, M, S, n, n): predictions of states ``[x, vx, y, vy, Ω]``;
    times_s (S,) s ahead; own_position, own_velocity (R, 2) m, m/s, or None (predictions
    already relative). Returns (R, M, S, 2) m and (R, M, S, 2, 2) m²: each mode's predicted
    intruder position minus ``own_position + t·own_velocity``, and its covariance.
    """
    pos = xs[..., (0, 2)]
    cov = Ps[..., (0, 2), :][..., (0, 2)]
    if own_position is not None:
        t = np.asarray(times_s, dtype=float)
        own = own_position[:, None, :] + t[None, :, None] * own_velocity[:, None, :]  # (R, S, 2)
        pos = pos - own[:, None]
    return pos, cov
