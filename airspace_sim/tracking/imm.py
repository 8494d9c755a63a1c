"""Batched Interacting Multiple Model (IMM) estimator (paper §IV).

One :class:`IMM` object tracks ``B`` independent targets with the same jump-Markov model:
``M`` linear-Gaussian modes ``x(k) = F_j x(k−1) + u_j + w_j``, ``w_j ~ N(0, Q_j)``, a mode
chain with row-stochastic ``Π`` (``Π[i, j] = Pr(next mode j | mode i)``) and linear
measurements ``z = H x + v``, ``v ~ N(0, R)``. Each :meth:`IMM.step` runs one IMM cycle
(Bar-Shalom, Li & Kirubarajan 2001, §11.6.6) for all trackers in a single numba loop:

1. mixing probabilities ``μ_{i|j} = π_ij μ_i / c̄_j`` with ``c̄_j = Σ_i π_ij μ_i``;
2. mixed initial conditions ``x0j = Σ_i μ_{i|j} x_i``,
   ``P0j = Σ_i μ_{i|j} [P_i + (x_i − x0j)(x_i − x0j)ᵀ]``;
3. mode-matched Kalman filtering: predict ``x_j = F_j x0j + u_j``,
   ``P_j = F_j P0j F_jᵀ + Q_j``; update with gain ``K_j = P_j Hᵀ S_j⁻¹``, Joseph-form
   covariance, and the Gaussian likelihood ``Λ_j = N(z; H x_j, S_j)``;
4. mode probabilities ``μ_j = Λ_j c̄_j / Σ_l Λ_l c̄_l``, computed in log space with
   log-sum-exp so that no likelihood underflows;
5. combination ``x = Σ_j μ_j x_j``, ``P = Σ_j μ_j [P_j + (x_j − x)(x_j − x)ᵀ]``.

Missing measurements and gating
-------------------------------
A measurement row containing any NaN (or inf) means "no measurement": that tracker is
predicted only (steps 1–3a), its mode probabilities become ``c̄``. A measurement that no
mode explains — every reachable mode's Mahalanobis distance ``d²_j = ν_jᵀ S_j⁻¹ ν_j``
exceeds the chi-square quantile of ``gate_probability`` for ``m`` degrees of freedom — is
treated the same way and flagged in :attr:`IMM.gated`: an outlier neither produces NaN nor
erases the mode probabilities (they become ``c̄``, the prediction of the evidence so far).
A mode whose ``d²`` is not finite (e.g. ``z = 1e200``) explains nothing, even with the gate
disabled. Within the gate the result is the textbook IMM, equal to
``filterpy.kalman.IMMEstimator`` to rounding (tests/test_imm_filterpy.py).

Mode probabilities are computed as ``μ_j = c̄_j exp(ℓ_j − max ℓ) / Σ_l c̄_l exp(ℓ_l − max ℓ)``
with ``ℓ_j = log Λ_j``: the log-sum-exp normalisation, so that no likelihood underflows to
zero unless it is negligible against the best mode's (filterpy instead floors ``Λ_j`` at
``sys.float_info.min``, after which μ silently equals c̄). A mode that cannot be reached
(``c̄_j = 0``) keeps its own estimate in the mixing step and keeps ``μ_j = 0``.

Storage
-------
:class:`SlotIMM` holds the filters in stable slots of the kernel's chunked
structure-of-arrays layout (a free list, an alive mask, geometric growth): births and drops
cost O(tracks that change) and the step skips free chunks. :class:`IMM` is the dense view
(rows 0..B−1, ``append``/``remove`` keeping the order of the rest) over it.

Units are whatever the model uses; in this project SI (m, m/s, rad/s), state
``[x, vx, y, vy, Ω]``.
"""

from __future__ import annotations

import math

import numpy as np

from airspace_sim.dynamics.markov import validate_transition_matrix
from airspace_sim.errors import UserError
from airspace_sim.resources import check_allocation
from airspace_sim.tracking import _codegen, _kernels
from airspace_sim.tracking.slots import Slots

#: Default gate: a measurement is dropped when it lies outside the 1 − 10⁻⁶ chi-square
#: region of every mode (d² > 27.6 for m = 2): an in-model measurement is dropped
#: about once per million updates, a 10-sigma outlier always.
DEFAULT_GATE_PROBABILITY = 1.0 - 1e-6

#: :class:`IMM` warns when a tracker has rejected this many measurements since it started
#: and accepted none (a start far from the target, e.g. x0 = 0 for an aircraft 50 km away).
GATED_START_WARNING = 5


def gate_threshold(gate_probability: float, m: int = 2) -> float:
    """The gate on d² = νᵀ S⁻¹ ν for ``gate_probability`` and ``m`` measurement components:
    the χ²(m) quantile with Pr(d² > gate) = 1 − p (inf for p = 1, no gate). 27.6 for the
    default 1 − 10⁻⁶ and m = 2."""
    if gate_probability == 1.0:
        return float("inf")
    from scipy.special import chdtri  # lighter to import than scipy.stats

    return float(chdtri(m, 1.0 - gate_probability))


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


def _ro(a: np.ndarray) -> np.ndarray:
    v = a.view()
    v.flags.writeable = False
    return v


def _combine(xm, Pm, mu):
    """Combined estimate Σ_j μ_j x_j and its covariance, (k, M, n), (k, M, n, n), (k, M)."""
    x = np.einsum("bj,bjk->bk", mu, xm)
    d = xm - x[:, None, :]
    P = np.einsum("bj,bjkl->bkl", mu, Pm + d[..., :, None] * d[..., None, :])
    P = 0.5 * (P + np.swapaxes(P, -1, -2))
    return np.ascontiguousarray(x), np.ascontiguousarray(P)


class SlotIMM:
    """IMM filters (paper §IV) in stable slots of the kernel's structure-of-arrays layout.

    The storage of every IMM in the project: :class:`IMM` is a dense view over it and the
    world's ``"imm"`` tracker uses it directly. Model parameters as for :class:`IMM`
    (``transitions`` … ``kernel``); ``capacity`` lanes are allocated at first (rounded up
    to whole chunks), none live.

    Slots
    -----
    Lane ``s`` lives in chunk ``s // W``, lane ``s % W`` of ``xs (C, M, n, W)``,
    ``Ps (C, M, n, n, W)`` (the generated kernel stores the upper triangles,
    ``(C, M, n(n+1)/2, W)``) and ``mus (C, M, W)``, with ``W`` the kernel's chunk width and
    ``C·W = capacity``. :meth:`birth` writes free lanes, :meth:`drop` frees lanes (the free
    list is :class:`~airspace_sim.tracking.slots.Slots`); no other lane is read or written,
    so both cost O(k) for k tracks. When no lane is free the capacity at least doubles (one
    O(capacity) copy, amortised). :meth:`step` skips chunks without a live lane; a free
    lane in a live chunk holds a fixed benign state (x = 0, P = I, uniform μ, written when it
    is freed) and is never written by the kernel, so it costs no repack and cannot overflow
    or turn NaN however long it stays free.

    Outputs and ownership
    ---------------------
    ``x (capacity, n)``, ``P (capacity, n, n)``, ``mu``, ``nis``, ``log_likelihood``,
    ``gated`` and ``alive`` are read-only views of this object's own buffers, by slot; free
    slots hold NaN (``gated``: False). The buffers are overwritten in place by the next
    :meth:`step`, :meth:`birth` or :meth:`drop` and replaced when the capacity grows: a view
    is valid until then. Copy what you keep.
    """

    def __init__(
        self,
        transitions,
        process_noise,
        measurement_matrix,
        measurement_noise,
        transition_matrix,
        offsets=None,
        gate_probability: float = DEFAULT_GATE_PROBABILITY,
        kernel: str = "auto",
        capacity: int = 0,
        estimated_turn_rate=None,
        dt=None,
        mode_names=None,
    ):
        F = _array(transitions, "transitions", 3)
        M, n, n2 = F.shape
        if n != n2 or n == 0 or M == 0:
            raise UserError(f"IMM transitions: expected shape (M, n, n), got {F.shape}")
        Q = _array(process_noise, "process_noise", (2, 3))
        if Q.shape == (n, n):
            Q = np.broadcast_to(Q, (M, n, n)).copy()
        if Q.shape != (M, n, n):
            raise UserError(
                f"IMM process_noise: expected shape {(M, n, n)} (like transitions), got {Q.shape}"
            )
        Q = _check_symmetric(Q, "process_noise")
        _check_psd(Q, "process_noise", strict=False)
        H = _array(measurement_matrix, "measurement_matrix", 2)
        if H.shape[1] != n or H.shape[0] == 0:
            raise UserError(f"IMM measurement_matrix: expected shape (m, {n}), got {H.shape}")
        m = H.shape[0]
        R = _array(measurement_noise, "measurement_noise", 2, (m, m))
        R = _check_symmetric(R, "measurement_noise")
        _check_psd(R, "measurement_noise", strict=True)
        Pi = validate_transition_matrix(transition_matrix, name="IMM transition_matrix")
        if Pi.shape != (M, M):
            raise UserError(
                f"IMM transition_matrix: expected shape {(M, M)} for {M} modes, got {Pi.shape}"
            )
        Pi = np.ascontiguousarray(Pi / Pi.sum(axis=1, keepdims=True))
        U = np.zeros((M, n)) if offsets is None else _array(offsets, "offsets", 2, (M, n))
        try:
            p = float(gate_probability)
        except (TypeError, ValueError):
            raise UserError(
                f"IMM gate_probability: must be a number in (0, 1], got {gate_probability!r}"
            ) from None
        if not (0.0 < p <= 1.0):
            raise UserError(f"IMM gate_probability: must be in (0, 1], got {gate_probability!r}")
        gate_d2 = gate_threshold(p, m)

        ct = np.zeros(M, dtype=bool)
        if estimated_turn_rate is not None:
            ct = np.array(estimated_turn_rate, dtype=bool).reshape(-1)
            if ct.shape != (M,):
                raise UserError(
                    f"IMM estimated_turn_rate: expected {M} flags (one per mode), got {ct.size}"
                )
        if ct.any():
            if n != 5:
                raise UserError(
                    f"IMM estimated_turn_rate: needs the state [x, vx, y, vy, Ω] (n = 5), got n = {n}"
                )
            try:
                dt = float(dt)
            except (TypeError, ValueError):
                raise UserError(
                    f"IMM dt: estimated-rate modes need the step in seconds, got {dt!r}"
                ) from None
            if not (np.isfinite(dt) and dt > 0):
                raise UserError(f"IMM dt: must be a positive number of seconds, got {dt!r}")
        self._ct, self._dt = ct, (float("nan") if dt is None else float(dt))
        names = tuple(f"mode{j}" for j in range(M)) if mode_names is None else tuple(mode_names)
        if len(names) != M or not all(isinstance(v, str) for v in names):
            raise UserError(f"IMM mode_names: expected {M} strings, got {mode_names!r}")
        #: (M,) names of the modes (e.g. ``straight``, ``left 3°/s``)
        self.mode_names = names
        self._preset = None
        self._per_dt: dict = {}
        self._F, self._Q, self._U, self._H, self._R, self._Pi = F, Q, U, H, R, Pi
        self._Fr, self._Fc, self._Fv, self._Fnnz = _nonzeros(F)
        Hr, Hc, Hv, _ = _nonzeros(H[None])
        nh = int(np.count_nonzero(H))
        self._Hr, self._Hc, self._Hv = Hr[0, :nh].copy(), Hc[0, :nh].copy(), Hv[0, :nh].copy()
        self.gate_probability = p
        #: chi-square threshold on d² (inf = no gating)
        self.gate_threshold = gate_d2
        self.M, self.n, self.m = M, n, m
        if kernel not in ("auto", "generated", "loops"):
            raise UserError(f"IMM kernel: expected 'auto', 'generated' or 'loops', got {kernel!r}")
        self._choose_kernel(kernel)
        self._tri_k, self._tri_l = np.triu_indices(n)
        W = self._W
        self._slots = Slots(W)
        pshape = (len(self._tri_k),) if self._tri else (n, n)
        self._xs = np.zeros((0, M, n, W))
        self._Ps = np.zeros((0, M) + pshape + (W,))
        self._mus = np.zeros((0, M, W))
        # a free lane's state: finite, and stays finite under a prediction without update
        eye = np.eye(n)
        self._free_P = eye[self._tri_k, self._tri_l] if self._tri else eye
        self._x = np.zeros((0, n))
        self._P = np.zeros((0, n, n))
        self._mu = np.zeros((0, M))
        self._nis = np.zeros(0)
        self._ll = np.zeros((0, M))
        self._gated = np.zeros(0, dtype=bool)
        if capacity:
            self._grow(self._slots.capacity_for(int(capacity)))

    # ------------------------------------------------------------------ helpers
    def _choose_kernel(self, kernel: str) -> None:
        generated = None
        if self._ct.any():
            # the EKF mode is in the loops kernel only (its Jacobian is per tracker)
            if kernel == "generated":
                raise UserError("IMM kernel: 'generated' has no estimated-rate modes; use 'auto'")
            kernel = "loops"
        if kernel != "loops":
            budget = None if kernel == "generated" else _codegen.AUTO_MAX_PRODUCTS
            generated = _codegen.step_kernel(self._F, self._H, max_products=budget)
        if generated is not None:
            self._kernel, self._W, self.kernel = generated, _codegen.CHUNK, "generated"
        else:
            self._kernel, self._W, self.kernel = _kernels.imm_step_kernel(), _kernels.CHUNK, "loops"
        # the generated kernel stores only the upper triangle of each P_j (less to move)
        self._tri = self.kernel == "generated"

    def __getstate__(self) -> dict:
        # the kernel is a compiled function (the generated one from a cache-directory
        # module): pickle the choice made, and find the same kernel again on unpickling
        state = self.__dict__.copy()
        del state["_kernel"]
        return state

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._choose_kernel(self.kernel)

    def _grow(self, capacity: int) -> None:
        """Reallocate every per-slot array to ``capacity`` lanes (new lanes free)."""
        old = self._slots.capacity
        if capacity <= old:
            return
        W, M, n = self._W, self.M, self.n
        C0, C = old // W, capacity // W
        soa = (self._xs, self._Ps, self._mus)  # (C, ..., W): W lanes per chunk
        rows = (self._x, self._P, self._mu, self._nis, self._ll, self._gated)  # (capacity, ...)
        lane_bytes = sum(a.itemsize * math.prod(a.shape[1:]) // W for a in soa) + sum(
            a.itemsize * math.prod(a.shape[1:]) for a in rows
        )
        check_allocation(  # old and new arrays live together while copying
            f"track table: growing to {capacity} tracks",
            (old + capacity) * lane_bytes,
            "fewer aircraft in sensor range of each other (traffic.count, sensor.range)",
        )

        def grown(a, fill, lanes_last):
            shape = ((C,) + a.shape[1:]) if lanes_last else ((capacity,) + a.shape[1:])
            b = np.empty(shape, dtype=a.dtype)
            k = C0 if lanes_last else old
            b[:k] = a
            b[k:] = fill
            return b

        self._xs = grown(self._xs, 0.0, True)
        self._Ps = grown(self._Ps, self._free_P[None, ..., None], True)
        self._mus = grown(self._mus, 1.0 / M, True)
        self._x = grown(self._x, np.nan, False)
        self._P = grown(self._P, np.nan, False)
        self._mu = grown(self._mu, np.nan, False)
        self._nis = grown(self._nis, np.nan, False)
        self._ll = grown(self._ll, np.nan, False)
        self._gated = grown(self._gated, False, False)
        self._slots.grow(capacity)
        assert self._xs.shape == (C, M, n, W)

    def _initial(self, x0, P0, mu0, where: str):
        n, M = self.n, self.M
        x0 = _array(x0, f"{where}x0", 2)
        if x0.shape[1] != n:
            raise UserError(f"IMM {where}x0: expected shape (B, {n}), got {x0.shape}")
        B = x0.shape[0]
        P0 = _array(P0, f"{where}P0", (2, 3))
        if P0.shape == (n, n):
            P0 = np.broadcast_to(P0, (B, n, n)).copy()
        if P0.shape != (B, n, n):
            raise UserError(
                f"IMM {where}P0: expected shape {(B, n, n)} or {(n, n)}, got {P0.shape}"
            )
        P0 = _check_symmetric(P0, f"{where}P0")
        _check_psd(P0, f"{where}P0", strict=True)
        mu0 = _array(mu0, f"{where}mu0", (1, 2))
        if mu0.shape == (M,):
            mu0 = np.broadcast_to(mu0, (B, M)).copy()
        if mu0.shape != (B, M):
            raise UserError(f"IMM {where}mu0: expected shape {(B, M)} or {(M,)}, got {mu0.shape}")
        if np.any(mu0 < 0):
            i, j = np.argwhere(mu0 < 0)[0]
            raise UserError(f"IMM {where}mu0: entry [{i}, {j}] = {mu0[i, j]!r} is negative")
        sums = mu0.sum(axis=1)
        bad = np.flatnonzero(np.abs(sums - 1.0) > 1e-6)
        if bad.size:
            raise UserError(f"IMM {where}mu0: row {bad[0]} sums to {sums[bad[0]]!r}, not 1")
        mu0 = np.ascontiguousarray(mu0 / sums[:, None])
        return x0, P0, mu0

    def _lanes(self, slots):
        return np.divmod(np.asarray(slots, dtype=np.int64), self._W)

    def _write(self, slots, x0, P0, mu0) -> None:
        """Start validated tracks (k, n), (k, n, n), (k, M) in the live lanes ``slots``."""
        k = x0.shape[0]
        M, n = self.M, self.n
        c, w = self._lanes(slots)
        self._xs[c, :, :, w] = x0[:, None, :]
        if self._tri:
            self._Ps[c, :, :, w] = P0[:, None, self._tri_k, self._tri_l]
        else:
            self._Ps[c, :, :, :, w] = P0[:, None]
        self._mus[c, :, w] = mu0
        # combined estimate as filterpy's constructor makes it (Σ μ_j x_j with equal x_j)
        xm = np.broadcast_to(x0[:, None, :], (k, M, n))
        Pm = np.broadcast_to(P0[:, None], (k, M, n, n))
        self._x[slots], self._P[slots] = _combine(xm, Pm, mu0)
        self._mu[slots] = mu0
        self._nis[slots] = np.nan
        self._ll[slots] = np.nan
        self._gated[slots] = False

    # --------------------------------------------------------------- properties
    @property
    def capacity(self) -> int:
        """Number of lanes allocated (a multiple of the kernel's chunk width)."""
        return self._slots.capacity

    @property
    def n_live(self) -> int:
        """Number of live slots."""
        return self._slots.n_live

    @property
    def alive(self) -> np.ndarray:
        """(capacity,) bool, read-only: live slots."""
        return _ro(self._slots.alive)

    @property
    def x(self) -> np.ndarray:
        """(capacity, n) combined posterior states by slot (paper §IV step 5)."""
        return _ro(self._x)

    @property
    def P(self) -> np.ndarray:
        """(capacity, n, n) combined posterior covariances by slot (paper §IV step 5)."""
        return _ro(self._P)

    @property
    def mu(self) -> np.ndarray:
        """(capacity, M) mode probabilities by slot (paper §IV step 4)."""
        return _ro(self._mu)

    @property
    def nis(self) -> np.ndarray:
        """(capacity,) last step's mixture NIS by slot (see :class:`IMM`)."""
        return _ro(self._nis)

    @property
    def log_likelihood(self) -> np.ndarray:
        """(capacity, M) last step's per-mode log-likelihoods by slot (see :class:`IMM`)."""
        return _ro(self._ll)

    @property
    def gated(self) -> np.ndarray:
        """(capacity,) bool: last step's finite measurement was rejected by the gate."""
        return _ro(self._gated)

    # ------------------------------------------------------------------ methods
    def birth(self, x0, P0, mu0) -> np.ndarray:
        """Start k tracks in free lanes; return their slots (k,) int64.

        x0 (k, n), P0 (k, n, n) or (n, n), mu0 (k, M) or (M,) (validated as in
        :class:`IMM`). Every mode starts from (x0, P0); ``nis``/``log_likelihood`` are NaN
        and ``gated`` False until their first step. O(k), plus an amortised growth.
        """
        x0, P0, mu0 = self._initial(x0, P0, mu0, "birth ")
        return self._birth_valid(x0, P0, mu0)

    def _birth_valid(self, x0, P0, mu0) -> np.ndarray:
        k = x0.shape[0]
        need = self._slots.capacity_for(k)
        if need > self.capacity:
            self._grow(need)
        slots = self._slots.take(k)
        if k:
            self._write(slots, x0, P0, mu0)
        return slots

    def drop(self, slots) -> None:
        """Free the live ``slots`` (k,) int: O(k); no other slot changes."""
        s = self._slots.release(slots, "IMM drop")
        if s.size == 0:
            return
        c, w = self._lanes(s)
        self._xs[c, :, :, w] = 0.0
        if self._tri:
            self._Ps[c, :, :, w] = self._free_P
        else:
            self._Ps[c, :, :, :, w] = self._free_P
        self._mus[c, :, w] = 1.0 / self.M
        for a in (self._x, self._P, self._mu, self._nis, self._ll):
            a[s] = np.nan
        self._gated[s] = False

    @classmethod
    def from_preset(cls, preset, **kwargs) -> SlotIMM:
        """The IMM of the preset's tracker model (:meth:`Preset.filter_model`: its own
        matched IMM unless it names another); it can step with any ``dt`` (:meth:`step`).
        ``kwargs``: ``gate_probability``, ``kernel``, ``capacity``."""
        preset = preset.filter_model()
        imm = cls(**preset.imm_arguments(), mode_names=preset.mode_names(), **kwargs)
        imm._preset, imm._dt = preset, preset.dt
        return imm

    def _model_at(self, dt: float):
        """(Fv, Q, U, Pi) of the preset at step ``dt`` s, cached by ``dt``."""
        if self._preset is None:
            raise UserError(
                "IMM step: dt given, but this IMM was built from matrices; build it with "
                "IMM.from_preset(...) to step with other time steps"
            )
        got = self._per_dt.get(dt)
        if got is None:
            a = self._preset.with_(dt=dt).imm_arguments()
            F = np.asarray(a["transitions"], dtype=float)
            rows = np.arange(self.M)[:, None]
            Fv = np.where(np.arange(self._Fr.shape[1]) < self._Fnnz[:, None],
                          F[rows, self._Fr, self._Fc], 0.0)  # fmt: skip
            if np.count_nonzero(F) != np.count_nonzero(Fv):
                raise UserError(f"IMM step: the model at dt={dt!r} s has another sparsity")
            Q = _check_symmetric(_array(a["process_noise"], "process_noise", 3), "process_noise")
            Pi = np.asarray(a["transition_matrix"], dtype=float)
            got = (Fv, Q, np.asarray(a["offsets"], dtype=float), Pi / Pi.sum(1, keepdims=True))
            if len(self._per_dt) >= 256:  # irregular sampling: keep the cache bounded
                self._per_dt.clear()
            self._per_dt[dt] = got
        return got

    def step(self, z, dt=None) -> None:
        """One IMM cycle (paper §IV steps 1–5) for every live slot.

        z : (capacity, m) measurements by slot; a row with any NaN/inf means no measurement
        (predict only); rows of free slots are not read. dt : seconds since the last step,
        or None for the model's own step; another ``dt`` needs an IMM built with
        :meth:`from_preset` (transition matrices, Q and Π are rebuilt for it and cached).
        """
        z = np.ascontiguousarray(z, dtype=float)
        if z.shape != (self.capacity, self.m):
            raise UserError(
                f"IMM step: z must have shape {(self.capacity, self.m)} (by slot), got {z.shape}"
            )
        Fv, Q, U, Pi, step_dt = self._Fv, self._Q, self._U, self._Pi, self._dt
        if dt is not None:
            step_dt = float(dt)
            if not (np.isfinite(step_dt) and step_dt > 0):
                raise UserError(f"IMM step: dt must be a positive number of seconds, got {dt!r}")
            if step_dt != self._dt:
                Fv, Q, U, Pi = self._model_at(step_dt)
        self._kernel(
            self._Fr, self._Fc, Fv, self._Fnnz, Q, U, self._ct, step_dt,
            self._Hr, self._Hc, self._Hv, self._R, Pi, self.gate_threshold,
            z, self._slots.alive, self._xs, self._Ps, self._mus,
            self._x, self._P, self._mu, self._nis, self._ll, self._gated,
        )  # fmt: skip

    def modes(self, slots):
        """Mode-conditioned posteriors of ``slots`` (R,): x_modes (R, M, n), P_modes
        (R, M, n, n) (paper §IV step 3), new arrays."""
        c, w = self._lanes(slots)
        xm = self._xs[c, :, :, w]
        if not self._tri:
            return xm, self._Ps[c, :, :, :, w]
        a = self._Ps[c, :, :, w]
        P = np.empty(a.shape[:2] + (self.n, self.n))
        P[..., self._tri_k, self._tri_l] = a
        P[..., self._tri_l, self._tri_k] = a
        return xm, P

    def predict_modes_at(self, steps, slots):
        """Each mode's own model propagated ``steps`` (S,) positive increasing step counts
        ahead, without mixing, for ``slots`` (R,): xs (R, M, S, n), Ps (R, M, S, n, n)
        (:func:`airspace_sim.tracking.prediction.predict_modes_at`)."""
        from airspace_sim.tracking.prediction import predict_modes_at

        xm, Pm = self.modes(slots)
        xs, Ps = predict_modes_at(self._F, self._Q, self._U, xm, Pm, steps)
        self._predict_ct(xm, Pm, steps, xs, Ps)
        return xs, Ps

    def _predict_ct(self, xm, Pm, steps, xs, Ps) -> None:
        """Overwrite the estimated-rate modes' predictions (EKF, :mod:`.coordinated_turn`)
        in xs (R, M, S, n), Ps (R, M, S, n, n) from xm (R, M, n), Pm (R, M, n, n)."""
        from airspace_sim.tracking import coordinated_turn

        for j in np.flatnonzero(self._ct):
            xs[:, j], Ps[:, j] = coordinated_turn.predict(
                xm[:, j], Pm[:, j], self._Q[j], self._dt, steps
            )

    def __repr__(self) -> str:
        return (
            f"SlotIMM(live={self.n_live}, capacity={self.capacity}, M={self.M}, n={self.n}, "
            f"m={self.m}, kernel={self.kernel!r})"
        )


class IMM:
    """Batched IMM estimator: ``B`` independent trackers sharing one jump-Markov model.

    A dense view (rows ``0 .. B-1``) over :class:`SlotIMM`: row ``i`` is slot ``rows[i]``.

    Parameters
    ----------
    transitions : (M, n, n)
        Mode transition matrices ``F_j``.
    process_noise : (M, n, n) or (n, n)
        Process-noise covariances ``Q_j`` (symmetric, positive semi-definite).
    measurement_matrix : (m, n)
        ``H``.
    measurement_noise : (m, m)
        ``R`` (symmetric, positive definite).
    transition_matrix : (M, M)
        Mode chain ``Π``; row i = ``Pr(next mode | mode i)`` (rows sum to 1).
    x0 : (B, n)
        Initial state of each tracker; every mode starts from it.
    P0 : (B, n, n) or (n, n)
        Initial covariance (symmetric positive definite); every mode starts from it.
    mu0 : (B, M) or (M,)
        Initial mode probabilities (non-negative, rows sum to 1).
    offsets : (M, n), optional
        Per-mode additive term ``u_j``: mode j predicts ``x' = F_j x + u_j``.
    gate_probability : float in (0, 1]
        Chi-square gate (``m`` degrees of freedom) on every mode's ``d²``; 1 disables
        gating. Default :data:`DEFAULT_GATE_PROBABILITY` = 1 − 10⁻⁶.
    kernel : {"auto", "generated", "loops"}
        How the step runs. ``"generated"``: straight-line code written for this model's
        sizes and sparsity (:mod:`._codegen`), compiled once per model structure (~20 s
        for 3 modes × 5 states, then loaded from the disk cache). ``"loops"``: one kernel
        for every model size (:mod:`._kernels`). Both give the same bits. ``"auto"``
        (default) generates unless the code would be slow to compile (over
        :data:`._codegen.AUTO_MAX_PRODUCTS` multiplications, e.g. dense 6-state models);
        the choice made is in the attribute ``kernel``.
    estimated_turn_rate : (M,) bool, optional
        Modes whose turn rate is the state's own Ω (n = 5, state ``[x, vx, y, vy, Ω]``):
        an EKF coordinated turn (:mod:`.coordinated_turn`), for which ``transitions[j]`` is
        not used; such a model runs the ``"loops"`` kernel.
    dt : float, optional
        The step in seconds; needed with estimated-rate modes.
    mode_names : (M,) str, optional
        Names of the modes (attribute ``mode_names``; default ``mode0``, ``mode1``, ...).
        :meth:`from_preset` gives the preset's names and can step with any dt.

    Attributes
    ----------
    x (B, n), P (B, n, n), mu (B, M)
        Combined posterior (paper §IV step 5) and mode probabilities (step 4).
    x_modes (B, M, n), P_modes (B, M, n, n)
        Mode-conditioned posteriors (step 3).
    nis (B,)
        Last step's normalised innovation squared of the mixture innovation
        ``ν = z − Σ_j c̄_j ẑ_j`` with ``S = Σ_j c̄_j [S_j + (ẑ_j − ẑ)(ẑ_j − ẑ)ᵀ]``; NaN where
        there was no measurement, computed (typically large) where it was gated.
    log_likelihood (B, M)
        Last step's ``log N(z; ẑ_j, S_j)`` per mode; NaN where there was no measurement,
        computed (but not used) where the measurement was gated, NaN for a mode whose
        ``d²`` is not finite.
    gated (B,) bool
        Last step's measurement was finite but outside every mode's gate (predict only).

    Ownership: every array attribute is read-only and valid until the next :meth:`step`,
    :meth:`append` or :meth:`remove`, which may overwrite it in place (it can be a view of
    the slot storage's buffers). Copy what you keep across steps.
    """

    def __init__(
        self,
        transitions,
        process_noise,
        measurement_matrix,
        measurement_noise,
        transition_matrix,
        x0,
        P0,
        mu0,
        offsets=None,
        gate_probability: float = DEFAULT_GATE_PROBABILITY,
        kernel: str = "auto",
        estimated_turn_rate=None,
        dt=None,
        mode_names=None,
        _slots: SlotIMM = None,
    ):
        s = _slots or SlotIMM(
            transitions,
            process_noise,
            measurement_matrix,
            measurement_noise,
            transition_matrix,
            offsets=offsets,
            gate_probability=gate_probability,
            kernel=kernel,
            estimated_turn_rate=estimated_turn_rate,
            dt=dt,
            mode_names=mode_names,
        )
        x0, P0, mu0 = s._initial(x0, P0, mu0, "")
        self._s = s
        self._rows = s._birth_valid(x0, P0, mu0)
        self._identity = True  # rows == arange(B): dense arrays are slices of the slots'
        self._cache: dict = {}
        self._z = np.zeros((0, s.m))
        # per tracker: measurements gated since it started, while it has accepted none
        self._gated_from_start = np.zeros(self.B, dtype=np.int64)
        self._warned = False

    @classmethod
    def from_preset(cls, preset, x0, P0, mu0=None, **kwargs) -> IMM:
        """The IMM of the preset's tracker model (:meth:`SlotIMM.from_preset`), trackers
        started at x0 (B, 5), P0, mu0 (default that model's :meth:`~Preset.mu0`); it can
        step with any ``dt`` (:meth:`step`). ``kwargs``: ``gate_probability``, ``kernel``."""
        preset = preset.filter_model()
        s = SlotIMM.from_preset(preset, **kwargs)
        return cls(None, None, None, None, None, x0, P0, preset.mu0() if mu0 is None else mu0,
                   _slots=s)  # fmt: skip

    def __getstate__(self) -> dict:
        state = self.__dict__.copy()
        state["_cache"] = {}
        state["_z"] = np.zeros((0, self._s.m))
        return state

    # --------------------------------------------------------------- properties
    M = property(lambda self: self._s.M, doc="Number of modes.")
    n = property(lambda self: self._s.n, doc="State dimension.")
    m = property(lambda self: self._s.m, doc="Measurement dimension.")
    kernel = property(lambda self: self._s.kernel, doc="The step kernel in use.")
    mode_names = property(lambda self: self._s.mode_names, doc="(M,) names of the modes.")
    gate_probability = property(lambda self: self._s.gate_probability)
    gate_threshold = property(lambda self: self._s.gate_threshold, doc="Gate on d² (inf: none).")

    @property
    def slots(self) -> SlotIMM:
        """The slot storage this is a view of."""
        return self._s

    @property
    def B(self) -> int:
        """Number of trackers."""
        return int(self._rows.size)

    def _dense(self, name: str) -> np.ndarray:
        a = getattr(self._s, name)
        if self._identity:
            return a[: self.B]
        if name not in self._cache:
            self._cache[name] = _ro(a[self._rows])
        return self._cache[name]

    @property
    def x(self) -> np.ndarray:
        """Combined posterior state (B, n) (paper §IV step 5)."""
        return self._dense("x")

    @property
    def P(self) -> np.ndarray:
        """Combined posterior covariance (B, n, n) (paper §IV step 5)."""
        return self._dense("P")

    @property
    def mu(self) -> np.ndarray:
        """Mode probabilities (B, M) (paper §IV step 4)."""
        return self._dense("mu")

    @property
    def nis(self) -> np.ndarray:
        """Last step's mixture NIS (B,); NaN where no measurement (see class docstring)."""
        return self._dense("nis")

    @property
    def log_likelihood(self) -> np.ndarray:
        """Last step's per-mode log-likelihoods (B, M); NaN where no measurement."""
        return self._dense("log_likelihood")

    @property
    def gated(self) -> np.ndarray:
        """Last step: finite measurement rejected by the gate (B,) bool."""
        return self._dense("gated")

    def _modes(self):
        if "modes" not in self._cache:
            xm, Pm = self._s.modes(self._rows)
            self._cache["modes"] = (_ro(xm), _ro(Pm))
        return self._cache["modes"]

    @property
    def x_modes(self) -> np.ndarray:
        """Mode-conditioned posterior states (B, M, n) (paper §IV step 3)."""
        return self._modes()[0]

    @property
    def P_modes(self) -> np.ndarray:
        """Mode-conditioned posterior covariances (B, M, n, n) (paper §IV step 3)."""
        return self._modes()[1]

    # ------------------------------------------------------------------ methods
    def step(self, z, dt=None) -> None:
        """One IMM cycle (paper §IV steps 1–5) for every tracker.

        Parameters
        ----------
        z : (B, m)
            Measurements; a row with any NaN/inf means no measurement (predict only).
        dt : float, optional
            Seconds since the last step (irregular sampling); None for the model's step.
            Needs an IMM built with :meth:`from_preset` (see :meth:`SlotIMM.step`).
        """
        z = np.asarray(z, dtype=float)
        B, s = self.B, self._s
        if z.shape != (B, s.m):
            raise UserError(f"IMM.step: z must have shape {(B, s.m)}, got {z.shape}")
        if self._z.shape[0] != s.capacity:
            self._z = np.zeros((s.capacity, s.m))
        if self._identity:
            self._z[:B] = z
        else:
            self._z[self._rows] = z
        s.step(self._z, dt)
        self._cache.clear()
        self._check_start(z)

    def _check_start(self, z) -> None:
        """Warn (once) when trackers have rejected every measurement since they started:
        their x0 / P0 are far from the measurements and they will never pick the target up."""
        have = np.all(np.isfinite(z), axis=1)
        g = self._gated_from_start
        g[:] = np.where(have & (g >= 0), np.where(self.gated, g + 1, -1), g)
        if not self._warned and np.any(g >= GATED_START_WARNING):
            import warnings

            self._warned = True
            bad = np.flatnonzero(g >= GATED_START_WARNING)
            warnings.warn(
                f"IMM: {bad.size} tracker(s) (first: row {bad[0]}) have rejected all of their "
                f"first {GATED_START_WARNING} measurements (gate d² > {self.gate_threshold:.3g}):"
                " their x0 / P0 are far from the measurements; start them with "
                "airspace_sim.tracking.two_point_initialisation",
                stacklevel=3,
            )

    def append(self, x0, P0, mu0) -> np.ndarray:
        """Add trackers at the end of the batch; return their row indices (k,) int.

        x0 (k, n), P0 (k, n, n) or (n, n), mu0 (k, M) or (M,), as in the constructor. Their
        ``nis``/``log_likelihood`` are NaN and ``gated`` False until their first step.
        Cost O(k) in the slot storage (plus O(B) integers for the row order).
        """
        x0, P0, mu0 = self._s._initial(x0, P0, mu0, "append ")
        B = self.B
        slots = self._s._birth_valid(x0, P0, mu0)
        self._identity = self._identity and bool(np.all(slots == np.arange(B, B + slots.size)))
        self._rows = np.concatenate([self._rows, slots])
        self._gated_from_start = np.concatenate(
            [self._gated_from_start, np.zeros(slots.size, dtype=np.int64)]
        )
        self._cache.clear()
        return np.arange(B, B + slots.size)

    def remove(self, indices) -> None:
        """Drop the trackers at ``indices`` (int array-like, or a (B,) bool mask).

        The remaining trackers keep their relative order (and their exact state).
        """
        idx = np.asarray(indices)
        B = self.B
        if idx.dtype == bool:
            if idx.shape != (B,):
                raise UserError(f"IMM.remove: boolean mask must have shape {(B,)}, got {idx.shape}")
            idx = np.flatnonzero(idx)
        elif idx.size == 0:
            idx = idx.astype(np.int64)
        elif not np.issubdtype(idx.dtype, np.integer):
            raise UserError(f"IMM.remove: indices must be integers, got dtype {idx.dtype}")
        idx = idx.reshape(-1)
        if idx.size and (idx.min() < -B or idx.max() >= B):
            raise UserError(f"IMM.remove: index out of range for {B} trackers: {idx.tolist()}")
        keep = np.ones(B, dtype=bool)
        keep[idx] = False
        self._s.drop(self._rows[~keep])
        self._rows = self._rows[keep]
        self._gated_from_start = self._gated_from_start[keep]
        self._identity = bool(np.all(self._rows == np.arange(self._rows.size)))
        self._cache.clear()

    def predict_modes(self, steps: int):
        """Each mode's own model propagated 1..steps steps ahead, without mixing.

        From the mode-conditioned posteriors, ``x ← F_j x + u_j``, ``P ← F_j P F_jᵀ + Q_j``.

        Returns
        -------
        xs : (B, M, steps, n)
        Ps : (B, M, steps, n, n)
        """
        if isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) or steps < 0:
            raise UserError(
                f"IMM.predict_modes: steps must be a non-negative integer, got {steps!r}"
            )
        steps = int(steps)
        s = self._s
        B, M, n = self.B, s.M, s.n
        xs = np.empty((B, M, steps, n))
        Ps = np.empty((B, M, steps, n, n))
        xm, Pm = self._modes()
        _kernels.predict_modes(s._F, s._Q, s._U, np.asarray(xm), np.asarray(Pm), steps, xs, Ps)
        if steps:
            s._predict_ct(np.asarray(xm), np.asarray(Pm), np.arange(1, steps + 1), xs, Ps)
        return xs, Ps

    def predict_modes_at(self, steps, rows=None):
        """:meth:`predict_modes` only at the step counts ``steps`` (S,) and for ``rows``.

        ``steps`` positive and increasing; ``rows`` tracker indices (R,) or None for all.
        Returns xs (R, M, S, n), Ps (R, M, S, n, n), same numbers as
        ``predict_modes(max(steps))[:, :, steps - 1]`` to rounding, in R·M·S·n² memory
        (:mod:`airspace_sim.tracking.prediction`).
        """
        slots = self._rows if rows is None else self._rows[np.asarray(rows)]
        return self._s.predict_modes_at(steps, slots)

    def __repr__(self) -> str:
        return (
            f"IMM(B={self.B}, M={self.M}, n={self.n}, m={self.m}, "
            f"gate_probability={self.gate_probability})"
        )
