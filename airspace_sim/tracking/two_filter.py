"""Fixed-interval IMM smoothing by two filters: one forward, one over the time-reversed record.

The expectation-correction smoother (:mod:`.smoother`) carries each mode's smoothed
estimate back from the end of the record one step at a time. Where the forward IMM keeps
some probability on a mode that is not flying (the quiet mode in a turn, re-mixed every
step), that mode's smoothed probability rides back unchanged while its estimate, a rigid
straight line for a mode with little process noise, runs off the track: on traffic of the
model itself, 0.2 of the probability held for 15 steps by an estimate 1.3 km off
(``docs/tracking.md``, "Two filters"). Here the information after step k comes from a
second IMM instead, run over the measurements in reverse order, so every mode's backward
estimate is re-mixed and re-measured at every step as the forward one is (Helmick, Blair &
Hoffman 1995, "Fixed-interval smoothing for Markovian switching systems", IEEE Trans.
Inf. Theory 41(6); the two-filter form of Fraser & Potter 1969 for each mode).

Time reversal. Flown backwards, a trajectory keeps its positions, negates its velocity
and its turn rate (a left turn flown backwards is a right turn): :data:`REVERSAL`. A model
is its own time reversal when every mode has a mirror mode (the same motion reflected,
``y → −y``, :data:`MIRROR`: a turn at ω and one at −ω, a straight mode and itself, an
estimated-rate mode and itself) and the mode chain is run backwards,
``Π^rev_ij = Π_ji p_j / p_i`` with ``p`` its stationary distribution. For a linear mode the
reversed model's transition density equals the forward one's (the discrete white-noise
acceleration is symmetric in time), so the backward filter started from the last two
measurements computes the likelihood of the measurements after k.

Fusion, per pair of modes at step k: j the forward filter's (the mode that flew k − 1 → k)
and i the backward filter's, which is the mode that flew k → k + 1 (the reversed filter's
mode at k moved it from k + 1 back to k). Both posteriors include the measurement ``z_k``
(divided out once) and the backward one the backward filter's prior ``p_0`` (flat in
position and velocity; ``p_i`` for the mode; for an estimated-rate mode its turn rate's
stationary spread ``N(0, s_i²)``, ``s_i² = Q_i[Ω, Ω] / (1 − Π_ii)``: the rate's random walk
over a sojourn's mean length), divided out too:

    p(x_k, s_k = j, s_{k+1} = i | Y) ∝ μ_f(j) N(x; x^j_f, P^j_f) · Π_ji
                        · μ_b(i) N(x; x^i_b, P^i_b) / (p_i N(z_k; H x, R) p_0(Ω | i)),

a Gaussian in information form, ``J = P_f⁻¹ + P_b⁻¹ − Hᵀ R⁻¹ H − e_Ω e_Ωᵀ / s_i²``, whose
integral over x is the pair's weight; ``μ_s(j)`` sums them over i, mode j's smoothed
estimate is their fused Gaussians moment-matched. Ω where a mode pins it (a straight or
known-rate mode): the forward mode holds it at its value, the backward one says nothing of
Ω at k (it moves the aircraft without it), and an estimated backward rate meeting a pinned
forward one is conditioned on it (:func:`_fuse_pair`). Neither filter gates (every
measurement is used, as in :func:`~airspace_sim.tracking.evaluation.evaluate`).

Fixed-lag (``lag``): every step's own backward filter over its window, started from the
window's last two measurements; the windows run side by side as one batch of trackers.

Compared with :func:`.smoother.smooth`: the same Smoothed record; it needs the measurements
(it runs both filters) where ``smooth`` needs only the forward record, and its positions keep
improving with the look-ahead where expectation correction's turn worse after 10–20 steps.
"""

from __future__ import annotations

import math

import numpy as np

from airspace_sim.dynamics import models
from airspace_sim.dynamics.markov import stationary_law
from airspace_sim.errors import UserError
from airspace_sim.tracking.initialisation import two_point_initialisation
from airspace_sim.tracking.smoother import Smoothed, forward_record

#: Time reversal of ``[x, vx, y, vy, Ω]``: the velocity and the turn rate change sign.
REVERSAL = np.array([1.0, -1.0, 1.0, -1.0, -1.0])
#: The reflection ``y → −y`` of ``[x, vx, y, vy, Ω]``: a turn at ω becomes a turn at −ω.
MIRROR = np.array([1.0, 1.0, -1.0, -1.0, -1.0])


def mirror_modes(model: dict) -> np.ndarray:
    """(M,) int: for each mode j, the mode whose motion is mode j's reflected (same
    transition, noise and offset under :data:`MIRROR`, same estimated-rate flag); a
    one-line :class:`UserError` when a mode has none."""
    F = np.asarray(model["transitions"], dtype=float)
    Q = np.asarray(model["process_noise"], dtype=float)
    M = F.shape[0]
    Q = np.broadcast_to(Q, F.shape)
    U = model.get("offsets")
    U = np.zeros(F.shape[:2]) if U is None else np.asarray(U, dtype=float)
    est = model.get("estimated_turn_rate")
    est = np.zeros(M, bool) if est is None else np.asarray(est, dtype=bool)
    D = np.outer(MIRROR, MIRROR)
    perm = np.full(M, -1)
    for j in range(M):
        for i in range(M):
            if (
                est[i] == est[j]
                and np.allclose(F[i], D * F[j], rtol=1e-9, atol=1e-12)
                and np.allclose(Q[i], D * Q[j], rtol=1e-9, atol=1e-15)
                and np.allclose(U[i], MIRROR * U[j], rtol=1e-9, atol=1e-15)
            ):
                perm[j] = i
                break
        if perm[j] < 0:
            raise UserError(
                f"two-filter smoothing: mode {j} has no mirror mode (a turn at -omega with the "
                "same noise); the model is not its own time reversal"
            )
    return perm


def reversed_model(model: dict):
    """The model flown backwards: (IMM keyword arguments, perm (M,), p (M,)). Reversed mode
    ``perm[j]`` is forward mode j flown backwards (its mirror); the chain is
    ``Π^rev_ij = Π_ji p_j / p_i`` relabelled accordingly, p the forward chain's stationary
    distribution."""
    perm = mirror_modes(model)
    Pi = np.asarray(model["transition_matrix"], dtype=float)
    p = stationary_law(Pi)
    rev = Pi.T * p[None, :] / np.maximum(p[:, None], np.finfo(float).tiny)
    rev /= rev.sum(axis=1, keepdims=True)
    back = np.argsort(perm)  # reversed label a is forward mode back[a]
    out = dict(model)
    out["transition_matrix"] = rev[np.ix_(back, back)]
    return out, perm, p


def rate_prior_variance(model: dict) -> np.ndarray:
    """(M,) (rad/s)²: an estimated-rate mode's turn-rate spread ``Q_j[Ω, Ω] / (1 − Π_jj)``
    (its random walk over a sojourn's mean length); NaN for the other modes."""
    M = len(model["transition_matrix"])
    est = model.get("estimated_turn_rate")
    est = np.zeros(M, bool) if est is None else np.asarray(est, dtype=bool)
    Q = np.broadcast_to(np.asarray(model["process_noise"], dtype=float), (M, 5, 5))
    stay = np.diagonal(np.asarray(model["transition_matrix"], dtype=float))
    om = models.TURN_RATE
    s2 = Q[:, om, om] / np.maximum(1.0 - stay, np.finfo(float).tiny)
    return np.where(est, s2, np.nan)


def _backward(model: dict):
    """What every backward filter shares: the reversed model's IMM arguments, perm (M,) (its
    mode perm[j] is forward mode j), its start's mode probabilities (the stationary ones, in
    its labels) and turn-rate variance (rad/s)²."""
    rmodel, perm, p = reversed_model(model)
    s2 = rate_prior_variance(model)
    omega_var = float(np.nanmax(s2)) if np.isfinite(s2).any() else 1e-6
    return rmodel, perm, p[np.argsort(perm)], omega_var


def _to_forward(mu, x, P, perm):
    """Backward posteriors (..., M), (..., M, 5), (..., M, 5, 5) in forward time and labels."""
    return (
        mu[..., perm],
        x[..., perm, :] * REVERSAL,
        P[..., perm, :, :] * np.outer(REVERSAL, REVERSAL),
    )


def _log_gauss(x, mean, cov):
    """log N(x; mean, cov) over the last axis; x, mean (..., d), cov (..., d, d)."""
    d = x - mean
    maha = np.einsum("...i,...i->...", d, np.linalg.solve(cov, d[..., None])[..., 0])
    return -0.5 * (maha + np.linalg.slogdet(cov)[1] + d.shape[-1] * math.log(2 * math.pi))


def smooth_two_filter(
    z, model: dict, x0, P0, mu0, dt: float, n_steps=None, lag: int | None = None
) -> Smoothed:
    """IMM smoothing of the records ``z`` by a forward and a backward IMM: fixed-interval, or
    fixed-lag with ``lag``.

    Parameters
    ----------
    z : (K, B, m)
        Measurements of K steps of B records (a NaN row: none; the forward IMM steps
        through them from ``x0``, ``P0``, ``mu0`` as :class:`~airspace_sim.tracking.IMM` does).
    model : dict
        The IMM's keyword arguments (``Preset.imm_arguments()``), state ``[x, vx, y, vy,
        Ω]``; every mode must have a mirror mode (:func:`mirror_modes`).
    x0 : (B, 5), P0 : (B, 5, 5), mu0 : (M,)
        The forward filters' start.
    dt : float
        Seconds between steps (the backward filters start from each record's last two
        measurements, :func:`~airspace_sim.tracking.two_point_initialisation`).
    n_steps : (B,) int, optional
        Each record's own length; its steps from ``n_steps[b]`` on are the forward
        filter's predictions. None: all K.
    lag : int, optional
        Fixed-lag smoothing: step k given the measurements up to k + ``lag`` (what a tracker
        that reports ``lag`` steps late can say; 0: the filter). Every step gets its own
        backward filter, started from the last two measured steps of its window (windows
        run side by side, :data:`LAG_WINDOWS` at a time). None: the whole record.

    Returns
    -------
    Smoothed
        μ, x^j, P^j for every step; a record's last step is the forward filter's.
    """
    from airspace_sim.tracking import IMM

    if model.get("along_track_acceleration") is not None:
        raise UserError(
            "two-filter smoothing: models with the along-track acceleration are not supported"
        )
    z = np.asarray(z, dtype=float)
    K, B, _ = z.shape
    x0, P0 = np.asarray(x0, dtype=float), np.asarray(P0, dtype=float)
    if x0.shape != (B, models.N_STATE) or P0.shape != (B, models.N_STATE, models.N_STATE):
        raise UserError(
            f"two-filter smoothing: x0 {x0.shape} and P0 {P0.shape} must be ({B}, 5) and "
            f"({B}, 5, 5)"
        )
    n_steps = np.full(B, K) if n_steps is None else np.asarray(n_steps, dtype=int)
    if n_steps.shape != (B,) or np.any(n_steps > K) or np.any(n_steps < 0):
        raise UserError(f"two-filter smoothing: n_steps must be (B,) = ({B},) in 0..{K}")
    rows = np.arange(B)
    ends = np.stack([z[np.maximum(n_steps - i, 0), rows] for i in (1, 2)])  # (2, B, m)
    long_enough = n_steps >= 2
    bad = long_enough & ~np.all(np.isfinite(ends), axis=(0, 2))
    if bad.any():
        raise UserError(
            f"two-filter smoothing: record {int(np.flatnonzero(bad)[0])} has no measurement at "
            "one of its last two steps (the backward filter starts from them)"
        )
    R = np.asarray(model["measurement_noise"], dtype=float)
    mu0 = np.asarray(mu0, dtype=float)
    mu_f, x_f, P_f = forward_record(IMM(**model, x0=x0, P0=P0, mu0=mu0, gate_probability=1.0), z)
    if lag is not None:
        if isinstance(lag, bool) or not isinstance(lag, (int, np.integer)) or lag < 0:
            raise UserError(
                f"two-filter smoothing: lag must be a non-negative integer, got {lag!r}"
            )
        return _fixed_lag(z, model, (mu_f, x_f, P_f), n_steps, int(lag), dt)

    rmodel, perm, mu0_b, omega_var = _backward(model)
    M = mu0.size
    t = np.arange(K)[:, None]
    src = n_steps[None, :] - 1 - t  # reversed step t is forward step n - 1 - t
    zr = np.where((src >= 0)[..., None], z[np.clip(src, 0, K - 1), rows[None]], np.nan)
    ok_end = np.where(long_enough[:, None], ends, 0.0)
    # the last two measurements in reversed order: the reversed state at step n - 2
    xb0, Pb0 = two_point_initialisation(ok_end[0], ok_end[1], dt, R, 0.0, omega_var)
    mu_r, x_r, P_r = forward_record(
        IMM(**rmodel, x0=xb0, P0=Pb0, mu0=mu0_b, gate_probability=1.0), zr[2:]
    )
    # reversed step 1 is the start itself: the last two measurements, no mode information
    mu_r = np.concatenate([np.broadcast_to(mu0_b, (1, B, M)), mu_r])
    x_r = np.concatenate([np.broadcast_to(xb0[None, :, None], (1, B, M, 5)), x_r])
    P_r = np.concatenate([np.broadcast_to(Pb0[None, :, None], (1, B, M, 5, 5)), P_r])
    # back to forward time and labels: reversed step t >= 1 is forward step k = n - 1 - t
    tt = np.clip(n_steps[None, :] - 1 - np.arange(K)[:, None], 1, K - 1) - 1  # (K, B)
    have = (np.arange(K)[:, None] <= n_steps[None, :] - 2) & long_enough[None, :]
    mu_b, x_b, P_b = _to_forward(
        mu_r[tt, rows[None]], x_r[tt, rows[None]], P_r[tt, rows[None]], perm
    )

    mu_s, x_s, P_s = fuse(mu_f, x_f, P_f, mu_b, x_b, P_b, have, z, model)
    return Smoothed(mu_s, x_s, P_s)


#: Windows (step, record) whose backward filters a fixed-lag pass runs at once.
LAG_WINDOWS = 4096


def _fixed_lag(z, model, forward, n_steps, lag: int, dt: float) -> Smoothed:
    """Fixed-lag two-filter smoothing: for every step k of every record, a backward IMM over
    the window k .. e, e the last step up to k + lag whose measurement and the one before it
    are there (its start), fused with the forward posterior at k; a window with e − 1 < k
    (lag 0, the record's last step, a gap) is the filter's."""
    from airspace_sim.tracking import IMM

    mu_f, x_f, P_f = forward
    K, B = mu_f.shape[:2]
    R = np.asarray(model["measurement_noise"], dtype=float)
    rmodel, perm, mu0_b, omega_var = _backward(model)
    M = mu0_b.size
    steps = np.arange(K)[:, None]
    measured = np.all(np.isfinite(z), axis=-1)
    good = measured & np.vstack([np.zeros((1, B), bool), measured[:-1]])  # z_t and z_{t-1}
    last_good = np.maximum.accumulate(np.where(good, steps, -1), axis=0)
    kk, bb = np.nonzero(steps < n_steps[None, :])  # live (step, record)
    e = last_good[np.minimum(kk + lag, n_steps[bb] - 1), bb]
    on = e - 1 >= kk
    mu_s, x_s, P_s = mu_f.copy(), x_f.copy(), P_f.copy()
    kk, bb, e = kk[on], bb[on], e[on]
    for lo in range(0, kk.size, LAG_WINDOWS):
        k, b, end = (a[lo : lo + LAG_WINDOWS] for a in (kk, bb, e))
        W = k.size
        cap = end - 1 - k  # backward steps from its start (at end - 1) to k
        xb0, Pb0 = two_point_initialisation(z[end, b], z[end - 1, b], dt, R, 0.0, omega_var)
        mu_b = np.broadcast_to(mu0_b, (W, M)).copy()
        x_b = np.broadcast_to(xb0[:, None], (W, M, 5)).copy()
        P_b = np.broadcast_to(Pb0[:, None], (W, M, 5, 5)).copy()
        imm = IMM(**rmodel, x0=xb0, P0=Pb0, mu0=mu0_b, gate_probability=1.0)
        for step in range(1, int(cap.max(initial=0)) + 1):
            t = end - 1 - step
            zs = np.where((step <= cap)[:, None], z[np.maximum(t, 0), b], np.nan)
            imm.step(zs)
            at = cap == step
            mu_b[at], x_b[at], P_b[at] = imm.mu[at], imm.x_modes[at], imm.P_modes[at]
        backward = _to_forward(mu_b, x_b, P_b, perm)
        fused = fuse(mu_f[k, b], x_f[k, b], P_f[k, b], *backward, np.ones(W, bool), z[k, b], model)
        mu_s[k, b], x_s[k, b], P_s[k, b] = fused
    return Smoothed(mu_s, x_s, P_s)


def fuse(mu_f, x_f, P_f, mu_b, x_b, P_b, have, z, model: dict):
    """The smoothed μ (..., M), x^j (..., M, 5), P^j (..., M, 5, 5) from the forward filter's
    posteriors at a step and the backward filter's at the same step (forward time and
    labels, its mode i the one that flies on from the step), over any leading shape (...):
    mu (..., M), x (..., M, 5), P (..., M, 5, 5) each; ``have`` (...) where there is a
    backward posterior (elsewhere the forward one is returned); z (..., m) the step's
    measurements (a NaN row: none). The pair fusion of the module docstring."""
    M = mu_f.shape[-1]
    est = model.get("estimated_turn_rate")
    est = np.zeros(M, bool) if est is None else np.asarray(est, dtype=bool)
    Pi = np.asarray(model["transition_matrix"], dtype=float)
    p = stationary_law(Pi)
    s2 = rate_prior_variance(model)
    R = np.asarray(model["measurement_noise"], dtype=float)
    H = np.asarray(model["measurement_matrix"], dtype=float)
    measured = np.all(np.isfinite(z), axis=-1)  # z is in both posteriors
    meas = (np.where(measured[..., None], z, 0.0), measured, H, np.linalg.inv(R), R)
    with np.errstate(divide="ignore"):
        log_f, log_b = np.log(mu_f), np.log(mu_b) - np.log(p)
    log_joint = np.full(mu_f.shape + (M,), -np.inf)  # (j at the step, i flying on from it)
    x_s, P_s = x_f.copy(), P_f.copy()
    five, four = np.arange(5), np.arange(4)
    # each filter's mode posteriors over the components they share, once per mode
    fwd = [_gaussian(x_f[..., j, :], P_f[..., j, :, :], five if est[j] else four, have)
           for j in range(M)]  # fmt: skip
    bwd = {(i, d.size): _gaussian(x_b[..., i, :], P_b[..., i, :, :], d, have)
           for i in range(M) for d in ((five, four) if est[i] else (four,))}  # fmt: skip
    for j in range(M):
        pairs = []
        for i in range(M):
            if est[i] and not est[j]:  # the backward rate conditioned on the forward pinned one
                back, extra = _conditioned(x_b[..., i, :], P_b[..., i, :, :], x_f[..., j, 4],
                                           s2[i], have)  # fmt: skip
            else:
                back, extra = bwd[i, 5 if est[i] and est[j] else 4], 0.0
            prior = s2[i] if est[i] and est[j] else None
            pairs.append(_fuse_pair(x_f[..., j, :], P_f[..., j, :, :], fwd[j], back, extra,
                                    prior, have, meas))  # fmt: skip
        with np.errstate(divide="ignore"):
            log_pi = np.log(Pi[j])
        for i, (log_c, _, _) in enumerate(pairs):
            log_joint[..., j, i] = log_f[..., j] + log_pi[i] + log_b[..., i] + log_c
        # mode j's smoothed estimate: its pairs' fused estimates, moment-matched
        lj = log_joint[..., j, :]
        top = np.max(lj, axis=-1)
        w = np.exp(lj - np.where(np.isfinite(top), top, 0.0)[..., None])
        w /= np.maximum(w.sum(axis=-1, keepdims=True), np.finfo(float).tiny)
        xp = np.stack([x for _, x, _ in pairs], axis=-2)  # (..., M_i, 5)
        Pp = np.stack([P for _, _, P in pairs], axis=-3)
        xm = np.einsum("...i,...ia->...a", w, xp)
        e = xp - xm[..., None, :]
        Pm = np.einsum("...i,...iac->...ac", w, Pp + e[..., :, None] * e[..., None, :])
        ok = np.isfinite(top)
        x_s[..., j, :] = np.where(ok[..., None], xm, x_f[..., j, :])
        P_s[..., j, :, :] = np.where(ok[..., None, None], Pm, P_f[..., j, :, :])
    flat = log_joint.reshape(mu_f.shape[:-1] + (M * M,))
    fused = np.isfinite(flat).any(axis=-1)
    top = np.where(fused, flat.max(axis=-1), 0.0)
    joint = np.exp(log_joint - top[..., None, None]).sum(axis=-1)
    mu_s = joint / np.maximum(joint.sum(axis=-1, keepdims=True), np.finfo(float).tiny)
    return np.where(fused[..., None], mu_s, mu_f), x_s, P_s


def _gaussian(x, P, dims, have):
    """A posterior over the components ``dims``: mean (..., d), covariance, information
    (its inverse) and log-determinant; the unit Gaussian where ``have`` is False."""
    eye = np.eye(dims.size)
    P = np.where(have[..., None, None], P[..., dims[:, None], dims], eye)
    return (
        np.where(have[..., None], x[..., dims], 0.0),
        P,
        np.linalg.inv(P),
        np.linalg.slogdet(P)[1],
    )


def _conditioned(xb, Pb, w0, s2_b, have):
    """The backward posterior of an estimated-rate mode conditioned on the forward mode's
    pinned rate ``w0`` (...): its position–velocity Gaussian (as :func:`_gaussian`) and the
    log of its rate density at ``w0`` over its prior's."""
    pv = np.arange(4)
    var = np.maximum(Pb[..., 4, 4], np.finfo(float).tiny)
    gain = Pb[..., pv, 4] / var[..., None]
    x = xb[..., pv] + gain * (w0 - xb[..., 4])[..., None]
    P = Pb[..., pv[:, None], pv] - gain[..., :, None] * Pb[..., 4, pv][..., None, :]
    extra = _log_gauss(w0[..., None], xb[..., 4:], var[..., None, None]) - _log_gauss(
        w0[..., None], np.zeros(1), np.array([[s2_b]])
    )
    x5, P5 = np.zeros(xb.shape), np.zeros(Pb.shape)
    x5[..., pv], P5[..., pv[:, None], pv] = x, P
    return _gaussian(x5, P5, pv, have), np.where(have, extra, 0.0)


def _log_gauss_info(x, mean, J, logdet):
    """log N(x; mean, P) with P's information J and log-determinant given."""
    d = x - mean
    maha = np.einsum("...i,...i->...", d, np.einsum("...ij,...j->...i", J, d))
    return -0.5 * (maha + logdet + d.shape[-1] * math.log(2 * math.pi))


def _fuse_pair(xf, Pf, fwd, back, extra, prior_var, have, meas):
    """Fuse forward mode j's posterior at k with backward mode i's (i the mode of step
    k + 1, which the reversed filter flew from k + 1 back to k).

    xf (..., 5), Pf (..., 5, 5) forward mode j's posterior; ``fwd``, ``back`` the two
    Gaussians over the components they share (:func:`_gaussian`: the forward mode's free
    ones, the backward one's first 4 or all 5 of them); ``extra`` (...) a log factor of the
    backward side (:func:`_conditioned`); ``prior_var`` the backward filter's turn-rate
    prior variance to divide out when both estimate Ω, else None; ``have`` (...) where the
    backward filter has an estimate; ``meas`` (z (..., m), measured (...), H, R⁻¹, R).
    Returns log c (...), the integral of ``N_f N_b / (N(z_k; Hx, R) p_0)`` (−inf where no
    fusion), and the fused x (..., 5), P (..., 5, 5).

    Ω: a mode that pins it (straight or known-rate) holds it at its value (forward) or
    says nothing of the rate at k (backward: mode i moves the aircraft from k with Ω_k only
    when it estimates it); forward pinned and backward estimated: the backward estimate is
    conditioned on the forward value.
    """
    z, measured, H, Ri, R = meas
    xf_u, Pf_u, Jf, logdet_f = fwd
    xb_u, _, Jb, logdet_b = back
    d, nb = xf_u.shape[-1], xb_u.shape[-1]
    U = np.arange(d)  # the forward mode's free components: the first 4 or all 5
    eye = np.eye(d)
    Hu = H[:, U]
    J = Jf.copy()
    J[..., :nb, :nb] += Jb
    J -= measured[..., None, None] * (Hu.T @ Ri @ Hu)
    h = np.einsum("...ij,...j->...i", Jf, xf_u)
    h[..., :nb] += np.einsum("...ij,...j->...i", Jb, xb_u)
    h -= z @ (Ri @ Hu)
    if prior_var is not None:  # the backward filter's own prior on the rate, divided out
        J[..., 4, 4] -= 1.0 / prior_var
    J = np.where(have[..., None, None], J, eye)
    pd = have & np.all(np.linalg.eigvalsh(J) > 0, axis=-1)
    J = np.where(pd[..., None, None], J, eye)
    logdet = np.linalg.slogdet(J)[1]
    x = np.linalg.solve(J, h[..., None])[..., 0]
    resid = z - x @ Hu.T
    log_c = (
        _log_gauss_info(x, xf_u, Jf, logdet_f)
        + _log_gauss_info(x[..., :nb], xb_u, Jb, logdet_b)
        - np.where(measured, _log_gauss(resid, np.zeros(z.shape[-1]), R), 0.0)
        + 0.5 * d * math.log(2 * math.pi)
        - 0.5 * logdet
        + extra
    )
    if prior_var is not None:
        log_c -= _log_gauss(x[..., 4:], np.zeros(1), np.array([[prior_var]]))
    xs, Ps = xf.copy(), Pf.copy()
    xs[..., U] = np.where(pd[..., None], x, xf_u)
    Ps[..., U[:, None], U] = np.where(pd[..., None, None], np.linalg.inv(J), Pf_u)
    return np.where(pd, log_c, -np.inf), xs, Ps
