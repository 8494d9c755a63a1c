"""The IMM's combination step (paper §IV step 5) for tracks written outside the kernel
(a birth): the kernel combines in its own loop."""

from __future__ import annotations

import numpy as np


def _combine(xm, Pm, mu):
    """Combined estimate Σ_j μ_j x_j and its covariance, (k, M, n), (k, M, n, n), (k, M)."""
    x = np.einsum("bj,bjk->bk", mu, xm)
    d = xm - x[:, None, :]
    P = np.einsum("bj,bjkl->bkl", mu, Pm + d[..., :, None] * d[..., None, :])
    P = 0.5 * (P + np.swapaxes(P, -1, -2))
    return np.ascontiguousarray(x), np.ascontiguousarray(P)
