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

Storage and modules
-------------------
:class:`SlotIMM` (:mod:`.slot_imm`) holds the filters in stable slots of the kernel's chunked
structure-of-arrays layout (a free list, an alive mask, geometric growth): births and drops
cost O(tracks that change) and the step skips free chunks. :class:`IMM` (this module) is the
dense view (rows 0..B−1, ``append``/``remove`` keeping the order of the rest) over it. The
gate is in :mod:`.gating`, the kernel choice and the matrices' sparsity in
:mod:`._kernel_choice`, the input checks in :mod:`._arrays`, the combination of a new
track's modes in :mod:`._combination`; the kernels themselves in :mod:`._codegen` and
:mod:`._kernels`. Everything is imported from here or from :mod:`airspace_sim.tracking`.

Units are whatever the model uses; in this project SI (m, m/s, rad/s), state
``[x, vx, y, vy, Ω]``.
"""

from __future__ import annotations

import numpy as np

from airspace_sim.errors import UserError
from airspace_sim.tracking import _kernels
from airspace_sim.tracking._arrays import _ro
from airspace_sim.tracking.gating import DEFAULT_GATE_PROBABILITY, gate_threshold
from airspace_sim.tracking.slot_imm import SlotIMM

__all__ = ["DEFAULT_GATE_PROBABILITY", "GATED_START_WARNING", "IMM", "SlotIMM", "gate_threshold"]

#: :class:`IMM` warns when a tracker has rejected this many measurements since it started
#: and accepted none (a start far from the target, e.g. x0 = 0 for an aircraft 50 km away).
GATED_START_WARNING = 5


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
        Modes whose turn rate is the state's own Ω (n = 5, state ``[x, vx, y, vy, Ω]``, or
        n = 6 with ``a`` pinned at its offset):
        an EKF coordinated turn (:mod:`.coordinated_turn`), for which ``transitions[j]`` is
        not used; such a model runs the ``"loops"`` kernel.
    dt : float, optional
        The step in seconds; needed with estimated-rate modes.
    along_track_acceleration : (M,) bool, optional
        Modes that are a coordinated turn at the state's own Ω *and* along-track
        acceleration ``a`` (n = 6, state ``[x, vx, y, vy, Ω, a]``; EKF,
        :mod:`.along_track`); ``transitions[j]`` is not used. Needs ``dt``; runs the
        ``"loops"`` kernel.
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

    # some tracker has accepted no measurement yet (a class default, so IMMs pickled before
    # this flag existed check once more)
    _starting = True

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
        along_track_acceleration=None,
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
            along_track_acceleration=along_track_acceleration,
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
        their x0 / P0 are far from the measurements and they will never pick the target up.
        Once every tracker has accepted one, or the warning was given, it returns at once
        until :meth:`append`: its array work would otherwise weigh on every small batch's
        step."""
        if not self._starting:
            return
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
        self._starting = not self._warned and bool(np.any(g >= 0))

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
        self._starting = not self._warned and (self._starting or slots.size > 0)
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
