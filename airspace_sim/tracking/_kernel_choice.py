"""Which step kernel runs an IMM model, and the sparsity of its matrices that the kernels
read (:mod:`._codegen`: straight-line code generated for the model; :mod:`._kernels`: one
loops kernel for every model size)."""

from __future__ import annotations

import numpy as np

from airspace_sim.errors import UserError
from airspace_sim.tracking import _codegen, _kernels


def _nonzeros(mats: np.ndarray):
    """Row, column, value of the non-zeros of each (k, l) matrix in ``mats`` (G, k, l), padded."""
    G = mats.shape[0]
    nnz = np.array([np.count_nonzero(a) for a in mats], dtype=np.int64)
    K = max(int(nnz.max(initial=0)), 1)
    rows = np.zeros((G, K), dtype=np.int64)
    cols = np.zeros((G, K), dtype=np.int64)
    vals = np.zeros((G, K))
    for g, a in enumerate(mats):
        r, c = np.nonzero(a)
        rows[g, : r.size], cols[g, : r.size], vals[g, : r.size] = r, c, a[r, c]
    return rows, cols, vals, nnz


def choose_kernel(F: np.ndarray, H: np.ndarray, estimated_turn_rate: np.ndarray, kernel: str):
    """(step function, chunk width W, name) of the kernel for transitions F (M, n, n),
    measurement matrix H (m, n) and the (M,) estimated-rate flags; ``kernel`` as for
    :class:`~airspace_sim.tracking.imm.IMM` ("auto", "generated", "loops")."""
    generated = None
    if estimated_turn_rate.any():
        # the EKF mode is in the loops kernel only (its Jacobian is per tracker)
        if kernel == "generated":
            raise UserError("IMM kernel: 'generated' has no estimated-rate modes; use 'auto'")
        kernel = "loops"
    if kernel != "loops":
        budget = None if kernel == "generated" else _codegen.AUTO_MAX_PRODUCTS
        generated = _codegen.step_kernel(F, H, max_products=budget)
    if generated is not None:
        return generated, _codegen.CHUNK, "generated"
    return _kernels.imm_step_kernel(), _kernels.CHUNK, "loops"
