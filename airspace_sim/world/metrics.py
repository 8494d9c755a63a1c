"""Safety, efficiency and estimation metrics of one world run, accumulated step by step.

Definitions (units SI; ``d`` a true centre distance between two aircraft):

- loss of separation (LoS): a pair with ``d < r_safe``. ``los_events``: LoS episodes
  (a pair entering LoS; a pair leaving and re-entering counts twice); ``los_pairs``:
  distinct pairs that ever lost separation; ``los_duration_s``: Σ over steps of the number
  of pairs in LoS × dt (pair-seconds); ``worst_intrusion``: max of ``1 − d/r_safe`` over
  pairs in LoS (0 if none).
- NMAC: ``d < nmac``; ``nmac_events``, ``nmac_pairs`` as above, including NMACs passed
  through between two step instants (closest approach within the step, exact for the
  straight chords aircraft fly in a step).
- ``min_separation_m``: smallest ``d`` seen between any two aircraft within sensor range
  of each other, over all steps (``inf`` if no pair was ever within range).
- ``alerts``: conflict alerts, i.e. times an ownship's resolver flag went from clear to
  conflict; ``conflict_s``: Σ over ownships of the time flagged in conflict.
- extra path: for aircraft with a plan (``route`` or ``straight`` autopilot),
  ``flown − planned distance covered`` (route: plan length minus distance still to go along
  the route; straight: progress along the initial heading). ``extra_path_m`` (sum),
  ``extra_path_pct`` (100·Σ extra / Σ planned covered; NaN when nothing planned was covered,
  e.g. only Markov autopilots, where a percentage would mean nothing).
- ``avoidance_turn_deg``: mean over aircraft of the total |heading change| flown while
  following resolver advice, degrees.
- tracking: ``track_rmse_m``: RMS of the position error of every track at every step;
  ``mode_accuracy``: fraction of (track, step) samples of Markov intruders whose most
  probable IMM mode equals the intruder's true mode (NaN if there were none);
  ``track_steps``: number of (track, step) samples.
"""

from __future__ import annotations

import math

import numpy as np

from airspace_sim.world.bodies import LOS, NMAC, RANGE


class WorldMetrics:
    """The accumulators of one world run (definitions in the module docstring).

    n aircraft; r_safe, nmac : separation and NMAC distances, m; dt : world step, s.
    """

    def __init__(self, n: int, r_safe: float, nmac: float, dt: float):
        self.n, self.r_safe, self.nmac, self.dt = n, float(r_safe), float(nmac), float(dt)
        self.flown = np.zeros(n)  # m flown per aircraft
        self._prev_contacts = None  # positions, LoS and NMAC keys at the previous step
        self.los_events = 0
        self.nmac_events = 0
        self.los_keys: set[int] = set()
        self.nmac_keys: set[int] = set()
        self.los_pair_steps = 0
        self.worst_intrusion = 0.0
        self.min_sep = math.inf
        self.alerts = 0
        self.conflict_steps = 0
        self.avoid_turn = np.zeros(n)
        self.sq_err = 0.0
        self.track_samples = 0
        self.mode_hits = 0
        self.mode_samples = 0
        self._prev_conflict = np.zeros(n, dtype=bool)

    def contacts(self, positions, pairs: dict, began: dict):
        """Record this step's pair sets and new episodes.

        positions : (N, 2) m; pairs : set → (P,) sorted keys ``i·N + j`` (``i < j``) of the
        pairs overlapping now, began : set → (E, 2) pairs that began overlapping in the last
        step (:class:`~.bodies.Airspace` ``pairs`` / ``began``; sets LOS, NMAC, RANGE).

        Pymunk's sets are sampled at step instants; two aircraft closing at 460 m/s can jump
        over the 152 m NMAC circle in a 1 s step. So for pairs in LoS now or at the previous
        step, the closest approach *within* the step is computed exactly (each aircraft flies
        a straight chord during a step) and counted in ``min_separation_m`` /
        ``worst_intrusion``; an NMAC passed through between two samples (in NMAC at
        neither) counts as an NMAC event.
        """
        n = max(self.n, 1)
        los_keys, nmac_keys, range_keys = pairs[LOS], pairs[NMAC], pairs[RANGE]
        prev_positions = prev_los_keys = prev_nmac_keys = None
        if self._prev_contacts is not None:
            prev_positions, prev_los_keys, prev_nmac_keys = self._prev_contacts
        self._prev_contacts = (positions.copy(), los_keys.copy(), nmac_keys.copy())
        los_began, nmac_began = began[LOS], began[NMAC]
        self.los_events += len(los_began)
        self.nmac_events += len(nmac_began)
        if prev_positions is not None and (los_keys.size or prev_los_keys.size):
            k = np.union1d(los_keys, prev_los_keys)
            i, j = k // n, k % n
            r0 = prev_positions[j] - prev_positions[i]
            dv = (positions[j] - positions[i]) - r0  # relative displacement over the step
            dv2 = np.einsum("ij,ij->i", dv, dv)
            with np.errstate(divide="ignore", invalid="ignore"):
                t = np.where(dv2 > 0, -np.einsum("ij,ij->i", r0, dv) / np.where(dv2 > 0, dv2, 1), 0)
            t = np.clip(t, 0.0, 1.0)
            d = np.hypot(*(r0 + t[:, None] * dv).T)
            if d.size:
                self.min_sep = min(self.min_sep, float(d.min()))
                self.worst_intrusion = max(self.worst_intrusion, float(1.0 - d.min() / self.r_safe))
            jumped = (d < self.nmac) & ~np.isin(k, nmac_keys) & ~np.isin(k, prev_nmac_keys)
            if jumped.any():
                self.nmac_events += int(jumped.sum())
                self.nmac_keys.update(int(x) for x in k[jumped])
        self.los_keys.update(int(k) for k in los_keys)
        self.nmac_keys.update(int(k) for k in nmac_keys)
        self.los_pair_steps += int(los_keys.size)
        if range_keys.size:
            i, j = range_keys // n, range_keys % n
            d = np.hypot(*(positions[i] - positions[j]).T)
            self.min_sep = min(self.min_sep, float(d.min()))
        if los_keys.size:
            i, j = los_keys // n, los_keys % n
            d = np.hypot(*(positions[i] - positions[j]).T)
            self.worst_intrusion = max(self.worst_intrusion, float(1.0 - d.min() / self.r_safe))

    def conflicts(self, conflict):
        self.alerts += int(np.count_nonzero(conflict & ~self._prev_conflict))
        self.conflict_steps += int(np.count_nonzero(conflict))
        self._prev_conflict = conflict.copy()

    def motion(self, travelled, turned, following_policy):
        """One step flown: ``travelled`` (N,) m, ``turned`` (N,) heading change, rad;
        ``following_policy`` (N,) bool, the turn was the CDA policy's."""
        self.flown += travelled
        self.avoid_turn += np.where(following_policy, np.abs(turned), 0.0)

    def tracking(self, track_pos, true_pos, mode_est=None, mode_true=None):
        """Add (P, 2) estimated vs true positions; optional (Q,) modes to compare."""
        if len(track_pos):
            e = np.asarray(track_pos) - np.asarray(true_pos)
            self.sq_err += float(np.einsum("ij,ij->", e, e))
            self.track_samples += len(track_pos)
        if mode_est is not None and len(mode_est):
            self.mode_hits += int(np.count_nonzero(mode_est == mode_true))
            self.mode_samples += len(mode_est)

    def report(self, steps: int, time: float, progress, has_plan) -> dict:
        """The metrics dict; progress (N,) planned distance covered, m; has_plan (N,) bool."""
        extra = np.where(has_plan, self.flown - np.nan_to_num(progress), 0.0)
        planned = float(np.sum(np.where(has_plan, np.nan_to_num(progress), 0.0)))
        return {
            "steps": int(steps),
            "time_s": float(time),
            "aircraft": int(self.n),
            "los_events": self.los_events,
            "los_pairs": len(self.los_keys),
            "los_duration_s": self.los_pair_steps * self.dt,
            "worst_intrusion": self.worst_intrusion,
            "nmac_events": self.nmac_events,
            "nmac_pairs": len(self.nmac_keys),
            "min_separation_m": self.min_sep,
            "alerts": self.alerts,
            "conflict_s": self.conflict_steps * self.dt,
            "extra_path_m": float(extra.sum()),
            "extra_path_pct": 100.0 * float(extra.sum()) / planned if planned > 0 else math.nan,
            "avoidance_turn_deg": float(np.degrees(self.avoid_turn).mean()) if self.n else 0.0,
            "track_rmse_m": math.sqrt(self.sq_err / self.track_samples)
            if self.track_samples
            else math.nan,
            "mode_accuracy": self.mode_hits / self.mode_samples if self.mode_samples else math.nan,
            "track_steps": self.track_samples,
        }
