"""IMM filters in stable slots (:class:`SlotIMM`): the storage and the step of every IMM in
the project (paper §IV; the algorithm, the missing-measurement and gating rules are in
:mod:`airspace_sim.tracking.imm`).

:class:`SlotIMM` holds the filters in stable slots of the kernel's chunked
structure-of-arrays layout (a free list, an alive mask, geometric growth): births and drops
cost O(tracks that change) and the step skips free chunks. :class:`~.imm.IMM` is the dense
view (rows 0..B−1, ``append``/``remove`` keeping the order of the rest) over it.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from airspace_sim.dynamics.markov import validate_transition_matrix
from airspace_sim.errors import UserError
from airspace_sim.resources import check_allocation
from airspace_sim.tracking._arrays import _array, _check_psd, _check_symmetric, _ro
from airspace_sim.tracking._combination import _combine
from airspace_sim.tracking._kernel_choice import _nonzeros, choose_kernel
from airspace_sim.tracking.gating import DEFAULT_GATE_PROBABILITY, gate_threshold
from airspace_sim.tracking.slots import Slots


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
        along_track_acceleration=None,
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

        flags = {}
        for key, value in (("estimated_turn_rate", estimated_turn_rate),
                           ("along_track_acceleration", along_track_acceleration)):  # fmt: skip
            flags[key] = np.zeros(M, dtype=bool)
            if value is not None:
                flags[key] = np.array(value, dtype=bool).reshape(-1)
                if flags[key].shape != (M,):
                    raise UserError(
                        f"IMM {key}: expected {M} flags (one per mode), got {flags[key].size}"
                    )
        est, cta = flags["estimated_turn_rate"], flags["along_track_acceleration"]
        if cta.any() and n != 6:
            raise UserError(
                "IMM along_track_acceleration: needs the state [x, vx, y, vy, Ω, a] (n = 6), "
                f"got n = {n}"
            )
        if est.any() and n not in (5, 6):
            raise UserError(
                "IMM estimated_turn_rate: needs the state [x, vx, y, vy, Ω] (n = 5) or "
                f"[x, vx, y, vy, Ω, a] (n = 6), got n = {n}"
            )
        # the kernel's EKF modes: the (M,) bool estimated-rate flags, as they always were
        # (the same argument types, so the same compiled kernels), or with along-track modes
        # the (M,) int kinds 0 linear, 1 estimated-rate turn, 2 with along-track a
        ct = np.where(cta, 2, np.where(est, 1, 0)).astype(np.int64) if cta.any() else est
        if ct.any():
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
        self._kernel, self._W, self.kernel = choose_kernel(self._F, self._H, self._ct, kernel)
        # the generated kernel stores only the upper triangle of each P_j (less to move)
        self._tri = self.kernel == "generated"
        n = self.n
        k, l = np.triu_indices(n) if self._tri else np.divmod(np.arange(n * n), n)
        # stored covariance entry t is entry _P_index[t] of the row-major (n, n) matrix
        self._P_index = np.ascontiguousarray(k * n + l, dtype=np.int64)

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
        # combined estimate as filterpy's constructor makes it (Σ μ_j x_j with equal x_j;
        # numpy's einsum, whose fused multiply-adds a plain loop would not reproduce)
        xm = np.broadcast_to(x0[:, None, :], (k, M, n))
        Pm = np.broadcast_to(P0[:, None], (k, M, n, n))
        x, P = _combine(xm, Pm, mu0)
        _write_lanes(
            np.asarray(slots, dtype=np.int64), self._W, x0, P0, mu0, x, P, self._P_index,
            self._xs, self._Ps_flat(), self._mus, self._x, self._P, self._mu, self._nis,
            self._ll, self._gated,
        )  # fmt: skip

    def _Ps_flat(self) -> np.ndarray:
        """``Ps`` as (C, M, T, W), T the stored entries of a covariance (a view: setting
        the shape raises rather than copy)."""
        v = self._Ps.view()
        v.shape = self._Ps.shape[:2] + (-1, self._W)
        return v

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

    def birth_checked(self, x0, P0, mu0) -> np.ndarray:
        """:meth:`birth` without the input checks, for arrays the caller guarantees:
        x0 (k, n) finite, P0 (k, n, n) finite, exactly symmetric, positive definite, mu0
        (k, M) as :meth:`birth` would make it (non-negative rows, each divided by its sum),
        all C-contiguous float64. The same slots and lanes as :meth:`birth` of them."""
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
        _free_lanes(
            s, self._W, self._free_P.reshape(-1), 1.0 / self.M, self._xs, self._Ps_flat(),
            self._mus, self._x, self._P, self._mu, self._nis, self._ll, self._gated,
        )  # fmt: skip

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
        from airspace_sim.tracking import along_track, coordinated_turn

        for j in np.flatnonzero(self._ct):
            if self._ct[j] == 2:
                xs[:, j], Ps[:, j] = along_track.predict(
                    xm[:, j], Pm[:, j], self._Q[j], self._dt, steps, self._U[j]
                )
            elif self.n == 5:
                xs[:, j], Ps[:, j] = coordinated_turn.predict(
                    xm[:, j], Pm[:, j], self._Q[j], self._dt, steps
                )
            else:  # a coordinated turn in the 6-state layout: a pinned at its offset
                x5, P5 = coordinated_turn.predict(
                    xm[:, j, :5], Pm[:, j, :5, :5], self._Q[j, :5, :5], self._dt, steps
                )
                xs[:, j] = self._U[j]
                xs[:, j, :, :5] = x5
                Ps[:, j] = 0.0
                Ps[:, j, :, :5, :5] = P5
                Ps[:, j, :, 5, 5] = self._Q[j, 5, 5]

    def __repr__(self) -> str:
        return (
            f"SlotIMM(live={self.n_live}, capacity={self.capacity}, M={self.M}, n={self.n}, "
            f"m={self.m}, kernel={self.kernel!r})"
        )


@njit(cache=True)
def _write_lanes(
    slots, W, x0, P0, mu0, x, P, P_index, xs, Ps, mus, x_out, P_out, mu_out, nis, ll, gated
):  # pragma: no cover - compiled
    """The births of :meth:`SlotIMM._write` in one pass: slot ``slots[b]`` (lane
    ``slots[b] % W`` of chunk ``slots[b] // W``) gets every mode's state x0[b] (n,),
    covariance P0[b] (n, n) (the stored entries ``P_index`` (T,) of the row-major matrix,
    into ``Ps`` (C, M, T, W)) and mode probabilities mu0[b] (M,); the combined estimate
    x[b], P[b]; NaN NIS and log-likelihoods, not gated."""
    n = x0.shape[1]
    M = mus.shape[1]
    T = P_index.size
    for b in range(slots.size):
        s = slots[b]
        c, w = s // W, s % W
        for j in range(M):
            for i in range(n):
                xs[c, j, i, w] = x0[b, i]
            for t in range(T):
                e = P_index[t]
                Ps[c, j, t, w] = P0[b, e // n, e % n]
            mus[c, j, w] = mu0[b, j]
            mu_out[s, j] = mu0[b, j]
            ll[s, j] = np.nan
        for i in range(n):
            x_out[s, i] = x[b, i]
            for k in range(n):
                P_out[s, i, k] = P[b, i, k]
        nis[s] = np.nan
        gated[s] = False


@njit(cache=True)
def _free_lanes(
    slots, W, free_P, free_mu, xs, Ps, mus, x_out, P_out, mu_out, nis, ll, gated
):  # pragma: no cover - compiled
    """The lanes of :meth:`SlotIMM.drop` reset in one pass: state 0, covariance entries
    ``free_P`` (T,), mode probabilities ``free_mu`` in the kernel's arrays; NaN outputs,
    not gated."""
    M = mus.shape[1]
    n = xs.shape[2]
    for b in range(slots.size):
        s = slots[b]
        c, w = s // W, s % W
        for j in range(M):
            for i in range(n):
                xs[c, j, i, w] = 0.0
            for t in range(free_P.size):
                Ps[c, j, t, w] = free_P[t]
            mus[c, j, w] = free_mu
            mu_out[s, j] = np.nan
            ll[s, j] = np.nan
        for i in range(n):
            x_out[s, i] = np.nan
            for k in range(n):
                P_out[s, i, k] = np.nan
        nis[s] = np.nan
        gated[s] = False
