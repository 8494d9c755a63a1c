"""The world's track table: one batched filter over every (ownship, intruder) pair.

A *track* is a row ``p`` with ``owner[p]`` (the aircraft that tracks), ``intruder[p]``
(the aircraft tracked), and the filter's estimate ``x[p]`` ``[x, vx, y, vy, Ω]`` (m, m/s,
rad/s, WORLD frame), ``P[p]`` (5, 5) and ``mu[p]`` (M,). ONE filter object (e.g. one
batched :class:`~airspace_sim.tracking.IMM`) holds every row of the world: rows are
appended as intruders are detected and removed after ``drop_after_misses`` missed scans;
the per-step work is a handful of numpy calls over all rows (no per-pair Python objects).

Track life cycle (per scan):

1. existing rows are stepped with their measurement (NaN row = not detected: predict only;
   between scans every row is predicted only); ``misses`` counts consecutive missed scans;
2. rows with ``misses ≥ drop_after_misses``, or whose owner or intruder left the world,
   are removed;
3. a detection without a track is *pending*; the next detection of the same pair within
   ``drop_after_misses`` scans starts the track by two-point initialisation: position =
   last measurement, velocity = difference / Δt, covariance from σ (position σ², velocity
   2σ²/Δt² plus a manoeuvre allowance, their correlation σ²/Δt).

Tracker factories (registry kind ``"tracker"``) have the signature
``factory(preset: Preset, sigma: float) -> filter`` where ``preset`` is the tracker's
dynamics preset at the world's dt and ``sigma`` the sensor's σ (m). The filter holds zero
rows at first and provides ``append(x0 (k,5), P0 (k,5,5), mu0 (M,)) -> rows``,
``remove(mask (B,) bool)``, ``step(z (B,2))`` (NaN row = no measurement) and ``x``, ``P``,
``mu`` (``mu`` may be absent: one mode). Built in: ``"imm"`` (the matched IMM of the
preset). The special kind ``"truth"`` runs no filter: tracks hold the intruders' true
states (perfect surveillance, for benchmarks and baselines).
"""

from __future__ import annotations

import numpy as np

from airspace_sim.dynamics.presets import Preset
from airspace_sim.registry import register

#: Velocity variance added at track start for a manoeuvring target, (m/s)².
MANOEUVRE_VELOCITY_VAR = 10.0**2


@register("tracker", "imm")
def imm_tracker(preset: Preset, sigma: float):
    """The preset's matched IMM (:meth:`Preset.imm_arguments`) with R = σ² I, zero rows."""
    from airspace_sim.tracking import IMM

    p = preset.with_(measurement_sigma=max(float(sigma), 1e-3))
    return IMM(**p.imm_arguments(), x0=np.zeros((0, 5)), P0=np.zeros((0, 5, 5)), mu0=p.mu0())


def _sort_lookup(keys: np.ndarray, query: np.ndarray):
    """For each query key, the index in ``keys`` holding it, or −1 (keys unique)."""
    if keys.size == 0 or query.size == 0:
        return np.full(query.size, -1, dtype=np.int64)
    order = np.argsort(keys, kind="stable")
    sk = keys[order]
    pos = np.minimum(np.searchsorted(sk, query), sk.size - 1)
    return np.where(sk[pos] == query, order[pos], -1)


class TrackTable:
    """All tracks of a world (see the module docstring).

    Attributes: ``owner`` (P,) int, ``intruder`` (P,) int, ``misses`` (P,) int, ``age``
    (P,) int (steps since the track started), ``x`` (P, 5), ``P`` (P, 5, 5), ``mu`` (P, M),
    ``mode_names`` (M,) str.
    """

    def __init__(
        self,
        n_aircraft: int,
        kind: str,
        preset: Preset,
        sigma: float,
        drop_after_misses: int,
        scan_period_s: float,
    ):
        from airspace_sim import registry

        self.n = int(n_aircraft)
        self.kind = kind
        self.sigma = float(sigma)
        self.drop_after = max(1, int(drop_after_misses))
        self.scan_period_s = float(scan_period_s)
        self.preset = preset
        self.n_modes = preset.n_modes if kind in ("imm", "truth") else None
        self.filter = None if kind == "truth" else registry.get("tracker", kind)(preset, sigma)
        self.owner = np.zeros(0, dtype=np.int64)
        self.intruder = np.zeros(0, dtype=np.int64)
        self.misses = np.zeros(0, dtype=np.int64)
        self.age = np.zeros(0, dtype=np.int64)
        self._truth_x = np.zeros((0, 5))
        self._pend_key = np.zeros(0, dtype=np.int64)
        self._pend_z = np.zeros((0, 2))
        self._pend_t = np.zeros(0)
        rates = np.abs(np.asarray(preset.turn_rates, dtype=float))
        self._omega_var = float(max(rates.max(initial=0.0), np.radians(3.0))) ** 2
        self.mode_names = (
            ["straight", "left", "right"]
            if preset.n_modes == 3
            else [f"mode{j}" for j in range(preset.n_modes)]
        )

    # ------------------------------------------------------------------ views
    def view(self):
        """Dense arrays over the live tracks (slots = rows here)."""
        from types import SimpleNamespace

        return SimpleNamespace(
            slots=np.arange(len(self)),
            owner=self.owner,
            intruder=self.intruder,
            misses=self.misses,
            age=self.age,
            x=self.x,
            P=self.P,
            mu=self.mu,
        )

    @property
    def predicts_modes(self) -> bool:
        return self.filter is not None and hasattr(self.filter, "predict_modes_at")

    def predict_modes_at(self, steps, slots):
        return self.filter.predict_modes_at(steps, slots)

    def __len__(self) -> int:
        return int(self.owner.size)

    @property
    def keys(self) -> np.ndarray:
        return self.owner * self.n + self.intruder

    @property
    def x(self) -> np.ndarray:
        return self._truth_x if self.filter is None else np.asarray(self.filter.x)

    @property
    def P(self) -> np.ndarray:
        if self.filter is None:
            return np.zeros((len(self), 5, 5))
        return np.asarray(self.filter.P)

    @property
    def mu(self) -> np.ndarray:
        if self.filter is not None and hasattr(self.filter, "mu"):
            return np.asarray(self.filter.mu)
        if self.filter is None and self.n_modes:
            return np.full((len(self), self.n_modes), np.nan)
        return np.ones((len(self), 1))

    # ----------------------------------------------------------------- update
    def update(
        self, time: float, scanned: bool, det_owner, det_intruder, z, alive, truth_states=None
    ) -> None:
        """One world step of the table.

        time : s, now. scanned : a scan happened now. det_owner, det_intruder (D,) int and
        z (D, 2) m: this scan's detections. alive : (N,) bool aircraft still in the world.
        truth_states : (N, 5) true ``[x, vx, y, vy, Ω]`` (used by kind ``"truth"`` only).
        """
        n = self.n
        det_key = np.asarray(det_owner, np.int64) * n + np.asarray(det_intruder, np.int64)
        row_of_det = _sort_lookup(self.keys, det_key)
        P = len(self)
        # 1. step existing rows
        hit = np.zeros(P, dtype=bool)
        matched = row_of_det >= 0
        hit[row_of_det[matched]] = True
        if self.filter is not None and P:
            Z = np.full((P, 2), np.nan)
            Z[row_of_det[matched]] = z[matched]
            self.filter.step(Z)
        self.age += 1
        if scanned:
            self.misses = np.where(hit, 0, self.misses + 1)
        # 2. drop
        drop = (self.misses >= self.drop_after) | ~alive[self.owner] | ~alive[self.intruder]
        if drop.any():
            self._remove(drop)
        # 3. births
        new = ~matched
        if new.any():
            self._births(time, det_key[new], np.asarray(z)[new], truth_states)
        if self.filter is None and len(self):
            self._truth_x = np.asarray(truth_states)[self.intruder].copy()

    def _remove(self, mask) -> None:
        keep = ~mask
        if self.filter is not None:
            self.filter.remove(mask)
        else:
            self._truth_x = self._truth_x[keep]
        self.owner, self.intruder = self.owner[keep], self.intruder[keep]
        self.misses, self.age = self.misses[keep], self.age[keep]

    def _append(self, keys, x0, P0) -> None:
        if self.filter is not None:
            mu0 = self.preset.mu0()
            self.filter.append(x0, P0, mu0)
        else:
            self._truth_x = np.concatenate([self._truth_x, x0])
        k = keys.size
        self.owner = np.concatenate([self.owner, keys // self.n])
        self.intruder = np.concatenate([self.intruder, keys % self.n])
        self.misses = np.concatenate([self.misses, np.zeros(k, np.int64)])
        self.age = np.concatenate([self.age, np.zeros(k, np.int64)])

    def _births(self, time, keys, z, truth_states) -> None:
        order = np.argsort(keys, kind="stable")
        keys, z = keys[order], z[order]
        if self.filter is None:  # perfect surveillance: start at once from truth
            self._append(keys, np.asarray(truth_states)[keys % self.n], None)
            return
        # expire stale pending detections
        max_age = self.drop_after * self.scan_period_s + 1e-9
        fresh = (time - self._pend_t) <= max_age
        self._pend_key, self._pend_z, self._pend_t = (
            self._pend_key[fresh],
            self._pend_z[fresh],
            self._pend_t[fresh],
        )
        prev = _sort_lookup(self._pend_key, keys)
        two = prev >= 0
        if two.any():
            two[two] = time - self._pend_t[prev[two]] > 0
        if two.any():
            p = prev[two]
            dt = (time - self._pend_t[p])[:, None]
            z1, z2 = self._pend_z[p], z[two]
            v = (z2 - z1) / dt
            k = z2.shape[0]
            x0 = np.zeros((k, 5))
            x0[:, 0], x0[:, 1], x0[:, 2], x0[:, 3] = z2[:, 0], v[:, 0], z2[:, 1], v[:, 1]
            s2 = max(self.sigma, 1.0) ** 2
            d = dt[:, 0]
            P0 = np.zeros((k, 5, 5))
            for a, b in ((0, 1), (2, 3)):
                P0[:, a, a] = s2
                P0[:, a, b] = P0[:, b, a] = s2 / d
                P0[:, b, b] = 2.0 * s2 / d**2 + MANOEUVRE_VELOCITY_VAR
            P0[:, 4, 4] = self._omega_var
            self._append(keys[two], x0, P0)
            gone = np.zeros(self._pend_key.size, dtype=bool)
            gone[p] = True
            self._pend_key, self._pend_z, self._pend_t = (
                self._pend_key[~gone],
                self._pend_z[~gone],
                self._pend_t[~gone],
            )
        # the others become (or refresh) pending detections
        rest = ~two
        if rest.any():
            old = prev[rest]
            refresh = old >= 0
            self._pend_z[old[refresh]] = z[rest][refresh]
            self._pend_t[old[refresh]] = time
            add = ~refresh
            if add.any():
                nk = keys[rest][add]
                self._pend_key = np.concatenate([self._pend_key, nk])
                self._pend_z = np.concatenate([self._pend_z, z[rest][add]])
                self._pend_t = np.concatenate([self._pend_t, np.full(nk.size, time)])
                o = np.argsort(self._pend_key, kind="stable")
                self._pend_key, self._pend_z, self._pend_t = (
                    self._pend_key[o],
                    self._pend_z[o],
                    self._pend_t[o],
                )
