"""Checks of the IMM's user inputs (one-line :class:`~airspace_sim.errors.UserError`
naming the argument and the bad entry) and read-only views of its buffers."""

from __future__ import annotations

import numpy as np

from airspace_sim.errors import UserError


def _array(value, name: str, ndim: int | tuple, shape=None) -> np.ndarray:
    try:
        a = np.array(value, dtype=float, order="C")
    except (TypeError, ValueError) as exc:
        raise UserError(f"IMM {name}: not a numeric array ({exc})") from None
    dims = (ndim,) if isinstance(ndim, int) else ndim
    if a.ndim not in dims:
        raise UserError(
            f"IMM {name}: expected {' or '.join(f'{d}-d' for d in dims)} array, got shape {a.shape}"
        )
    if shape is not None and a.shape != tuple(shape):
        raise UserError(f"IMM {name}: expected shape {tuple(shape)}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        idx = tuple(int(i) for i in np.argwhere(~np.isfinite(a))[0])
        raise UserError(f"IMM {name}: non-finite value {a[idx]!r} at index {list(idx)}")
    return a


def _check_symmetric(a: np.ndarray, name: str) -> np.ndarray:
    """Raise unless ``a`` (..., k, k) is symmetric to 1e-9 relative; return it symmetrised."""
    at = np.swapaxes(a, -1, -2)
    scale = np.maximum(np.abs(a).max(axis=(-1, -2), keepdims=True), np.finfo(float).tiny)
    bad = np.abs(a - at) > 1e-9 * scale
    if np.any(bad):
        idx = tuple(int(i) for i in np.argwhere(bad)[0])
        raise UserError(
            f"IMM {name}: not symmetric (entry {list(idx)} = {a[idx]!r} differs from its transpose)"
        )
    return np.ascontiguousarray(0.5 * (a + at))


def _check_psd(a: np.ndarray, name: str, strict: bool) -> None:
    """Raise unless every matrix of ``a`` (..., k, k) is positive (semi-)definite."""
    flat = a.reshape((-1,) + a.shape[-2:])
    if flat.shape[0] == 0:
        return
    w = np.linalg.eigvalsh(flat)
    scale = np.maximum(np.abs(w).max(axis=-1), np.finfo(float).tiny)
    bad = (w[:, 0] <= 0) if strict else (w[:, 0] < -1e-12 * scale)
    if np.any(bad):
        i = int(np.flatnonzero(bad)[0])
        where = f" (matrix {np.unravel_index(i, a.shape[:-2])})" if a.ndim > 2 else ""
        kind = "positive definite" if strict else "positive semi-definite"
        raise UserError(f"IMM {name}: not {kind}{where}: smallest eigenvalue {w[i, 0]!r}")


def _ro(a: np.ndarray) -> np.ndarray:
    v = a.view()
    v.flags.writeable = False
    return v
