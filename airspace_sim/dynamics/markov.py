"""The mode chain: transition matrix Π, per step or from sojourn times (paper §II).

``Π[i, j] = Pr(q(k+1) = j | q(k) = i)``: rows sum to one (the paper's "sum over i" is a
typo, see ``docs/paper-notes.md`` §1). A per-step Π silently depends on ΔT, so a
scenario can give mean sojourn times in seconds instead: with the generator matrix
``Λ`` (``Λ[i, i] = −1/τ_i``, ``Λ[i, j] = p_ij/τ_i`` off the diagonal), ``Π(ΔT) = expm(Λ ΔT)``.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import expm

from airspace_sim.errors import UserError


def validate_transition_matrix(
    Pi, name: str = "transition_matrix", atol: float = 1e-9
) -> np.ndarray:
    """Check that ``Pi`` is a square, non-negative, row-stochastic matrix; return it as float.

    Raises :class:`UserError` naming ``name``, the offending row and its value.
    """
    try:
        P = np.array(Pi, dtype=float)
    except (TypeError, ValueError):
        raise UserError(f"{name}: must be a square (M, M) matrix of numbers, got {Pi!r}") from None
    if P.ndim != 2 or P.shape[0] != P.shape[1] or P.shape[0] == 0:
        raise UserError(f"{name}: must be a square (M, M) matrix, got shape {P.shape}")
    if not np.all(np.isfinite(P)):
        raise UserError(f"{name}: contains a non-finite value: {P.tolist()}")
    if np.any(P < 0):
        i, j = np.argwhere(P < 0)[0]
        raise UserError(f"{name}: entry [{i}, {j}] = {float(P[i, j]):.12g} is negative")
    sums = P.sum(axis=1)
    bad = np.flatnonzero(np.abs(sums - 1.0) > atol)
    if bad.size:
        i = bad[0]
        raise UserError(
            f"{name}: row {i} sums to {float(sums[i]):.12g}, not 1 (row i = Pr(next mode | mode i))"
        )
    return P


def generator_from_sojourn(sojourn_s, switch_probabilities=None) -> np.ndarray:
    """Generator matrix ``Λ`` (M, M) from mean sojourn times in seconds.

    Parameters
    ----------
    sojourn_s : array of shape ``(M,)``
        Mean time τ_i in seconds spent in mode i before leaving it; must be positive.
    switch_probabilities : array of shape ``(M, M)``, optional
        ``p_ij``: where mode i goes when it leaves (diagonal ignored, rows renormalised).
        Default: uniform over the other modes.
    """
    tau = np.asarray(sojourn_s, dtype=float)
    if tau.ndim != 1 or tau.size == 0:
        raise UserError(f"sojourn_s: must be a 1-d list of times in seconds, got {tau.tolist()}")
    if not np.all(np.isfinite(tau)) or np.any(tau <= 0):
        raise UserError(f"sojourn_s: times must be positive and finite seconds, got {tau.tolist()}")
    M = tau.size
    if switch_probabilities is None:
        p = np.ones((M, M)) - np.eye(M)
    else:
        p = np.array(switch_probabilities, dtype=float)
        if p.shape != (M, M) or np.any(p < 0) or not np.all(np.isfinite(p)):
            raise UserError(f"switch_probabilities: must be a non-negative ({M}, {M}) matrix")
        np.fill_diagonal(p, 0.0)
    rows = p.sum(axis=1, keepdims=True)
    if M > 1 and np.any(rows == 0):
        raise UserError("switch_probabilities: every mode needs somewhere to switch to")
    p = np.divide(p, rows, out=np.zeros_like(p), where=rows > 0)
    G = p / tau[:, None]
    G[np.diag_indices(M)] = -1.0 / tau if M > 1 else 0.0
    return G


def transition_matrix_from_sojourn(sojourn_s, dt: float, switch_probabilities=None) -> np.ndarray:
    """Per-step ``Π(ΔT) = expm(Λ ΔT)`` (M, M) for mean sojourn times in seconds."""
    if not (isinstance(dt, (int, float, np.floating, np.integer)) and np.isfinite(dt) and dt > 0):
        raise UserError(f"dt: must be a positive number of seconds, got {dt!r}")
    Pi = expm(generator_from_sojourn(sojourn_s, switch_probabilities) * dt)
    Pi = np.clip(Pi, 0.0, None)
    Pi /= Pi.sum(axis=1, keepdims=True)
    return validate_transition_matrix(Pi)


def stationary_law(transition_matrix) -> np.ndarray:
    """(M,) the chain's stationary law: ``p Π = p``, ``Σ p = 1``, for a row-stochastic Π
    (M, M) (least squares, so a chain with several closed classes still gets an answer;
    round-off negatives are clipped)."""
    Pi = np.asarray(transition_matrix, dtype=float)
    M = Pi.shape[0]
    A = np.vstack([Pi.T - np.eye(M), np.ones((1, M))])
    b = np.zeros(M + 1)
    b[-1] = 1.0
    p = np.clip(np.linalg.lstsq(A, b, rcond=None)[0], 0.0, None)
    return p / p.sum()


def mode_cdf(transition_matrix) -> np.ndarray:
    """Row-wise cumulative Π (M, M), each row divided by its last entry so that it ends at
    exactly 1 (a zero-probability mode, trailing ones included, is never drawn)."""
    cdf = np.cumsum(np.asarray(transition_matrix, dtype=float), axis=-1)
    return cdf / cdf[..., -1:]


def next_modes(cdf: np.ndarray, previous, u) -> np.ndarray:
    """Next modes by inverse-CDF sampling (paper §II, the Markov chain ``Π``).

    cdf : (M, M) from :func:`mode_cdf`; previous : (B,) int modes; u : (B,) uniforms in
    [0, 1). The next mode is the number of cumulative probabilities ``≤ u``: (B,) int.
    """
    return (np.asarray(u)[..., None] >= cdf[np.asarray(previous)]).sum(axis=-1)
