"""Conflict probability from the IMM's mode mixture (``seed-model.md`` §3, weakness 2).

The paper (§VI, assumption 4) notes that its prediction ignores that a forecast grows less
certain the further ahead it looks. The IMM gives, for each pair, mode-conditioned predicted
relative positions ``x_{m,s}`` and covariances ``P_{m,s}`` (mode ``m``, step ``s``) and mode
probabilities ``μ_m``. This module computes

    P(conflict) ≈ Σ_m μ_m · max_s P(|X_{m,s}| < R),   X_{m,s} ~ N(x_{m,s}, P_{m,s})

The max over steps is a lower bound of the probability that *some* step is inside (exact
when the steps' errors are fully correlated, the usual case for a short straight prediction);
the mixture over modes is exact given the per-mode values.

The disc probability of a 2-D Gaussian is computed deterministically: in the covariance's
eigenbasis (standard deviations ``σ_s ≤ σ_l``) it is the 1-D integral over the small-σ
coordinate ``x`` of its Gaussian density times the exact probability
``Φ((h − m_l)/σ_l) − Φ((−h − m_l)/σ_l)`` that the other coordinate lies in the chord
``|y| < h = √(R² − x²)``. The outer integral runs over ``[−R, R] ∩ [m_s ± 8σ_s]``, split
into three panels at ``x = ±√(R² − m_l²)`` where the chord probability switches, with fixed
Gauss–Legendre nodes per panel after a map whose nodes cluster at the switch points and at
``x = ±R`` (removing the chord's square-root singularity there). Absolute error is about 1e-6 or better in typical cases (tested against Monte Carlo).
Degenerate covariances take the exact limits (zero covariance → indicator of ``|x| < R``).
"""

from __future__ import annotations

import numpy as np
from scipy.special import ndtr

#: Gauss–Legendre nodes per panel of the outer integral (three panels).
N_NODES = 48
_NODES, _WEIGHTS = np.polynomial.legendre.leggauss(N_NODES)


def _panel_maps():
    """Maps ``g: [−1, 1] → [0, 1]`` and ``dg/dτ`` by kind = 1·(cluster low end) + 2·(high end).

    A clustered end has ``g' = 0`` there, so a square-root singularity ``√(x − end)`` becomes
    smooth and a sharp switch at the end is resolved by the ``(1 ∓ τ)²`` node spacing.
    """
    s = 0.5 * (1.0 + _NODES)
    q = 0.25 * np.pi
    g = np.stack([s, 1 - np.cos(2 * q * s), np.sin(2 * q * s), 0.5 * (1 - np.cos(4 * q * s))])
    dg = np.stack([np.full_like(s, 0.5), q * np.sin(2 * q * s), q * np.cos(2 * q * s),
                   q * np.sin(4 * q * s)])
    return g, dg


_MAP, _DMAP = _panel_maps()
#: Half-width of the outer integration window, in standard deviations.
WINDOW_SIGMAS = 8.0


def probability_inside_circle(mean, cov, radius):
    """Probability that ``X ~ N(mean, cov)`` lies strictly inside the circle ``|X| < radius``.

    Parameters
    ----------
    mean : array_like, shape ``(..., 2)``
        Mean relative position, m.
    cov : array_like, shape ``(..., 2, 2)``
        Covariance, m² (symmetric positive semi-definite).
    radius : float or array broadcastable to ``(...)``
        Circle radius, m (> 0).

    Returns
    -------
    ndarray, shape ``(...)``, values in ``[0, 1]``.
    """
    mean = np.asarray(mean, dtype=float)
    cov = np.asarray(cov, dtype=float)
    shape = np.broadcast_shapes(mean.shape[:-1], cov.shape[:-2], np.shape(radius))
    mean = np.broadcast_to(mean, shape + (2,))
    cov = np.broadcast_to(cov, shape + (2, 2))
    big_r = np.broadcast_to(np.asarray(radius, dtype=float), shape)
    sym = 0.5 * (cov + np.swapaxes(cov, -1, -2))
    lam, vec = np.linalg.eigh(sym)  # ascending eigenvalues
    sig_s = np.sqrt(np.maximum(lam[..., 0], 0.0))
    sig_l = np.sqrt(np.maximum(lam[..., 1], 0.0))
    m_s = np.sum(vec[..., :, 0] * mean, axis=-1)
    m_l = np.sum(vec[..., :, 1] * mean, axis=-1)

    scale = np.maximum(big_r, np.hypot(mean[..., 0], mean[..., 1]))
    tiny = 1e-12 * scale
    degenerate = sig_s <= tiny  # outer Gaussian is a point mass at m_s

    # outer window, as offsets d = x − m_s from the mean (kept local for precision)
    d_lo = np.maximum(-WINDOW_SIGMAS * sig_s, -big_r - m_s)
    d_hi = np.minimum(WINDOW_SIGMAS * sig_s, big_r - m_s)
    d_hi = np.maximum(d_hi, d_lo)  # empty window (mean far outside): zero width
    # the chord probability switches where the chord end h(x) passes |m_l|, at x = ±x*:
    # split the window there so that every sharp feature sits at a panel end
    ml = np.abs(m_l)
    x_star = np.sqrt(np.maximum((big_r - ml) * (big_r + ml), 0.0))
    b1 = np.clip(-x_star - m_s, d_lo, d_hi)
    b2 = np.clip(x_star - m_s, d_lo, d_hi)
    edges = np.stack([d_lo, b1, b2, d_hi], axis=-1)  # (..., 4), non-decreasing
    lo, width = edges[..., :-1], edges[..., 1:] - edges[..., :-1]  # (..., 3)
    # which panel ends need clustered nodes: the switch points, and the window clipped at ±R
    # (the chord's square-root singularity); the ±8σ window ends do not
    clip_lo = -big_r - m_s >= -WINDOW_SIGMAS * sig_s
    clip_hi = big_r - m_s <= WINDOW_SIGMAS * sig_s
    def edge_flag(b):  # a switch point inside the window, or a window end clipped at ±R
        return ((b > d_lo) & (b < d_hi)) | ((b == d_lo) & clip_lo) | ((b == d_hi) & clip_hi)

    flags = np.stack([clip_lo, edge_flag(b1), edge_flag(b2), clip_hi], axis=-1)
    kind = flags[..., :-1] * 1 + flags[..., 1:] * 2
    g, dg = _MAP[kind], _DMAP[kind]  # (..., 3, nodes)
    d = lo[..., None] + width[..., None] * g
    jac = width[..., None] * dg
    r_minus = np.maximum((big_r - m_s)[..., None, None] - d, 0.0)
    r_plus = np.maximum((big_r + m_s)[..., None, None] + d, 0.0)
    h = np.sqrt(r_minus * r_plus)
    sig_s_eff = np.where(degenerate, 1.0, sig_s)[..., None, None]
    dens = np.exp(-0.5 * (d / sig_s_eff) ** 2) / (np.sqrt(2.0 * np.pi) * sig_s_eff)
    inner = _chord_probability(h, m_l[..., None, None], sig_l[..., None, None],
                               tiny[..., None, None])
    integral = np.sum(_WEIGHTS * dens * inner * jac, axis=(-2, -1))

    # point-mass limit in the small direction
    h0 = np.sqrt(np.maximum(big_r**2 - m_s**2, 0.0))
    point = np.where(np.abs(m_s) < big_r, _chord_probability(h0, m_l, sig_l, tiny), 0.0)
    return np.clip(np.where(degenerate, point, integral), 0.0, 1.0)


def _chord_probability(h, m, sig, tiny):
    """``P(|Y| < h)`` for ``Y ~ N(m, sig²)``; the indicator ``|m| < h`` when ``sig ≈ 0``."""
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(sig > tiny, sig, 1.0)
        p = ndtr((h - m) / s) - ndtr((-h - m) / s)
    return np.where(sig > tiny, p, (np.abs(m) < h).astype(float))


def conflict_probability(xs, Ps, mu, r_safe):
    """Mixture conflict probability ``Σ_m μ_m max_s P(|X_{m,s}| < r_safe)``.

    Parameters
    ----------
    xs : array_like, shape ``(..., M, S, 2)``
        Mode-conditioned predicted relative positions (intruder minus ownship), m, for
        ``M`` modes and ``S`` prediction steps.
    Ps : array_like, shape ``(..., M, S, 2, 2)``
        Their position covariances, m².
    mu : array_like, shape ``(..., M)``
        Mode probabilities (summing to 1).
    r_safe : float or array broadcastable to ``(...)``
        Safety radius, m.

    Returns
    -------
    ndarray, shape ``(...)``, in ``[0, 1]``.
    """
    xs = np.asarray(xs, dtype=float)
    r = np.asarray(r_safe, dtype=float)[..., None, None]
    p = probability_inside_circle(xs, Ps, r)  # (..., M, S)
    return np.clip(np.sum(np.asarray(mu, dtype=float) * p.max(axis=-1), axis=-1), 0.0, 1.0)
