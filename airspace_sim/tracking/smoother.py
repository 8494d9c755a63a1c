"""IMM smoothing, fixed-interval (every step given the whole record) and fixed-lag.

The IMM (paper §IV) is a filter: its estimate at step k uses the measurements up to k, so a
turn is confirmed only once it has bent the track beyond the noise. Labelling a recorded
flight (which seconds were turns, of which sign), or reconstructing its path, may use the
measurements after k too. :func:`smooth` runs a backward pass over the mode-conditioned
posteriors a forward IMM stored, in the form of the expectation-correction smoother for
switching linear dynamical systems (Barber 2006, "Expectation correction for smoothed
inference in switching linear dynamical systems", JMLR 7) with the mode posterior below and
an extended-Kalman step for the estimated-rate mode. From step k + 1 back to k, for every
pair (j at k, i at k + 1):

- the prediction of mode j's filtered estimate through mode i's model, ``x⁻ = f_i(x^j_{k|k})``,
  ``P⁻ = J_i P^j_{k|k} J_iᵀ + Q_i`` (``F_i x + u_i`` and ``J_i = F_i`` for a linear mode; the
  coordinated turn and its Jacobian at ``x^j_{k|k}`` for an estimated-rate one,
  :mod:`.coordinated_turn`);
- the mode posterior, from the forward mixing weight and how well that prediction meets
  the smoothed estimate of mode i (the correction Kim's 1994 smoother leaves out):

      Pr(s_k = j | s_{k+1} = i, Y_N) ∝ π_ji μ_{k|k}(j) N(x^i_{k+1|N}; x⁻, P⁻ + P^i_{k+1|N}),

  the pair's prediction density averaged over the smoothed estimate of mode i (Barber
  evaluates it at the smoothed mean, ``N(x^i_{k+1|N}; x⁻, P⁻)``; that sharper form lets a
  mode's probability ride back on a smoothed estimate that has run off the track, by
  hundreds of metres to kilometres on simulated traffic of the very model,
  ``docs/tracking.md``, "After the fact"); so ``μ_{k|N}(j) = Σ_i Pr(j | i) μ_{k+1|N}(i)`` and
  ``w_{i|j} = Pr(j | i) μ_{k+1|N}(i) / μ_{k|N}(j)``;
- a Rauch–Tung–Striebel step, ``G = P^j_{k|k} J_iᵀ (P⁻)⁻¹``,
  ``x^{ji} = x^j_{k|k} + G (x^i_{k+1|N} − x⁻)``, ``P^{ji} = P^j_{k|k} + G (P^i_{k+1|N} − P⁻) Gᵀ``,
  merged over i with the weights ``w_{i|j}`` (moment matching).

With one mode this is the Rauch–Tung–Striebel smoother; with several it approximates the
exact smoother (a mixture over every mode sequence) as the IMM approximates the exact filter.
``tests/test_smoother.py`` checks both: filterpy's ``rts_smoother``, and the exact posterior
by enumeration of every mode sequence on short records. Without the correction (Kim's
smoother) a mode with little process noise carries its smoothed estimate back as a rigid
straight line, far from a slow turn its forward filter followed only by mixing. A smoother
trusts its model over the whole record: modes that cannot fly the record's manoeuvres give
smoothed positions worse than the filter's (``docs/tracking.md``, "After the fact", also
for the variants measured).

A mode whose model pins a state component (a known-rate mode sets Ω = ω_j: a zero row of
``F_i`` and no process noise on it) has a singular ``P⁻``; the pinned component carries no
information back (its gain column is zero) and its density is the same for every j, which a
unit on the zero diagonal gives exactly.

Over long records the fixed-interval form loses to its own 10–20-step lag, even on traffic
of the model itself: where the forward filter keeps some probability on a mode that is not
flying, that probability rides back on the mode's smoothed estimate after it has run off
(``docs/tracking.md``, "Two filters"). :func:`.two_filter.smooth_two_filter` does not (it
needs the measurements, not only the forward record); this one is as good up to a few steps
of lag.

Memory: the forward pass's K·B·M·n² covariances; callers with long records split the
trackers into batches (:func:`airspace_sim.tracking.evaluation.evaluate` does).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from airspace_sim.errors import UserError
from airspace_sim.tracking import coordinated_turn


class Smoothed(NamedTuple):
    """Smoothed estimates over K steps of B trackers with M modes of n states."""

    #: (K, B, M) mode probabilities μ_{k|N}
    mu: np.ndarray
    #: (K, B, M, n) mode-conditioned states
    x_modes: np.ndarray
    #: (K, B, M, n, n) mode-conditioned covariances
    P_modes: np.ndarray

    @property
    def x(self) -> np.ndarray:
        """(K, B, n) the combined states ``Σ_j μ_j x^j``."""
        return np.einsum("kbm,kbmn->kbn", self.mu, self.x_modes)


def forward_record(imm, z):
    """Step ``imm`` (an :class:`~airspace_sim.tracking.IMM`) through the measurements z
    (K, B, m): its record μ (K, B, M), x^j (K, B, M, n), P^j (K, B, M, n, n) after every
    step, what the smoothers take."""
    K = z.shape[0]
    B, M, n = imm.x_modes.shape
    mu, x, P = np.empty((K, B, M)), np.empty((K, B, M, n)), np.empty((K, B, M, n, n))
    for k in range(K):
        imm.step(z[k])
        mu[k], x[k], P[k] = imm.mu, imm.x_modes, imm.P_modes
    return mu, x, P


def _predictions(x, P, F, Q, U, estimated, T):
    """Every filtered mode j through every mode i's model.

    x (B, M, n), P (B, M, n, n) the mode-conditioned posteriors; F, Q (M, n, n), U (M, n) the
    modes' linear models; ``estimated`` (M,) bool the estimated-rate modes, whose f and
    Jacobian come from :func:`.coordinated_turn.transition` over ``T`` s. Returns x⁻
    (B, M_j, M_i, n), P⁻ (B, M_j, M_i, n, n) and the Jacobians J (B, M_j, M_i, n, n).
    """
    B, M, n = x.shape
    J = np.broadcast_to(F[None, None], (B, M, M, n, n)).copy()
    xp = np.einsum("ikl,bjl->bjik", F, x) + U[None, None]
    if estimated.any():  # every estimated-rate mode flies the same turn (only Q differs)
        fx, Jct = coordinated_turn.transition(x.reshape(B * M, n), T)
        xp[:, :, estimated] = fx.reshape(B, M, 1, n)
        J[:, :, estimated] = Jct.reshape(B, M, 1, n, n)
    Pp = J @ P[:, :, None] @ np.swapaxes(J, -1, -2) + Q[None, None]
    return xp, Pp, J


def smooth(mu, x_modes, P_modes, model: dict, n_steps=None, lag=None) -> Smoothed:
    """The IMM smoother's backward pass over a forward IMM's record: fixed-interval (every
    step given the whole record) or, with ``lag``, fixed-lag (step k given the measurements
    up to k + lag: what a tracker that reports ``lag`` steps late can say).

    Parameters
    ----------
    mu : (K, B, M)
        Forward (filtered) mode probabilities μ_{k|k} after each of K steps.
    x_modes : (K, B, M, n)
        Forward mode-conditioned posterior states (``IMM.x_modes`` after each step).
    P_modes : (K, B, M, n, n)
        Forward mode-conditioned posterior covariances (``IMM.P_modes``).
    model : dict
        The forward IMM's keyword arguments (``Preset.imm_arguments()``): ``transitions``,
        ``process_noise``, ``transition_matrix``, ``offsets`` and, with estimated-rate modes,
        ``estimated_turn_rate`` and ``dt`` (s). The step is the model's (regular sampling).
        Models with the along-track acceleration in the state are not supported.
    n_steps : (B,) int, optional
        Each tracker's own record length, for a batch of records of different lengths: a
        tracker's steps from ``n_steps[b]`` on (predictions after its last measurement, NaN
        padding) are returned as given and carry nothing back. None: all K steps.
    lag : int, optional
        Fixed-lag smoothing with this many steps of look-ahead (0: the filter); each step
        costs ``lag`` backward steps. None: fixed-interval.

    Returns
    -------
    Smoothed
        μ, x^j, P^j for every step; the last step's are the filter's.
    """
    if model.get("along_track_acceleration") is not None:
        raise UserError("smooth: models with the along-track acceleration are not supported")
    mu = np.asarray(mu, dtype=float)
    xf = np.asarray(x_modes, dtype=float)
    Pf = np.asarray(P_modes, dtype=float)
    K, B, M = mu.shape
    n = xf.shape[-1]
    if xf.shape != (K, B, M, n) or Pf.shape != (K, B, M, n, n):
        raise UserError(
            f"smooth: x_modes {xf.shape} and P_modes {Pf.shape} do not match mu {mu.shape}"
        )
    F = np.asarray(model["transitions"], dtype=float)
    Q = np.asarray(model["process_noise"], dtype=float)
    Pi = np.asarray(model["transition_matrix"], dtype=float)
    U = model.get("offsets")
    U = np.zeros((M, n)) if U is None else np.asarray(U, dtype=float)
    estimated = model.get("estimated_turn_rate")
    estimated = np.zeros(M, bool) if estimated is None else np.asarray(estimated, dtype=bool)
    T = float(model["dt"]) if estimated.any() else float("nan")
    n_steps = np.full(B, K) if n_steps is None else np.asarray(n_steps)
    if n_steps.shape != (B,):
        raise UserError(f"smooth: n_steps must have shape {(B,)}, got {n_steps.shape}")
    if lag is not None and (
        isinstance(lag, bool) or not isinstance(lag, (int, np.integer)) or lag < 0
    ):
        raise UserError(f"smooth: lag must be a non-negative integer of steps, got {lag!r}")
    terms = (F, Q, U, Pi, estimated, T)
    if lag is not None:
        return _fixed_lag(mu, xf, Pf, n_steps, int(lag), terms)

    mu_s, x_s, P_s = mu.copy(), xf.copy(), Pf.copy()
    for k in range(K - 2, -1, -1):
        on = np.flatnonzero(k + 1 < n_steps)  # trackers with a smoothed step k + 1
        if on.size == 0:
            continue
        filtered = (mu[k, on], xf[k, on], Pf[k, on])
        after = (mu_s[k + 1, on], x_s[k + 1, on], P_s[k + 1, on])
        mu_s[k, on], x_s[k, on], P_s[k, on] = _backward_step(*filtered, *after, *terms)
    return Smoothed(mu_s, x_s, P_s)


#: Windows (step, tracker) a fixed-lag pass steps back at once (bounds its memory).
LAG_WINDOWS = 4096


def _fixed_lag(mu, xf, Pf, n_steps, lag, terms) -> Smoothed:
    """Every step's own backward pass, from the filtered estimate ``lag`` steps later (or
    its record's last step) back to it; the windows (k, b) run side by side."""
    K, B = mu.shape[:2]
    kk, bb = np.nonzero(np.arange(K)[:, None] < n_steps[None, :])  # live (step, tracker)
    end = np.minimum(kk + lag, n_steps[bb] - 1)
    mu_s, x_s, P_s = mu.copy(), xf.copy(), Pf.copy()
    for lo in range(0, kk.size, LAG_WINDOWS):
        k, b, e = kk[lo : lo + LAG_WINDOWS], bb[lo : lo + LAG_WINDOWS], end[lo : lo + LAG_WINDOWS]
        cur = [mu[e, b], xf[e, b], Pf[e, b]]
        for t_back in range(lag - 1, -1, -1):
            on = np.flatnonzero(k + t_back < e)  # windows whose chain reaches k + t_back
            if on.size == 0:
                continue
            t = k[on] + t_back
            filtered = (mu[t, b[on]], xf[t, b[on]], Pf[t, b[on]])
            after = [c[on] for c in cur]
            for c, new in zip(cur, _backward_step(*filtered, *after, *terms)):
                c[on] = new
        mu_s[k, b], x_s[k, b], P_s[k, b] = cur
    return Smoothed(mu_s, x_s, P_s)


def _backward_step(mu, xf, Pf, mu_next, x_next, P_next, F, Q, U, Pi, estimated, T):
    """One step back, k + 1 → k, for R trackers: the filtered μ (R, M), x (R, M, n),
    P (R, M, n, n) at k and the smoothed ones at k + 1; returns the smoothed ones at k."""
    n = xf.shape[-1]
    xp, Pp, J = _predictions(xf, Pf, F, Q, U, estimated, T)
    # a pinned component: zero row and column of P⁻; a unit there zeroes its gain column
    d = np.diagonal(Pp, axis1=-2, axis2=-1)
    Pp_safe = Pp + (d == 0.0)[..., None] * np.eye(n)
    dx = x_next[:, None] - xp  # (R, M_j, M_i, n)

    # Pr(s_k = j | s_{k+1} = i, Y_N) ∝ π_ji μ_{k|k}(j) N(x^i_{k+1|N}; x⁻_ji, P⁻_ji + P^i_{k+1|N})
    S = Pp_safe + P_next[:, None]
    sign, logdet = np.linalg.slogdet(S)
    maha = np.einsum("rjia,rjia->rji", dx, np.linalg.solve(S, dx[..., None])[..., 0])
    with np.errstate(divide="ignore"):
        log_a = np.log(Pi)[None] + np.log(mu)[:, :, None] - 0.5 * (maha + logdet)
    log_a = np.where(sign > 0, log_a, -np.inf)
    a = np.exp(log_a - log_a.max(axis=1, keepdims=True))
    a = np.nan_to_num(a / a.sum(axis=1, keepdims=True))  # over j, for each i
    joint = a * mu_next[:, None, :]  # Pr(s_k = j, s_{k+1} = i | Y_N)
    # a mode i no j can reach (every pair impossible) would lose its probability: renormalise
    total = joint.sum(axis=(1, 2))[:, None, None]
    joint = np.where(total > 0, joint / np.where(total > 0, total, 1.0), Pi[None] * mu[..., None])
    mu_s = joint.sum(axis=2)
    w = joint / np.maximum(mu_s[..., None], np.finfo(float).tiny)  # w_{i|j}

    G = np.swapaxes(np.linalg.solve(Pp_safe, J @ Pf[:, :, None]), -1, -2)  # P^j Jᵀ (P⁻)⁻¹
    x_ji = xf[:, :, None] + np.einsum("rjiac,rjic->rjia", G, dx)
    P_ji = Pf[:, :, None] + G @ (P_next[:, None] - Pp) @ np.swapaxes(G, -1, -2)
    x_s = np.einsum("rji,rjia->rja", w, x_ji)
    e = x_ji - x_s[:, :, None]
    P_s = np.einsum("rji,rjiac->rjac", w, P_ji + e[..., :, None] * e[..., None, :])
    return mu_s, x_s, P_s
