"""Batched linear Kalman filter: B independent trackers sharing one linear-Gaussian model.

The single-model baseline for the IMM (a constant-velocity filter is the classic one) and
the ``kalman`` tracker plugin (``plugins/kalman_tracker.py``, through :func:`predict` and
:func:`update`). Same conventions as :class:`~airspace_sim.tracking.IMM`
(:class:`~airspace_sim.tracking.IMM`): every array has the tracker axis first, one :meth:`step` is a
predict followed by an update, a NaN measurement row means "no measurement: predict only".
Everything is numpy over the batch axis (``matmul``/``einsum``); there is no Python loop
over trackers.

Model (Bar-Shalom, Li & Kirubarajan 2001, §5.2)::

    x(k) = F x(k−1) + u + w,   w ~ N(0, Q)
    z(k) = H x(k) + v,         v ~ N(0, R)

Update in Joseph form, ``P = (I − KH) P (I − KH)ᵀ + K R Kᵀ``, which keeps P symmetric and
positive semi-definite under round-off (the same form filterpy 2.0.0 uses).
"""

from __future__ import annotations

import numpy as np

from airspace_sim.errors import UserError


def _sym(P: np.ndarray) -> np.ndarray:
    return 0.5 * (P + np.swapaxes(P, -1, -2))


def predict(x, P, F, Q, u):
    """Time update of a batch: ``x ← F x + u``, ``P ← F P Fᵀ + Q``.

    x (B, n), P (B, n, n), F, Q (n, n), u (n,); returns new (x, P).
    """
    return x @ F.T + u, _sym(F @ P @ F.T + Q)


def update(x, P, z, H, R):
    """Measurement update (Joseph form) of the rows of ``z`` (B, m) without NaN/inf.

    x (B, n), P (B, n, n), H (m, n), R (m, m); returns new (x, P, nis (B,)), nis NaN
    where there was no measurement (those rows of x and P are the inputs' values).
    """
    B, n = x.shape
    has = np.all(np.isfinite(z), axis=1)  # NaN (or inf) row: no measurement
    nis = np.full(B, np.nan)
    if not has.any():
        return x, P, nis
    x, P = x.copy(), P.copy()
    idx = np.flatnonzero(has) if not has.all() else slice(None)
    xi, Pi = x[idx], P[idx]
    nu = z[idx] - xi @ H.T  # (b, m)
    PHt = Pi @ H.T  # (b, n, m)
    S = _sym(H @ PHt + R)  # (b, m, m)
    # K = P Hᵀ S⁻¹ = (S⁻¹ H P)ᵀ since S and P are symmetric
    K = np.swapaxes(np.linalg.solve(S, np.swapaxes(PHt, -1, -2)), -1, -2)  # (b, n, m)
    nis[idx] = np.einsum("bi,bi->b", nu, np.linalg.solve(S, nu[..., None])[..., 0])
    xi = xi + np.einsum("bij,bj->bi", K, nu)
    IKH = np.eye(n) - K @ H
    Pi = IKH @ Pi @ np.swapaxes(IKH, -1, -2) + K @ R @ np.swapaxes(K, -1, -2)
    x[idx], P[idx] = xi, _sym(Pi)
    return x, P, nis


class KalmanFilter:
    """B Kalman filters with a shared model, stepped together.

    Parameters
    ----------
    transition : (n, n) state transition F.
    process_noise : (n, n) process noise covariance Q.
    measurement_matrix : (m, n) H.
    measurement_noise : (m, m) R.
    x0 : (B, n) initial estimates.
    P0 : (B, n, n) initial covariances (or (n, n), shared).
    offset : (n,) optional additive term u in the prediction.

    Attributes
    ----------
    x : (B, n) posterior estimates; P : (B, n, n) posterior covariances.
    nis : (B,) last step's normalised innovation squared ``νᵀ S⁻¹ ν``, NaN where there was
        no measurement.
    """

    def __init__(
        self, transition, process_noise, measurement_matrix, measurement_noise, x0, P0, offset=None
    ):
        F = np.asarray(transition, dtype=float)
        n = F.shape[-1]
        if F.shape != (n, n):
            raise UserError(f"KalmanFilter: transition must be (n, n), got {F.shape}")
        Q = np.asarray(process_noise, dtype=float)
        H = np.asarray(measurement_matrix, dtype=float)
        R = np.asarray(measurement_noise, dtype=float)
        m = H.shape[0] if H.ndim == 2 else -1
        if Q.shape != (n, n) or H.shape != (m, n) or R.shape != (m, m):
            raise UserError(
                f"KalmanFilter: shapes Q {Q.shape}, H {H.shape}, R {R.shape} do not fit n = {n}"
            )
        self.F, self.Q, self.H, self.R = F, Q, H, R
        self.u = np.zeros(n) if offset is None else np.asarray(offset, dtype=float).reshape(n)
        self.n, self.m = n, m
        self.x = np.empty((0, n))
        self.P = np.empty((0, n, n))
        self.nis = np.empty(0)
        self.append(x0, P0)

    # --- batch management -------------------------------------------------------------
    @property
    def B(self) -> int:
        """Number of trackers."""
        return self.x.shape[0]

    def append(self, x0, P0) -> np.ndarray:
        """Add trackers at the end; returns their row indices."""
        x0 = np.asarray(x0, dtype=float)
        if x0.ndim == 1:
            x0 = x0[None]
        P0 = np.asarray(P0, dtype=float)
        if x0.ndim != 2 or x0.shape[1] != self.n:
            raise UserError(f"KalmanFilter: x0 must be (B, {self.n}), got {x0.shape}")
        try:
            P0 = np.broadcast_to(P0, (x0.shape[0], self.n, self.n))
        except ValueError:
            raise UserError(
                f"KalmanFilter: P0 must be ({self.n}, {self.n}) or (B, {self.n}, {self.n}), got {P0.shape}"
            ) from None
        if not (np.all(np.isfinite(x0)) and np.all(np.isfinite(P0))):
            raise UserError("KalmanFilter: x0 and P0 must be finite")
        start = self.B
        self.x = np.concatenate([self.x, x0])
        self.P = np.concatenate([self.P, P0])
        self.nis = np.concatenate([self.nis, np.full(x0.shape[0], np.nan)])
        return np.arange(start, self.B)

    def remove(self, indices) -> None:
        """Drop trackers ``indices``; the others keep their order."""
        keep = np.ones(self.B, dtype=bool)
        keep[np.asarray(indices, dtype=np.int64)] = False
        self.x, self.P, self.nis = self.x[keep], self.P[keep], self.nis[keep]

    # --- filtering ----------------------------------------------------------------------
    def predict(self) -> None:
        """Time update only: ``x ← F x + u``, ``P ← F P Fᵀ + Q``."""
        self.x, self.P = predict(self.x, self.P, self.F, self.Q, self.u)

    def update(self, z) -> None:
        """Measurement update for rows of ``z`` (B, m) that are not NaN."""
        z = np.asarray(z, dtype=float).reshape(self.B, self.m)
        self.x, self.P, self.nis = update(self.x, self.P, z, self.H, self.R)

    def step(self, z) -> None:
        """One cycle: predict, then update with ``z`` (B, m); a NaN (or inf) row predicts only."""
        self.predict()
        self.update(z)
