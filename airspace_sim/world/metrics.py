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
  probable IMM mode equals the intruder's true mode (NaN if there were none, or if the
  tracker's modes are not the traffic's, compared by name);
  ``track_steps``: number of (track, step) samples.

Safety-assurance metrics (DAIDALUS / ACAS X study conventions; ``docs/safety.md``):

- well clear: a pair violates the horizontal DAA well clear (DWC) of DO-365 (RTCA, 2017, its DAA
  Well Clear definition; DAIDALUS ``WCV_TAUMOD``) when ``d ≤ DMOD``, or when it is
  closing (``s·v < 0``) with modified tau ``τ_mod = (DMOD² − d²)/(s·v) ≤ τ*_mod`` and
  horizontal miss distance at CPA ``HMD ≤ HMD*``; ``s, v`` relative position and velocity
  (true states). DO-365's horizontal values: ``DMOD = HMD* = 4000 ft = 1219.2 m``,
  ``τ*_mod = 35 s`` (its ``h* = 450 ft`` is vertical; this world is 2D). ``wcv_events``:
  episodes (a pair entering violation); ``wcv_pairs``: distinct pairs; ``wcv_duration_s``:
  pair-seconds in violation, sampled at step instants.
- ``induced_los_pairs``: LoS pairs never predicted in conflict before their loss began by
  the *unresolved* straight-line prediction: from true states, at a step after which
  neither aircraft was flying the CDA policy (advice or hold) in the step just flown, the
  pair's closest approach within the resolver's look-ahead is ``< r_safe``. A loss the
  resolver's manoeuvres brought about, not one it failed to prevent. Pairs in LoS at the
  start are never induced.
- ``alerts_per_flight_hour``: ``alerts`` / ``flight_hours`` (Σ over aircraft of the time
  flown, h; NaN when nothing flew); ``first_alert_s``: simulated time of the first alert
  of the run (NaN if none).
- arrival, over aircraft with a plan: ``arrived`` (their autopilot finished the plan, a
  route's last waypoint reached, and they left the world), ``not_arrived`` (still flying at
  the end of the run; a ``straight`` autopilot never arrives); aircraft taken out without
  finishing (the env's agents retired after an NMAC or truncation) are neither.
  ``arrival_delay_mean_s`` / ``arrival_delay_max_s`` over the arrived:
  arrival time minus the planned straight time ``plan length / speed`` (the aircraft's own
  speed where the CDA policy may change it, else the last speed flown; a route is
  captured within one step's travel of its last waypoint, so an undisturbed flight has a
  delay in ``[−dt, 0]``); NaN when none arrived.

Pair reach: the safety pass never scans all N(N−1)/2 pairs. Well clear and the unresolved
prediction are flagged only for pairs closer than their :func:`pair_reaches` (from the
fastest active aircraft), found on grids of cells that wide (the prediction's for the
aircraft not following the policy, well clear's for the pairs with one that does); state
is kept for flagged pairs only (keys ``i·N + j`` in
:class:`~airspace_sim.tracking.keymap.KeyMap` hashes). The reach is not
the sensor range and may exceed it (460 m/s closing: 16.2 km for well clear; with a 120 s
look-ahead and ``r_safe`` 3 km, 58 km for the prediction; the scenarios' range is 30-40 km),
so the world's RANGE pairs are not used: the flags are exactly those of an all-pairs scan.

The risk ratio (NMACs with the resolver over NMACs without, same seeds) needs two runs:
:func:`airspace_sim.world.risk.risk_ratio`.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from airspace_sim.tracking.keymap import KeyMap
from airspace_sim.world.bodies import LOS, NMAC, RANGE

#: DO-365 horizontal well-clear thresholds (module docstring): m, m, s
DMOD_M = 1219.2  # 4000 ft
HMD_M = 1219.2  # 4000 ft
TAU_MOD_S = 35.0


def pair_reach(speed_max, dmod, tau_mod, r_safe, lookahead):
    """m: no pair farther apart than this can violate well clear or be predicted in
    conflict, when no aircraft flies faster than ``speed_max`` m/s (relative speeds
    ``|v| ≤ V = 2·speed_max``): the larger of :func:`pair_reaches`."""
    return max(pair_reaches(speed_max, dmod, tau_mod, r_safe, lookahead))


def pair_reaches(speed_max, dmod, tau_mod, r_safe, lookahead):
    """``(well clear, prediction)``, m: no pair farther apart than the first can violate
    well clear, none farther apart than the second be predicted in conflict, when no
    aircraft flies faster than ``speed_max`` m/s (relative speeds ``|v| ≤ V = 2·speed_max``).

    Well clear beyond DMOD needs ``s·v < 0`` and ``d² − DMOD² ≤ τ*_mod·(−s·v) ≤ τ*_mod·d·V``,
    so ``d ≤ (τ*_mod V + √(τ*_mod² V² + 4 DMOD²))/2``; the unresolved prediction needs
    ``|s + t v| < r_safe`` for some ``t ≤ look-ahead``, so ``d < r_safe + look-ahead·V``.
    A relative 1e-6 plus 1 m covers float rounding. Neither bound is tied to the sensor
    range: e.g. 460 m/s closing gives 16.2 km for well clear and, with a 120 s look-ahead
    and ``r_safe`` 3 km, 58 km for the prediction, beyond the scenarios' 40 km range.
    """
    v = 2.0 * float(speed_max)
    wcv = 0.5 * (tau_mod * v + math.sqrt((tau_mod * v) ** 2 + 4.0 * dmod * dmod))
    slack = 1.0 + 1e-6
    return max(wcv, dmod) * slack + 1.0, (r_safe + lookahead * v) * slack + 1.0


@njit(cache=True)
def _push(buf, n, key):
    """``buf`` with ``key`` written at ``n`` (doubled first when full)."""
    if n == buf.size:
        grown = np.empty(2 * buf.size, dtype=np.int64)
        grown[:n] = buf[:n]
        buf = grown
    buf[n] = key
    return buf


@njit(cache=True)
def _cell_start(cx, cy, x, y):
    """First index of the (x, y) cell in the lexicographically sorted cells (cx, cy), or
    −1 if there is none."""
    lo, hi = 0, cx.size
    while lo < hi:
        mid = (lo + hi) // 2
        if cx[mid] < x or (cx[mid] == x and cy[mid] < y):
            lo = mid + 1
        else:
            hi = mid
    return lo if lo < cx.size and cx[lo] == x and cy[lo] == y else -1


@njit(cache=True)
def _grid(ids, pos, width):
    """``(ids, cx, cy)``: the aircraft ``ids`` (M,) int64 sorted lexicographically by their
    cells ``(floor(x / width), floor(y / width))`` (M,) int64 each; pos (N, 2) m, width m
    (``inf``: one cell)."""
    m = ids.size
    cx = np.empty(m, dtype=np.int64)
    cy = np.empty(m, dtype=np.int64)
    for a in range(m):
        cx[a] = np.int64(np.floor(pos[ids[a], 0] / width))
        cy[a] = np.int64(np.floor(pos[ids[a], 1] / width))
    o = np.argsort(cy, kind="mergesort")
    o = o[np.argsort(cx[o], kind="mergesort")]
    return ids[o], cx[o], cy[o]


@njit(cache=True, error_model="numpy")
def _scan_cells(
    ids, cx, cy, pos, vel, following, mixed, n_key, dmod2, hmd2, tau_mod, r_safe2, lookahead,
    wcv_reach2, pred_reach2, wcv, nw, pred, nq,
):  # fmt: skip  # pragma: no cover - compiled
    """The pairs of aircraft ``ids`` (M,) in the same or neighbouring cells of a grid
    (:func:`_grid`: sorted by cells (cx, cy) (M,), cells at least as wide as the reach of
    each test made), each once. ``mixed``: test only the pairs with an aircraft that
    follows the policy (``following`` (N,) bool), for well clear only (the prediction
    never flags them); else test every pair for both. Flagged keys ``i·n_key + j``
    (``i < j``) are appended to ``wcv`` (after ``nw`` keys) and ``pred`` (after ``nq``);
    returns ``(wcv, nw, pred, nq)``. Other arguments as :func:`_pair_scan`.
    """
    m = ids.size
    px = np.empty(m)
    py = np.empty(m)
    qx = np.empty(m)
    qy = np.empty(m)
    fol = np.empty(m, dtype=np.bool_)
    for a in range(m):  # the states in cell order, read in order by the inner loop
        i = ids[a]
        px[a], py[a] = pos[i, 0], pos[i, 1]
        qx[a], qy[a] = vel[i, 0], vel[i, 1]
        fol[a] = following[i]
    far2 = wcv_reach2 if mixed else max(wcv_reach2, pred_reach2)
    a0 = 0
    while a0 < m:
        a1 = a0 + 1
        while a1 < m and cx[a1] == cx[a0] and cy[a1] == cy[a0]:
            a1 += 1
        # the cell itself and the four neighbours after it: each neighbouring pair once
        for nb in range(5):
            if nb == 0:
                b0, b1 = a0, a1
            else:
                dx = 0 if nb == 1 else 1
                dy = (1, -1, 0, 1)[nb - 1]
                b0 = _cell_start(cx, cy, cx[a0] + dx, cy[a0] + dy)
                if b0 < 0:
                    continue
                b1 = b0 + 1
                while b1 < m and cx[b1] == cx[b0] and cy[b1] == cy[b0]:
                    b1 += 1
            for a in range(a0, a1):
                ax, ay, avx, avy, afol = px[a], py[a], qx[a], qy[a], fol[a]
                for b in range(b0 if nb else a + 1, b1):
                    if mixed and not (afol or fol[b]):
                        continue
                    # s = p_b − p_a, v = v_b − v_a: the pair's (j − i) or its negation,
                    # which leaves ss, sv and vv the same bits (IEEE negation is exact)
                    sx, sy = px[b] - ax, py[b] - ay
                    ss = sx * sx + sy * sy
                    if ss > far2:
                        continue
                    vx, vy = qx[b] - avx, qy[b] - avy
                    i, j = ids[a], ids[b]
                    if i > j:
                        i, j = j, i
                    sv = sx * vx + sy * vy
                    vv = vx * vx + vy * vy
                    if ss <= wcv_reach2:
                        flag = ss <= dmod2
                        if not flag and sv < 0.0:  # closing, so vv > 0
                            if (dmod2 - ss) / sv <= tau_mod:
                                flag = ss - sv * sv / vv <= hmd2
                        if flag:
                            wcv = _push(wcv, nw, i * n_key + j)
                            nw += 1
                    if not mixed and ss <= pred_reach2:
                        tc = 0.0
                        if vv > 0.0:
                            tc = min(max(-sv / vv, 0.0), lookahead)
                        if ss + 2.0 * tc * sv + tc * tc * vv < r_safe2:
                            pred = _push(pred, nq, i * n_key + j)
                            nq += 1
        a0 = a1
    return wcv, nw, pred, nq


@njit(cache=True, error_model="numpy")
def _pair_scan(
    ids, pos, vel, following, n_key, dmod2, hmd2, tau_mod, r_safe2, lookahead, reaches
):  # pragma: no cover - compiled
    """Well clear and unresolved-conflict flags of every pair of aircraft ``ids`` (M,)
    int64 that can be flagged, each pair tested once.

    pos, vel (N, 2) m, m/s; following (N,) bool; n_key: keys ``i·n_key + j`` (``i < j``);
    squared thresholds m², τ s; reaches (2,) m: :func:`pair_reaches` (``inf``: no
    distance cut, one cell). Returns ``(wcv (W,), predicted (Q,))`` keys, unsorted: pairs
    violating well clear, and pairs neither of whose aircraft flew the CDA policy in the
    last step with a straight-line closest approach within ``lookahead`` s under
    √r_safe2. Time O(M log M + pairs tested), memory O(M + W + Q).

    A pair farther apart than a test's reach cannot be flagged by it and is not worth its
    divisions, and a pair with an aircraft that follows the policy is never predicted in
    conflict, so its reach is well clear's alone (16 km against the prediction's 58 km at
    460 m/s closing and 120 s). So two grids (:func:`_scan_cells`): the aircraft that do
    not follow the policy, with both tests, on cells of the larger reach; all aircraft,
    for the pairs with one that follows and well clear only, on cells of well clear's
    reach. On the 1000-aircraft benchmark traffic nine in ten aircraft follow the policy
    and the pairs tested fall from 111,000 to ~12,000. Each test cuts at its own reach,
    as one grid of the larger reach did, so the flags are the same.
    """
    wcv_reach, pred_reach = reaches[0], reaches[1]
    wcv_reach2, pred_reach2 = wcv_reach * wcv_reach, pred_reach * pred_reach
    wcv = np.empty(16, dtype=np.int64)
    pred = np.empty(16, dtype=np.int64)
    nw = 0
    nq = 0
    n_free = 0
    for a in range(ids.size):
        n_free += not following[ids[a]]
    free = np.empty(n_free, dtype=np.int64)
    k = 0
    for a in range(ids.size):
        if not following[ids[a]]:
            free[k] = ids[a]
            k += 1
    if n_free > 1:
        g, cx, cy = _grid(free, pos, max(wcv_reach, pred_reach))
        wcv, nw, pred, nq = _scan_cells(
            g, cx, cy, pos, vel, following, False, n_key, dmod2, hmd2, tau_mod, r_safe2,
            lookahead, wcv_reach2, pred_reach2, wcv, nw, pred, nq,
        )  # fmt: skip
    if n_free < ids.size:
        g, cx, cy = _grid(ids, pos, wcv_reach)
        wcv, nw, pred, nq = _scan_cells(
            g, cx, cy, pos, vel, following, True, n_key, dmod2, hmd2, tau_mod, r_safe2,
            lookahead, wcv_reach2, pred_reach2, wcv, nw, pred, nq,
        )  # fmt: skip
    return wcv[:nw], pred[:nq]


@njit(cache=True, error_model="numpy")
def _closest_pair_distance(ci, cj, positions):  # pragma: no cover - compiled
    """``min over pairs of hypot(positions[i] − positions[j])``, m, for the pairs of
    aircraft ``ci``, ``cj`` (P,) int64 and positions (N, 2) m (``inf`` for no pair): the
    numpy expression's value, with ``hypot`` (libm, as numpy's) evaluated only for pairs
    whose squared distance is within a relative 1e-9 of the smallest so far (``hypot`` and
    the rounded square differ by far less), not for all of them."""
    best = np.inf
    best2 = np.inf
    for p in range(ci.size):
        i, j = ci[p], cj[p]
        dx = positions[i, 0] - positions[j, 0]
        dy = positions[i, 1] - positions[j, 1]
        d2 = dx * dx + dy * dy
        if d2 <= best2 * (1.0 + 1e-9) or not (d2 == d2):
            d = np.hypot(dx, dy)
            if d < best or not (d == d):
                best = d
            best2 = min(best2, d2)
    return best


@njit(cache=True)
def _track_errors(x, intruder, positions):  # pragma: no cover - compiled
    """(P, 2) m: ``x[:, [0, 2]] − positions[intruder]``, track state rows x (P, ≥3)
    ``[x, vx, y, …]``, intruder (P,) int64, positions (N, 2) m (the numpy expression's
    differences, in a C-contiguous array)."""
    e = np.empty((x.shape[0], 2))
    for p in range(x.shape[0]):
        t = intruder[p]
        e[p, 0] = x[p, 0] - positions[t, 0]
        e[p, 1] = x[p, 2] - positions[t, 1]
    return e


#: up to this many active aircraft, :meth:`WorldMetrics.safety` tests all their pairs
#: (at most 496) instead of building the grid, whose set-up costs more than that
_ONE_CELL = 32


class WorldMetrics:
    """The accumulators of one world run (definitions in the module docstring).

    n aircraft; r_safe, nmac : separation and NMAC distances, m; dt : world step, s.
    """

    def __init__(
        self,
        n: int,
        r_safe: float,
        nmac: float,
        dt: float,
        dmod: float = DMOD_M,
        hmd: float = HMD_M,
        tau_mod: float = TAU_MOD_S,
    ):
        self.n, self.r_safe, self.nmac, self.dt = n, float(r_safe), float(nmac), float(dt)
        self.dmod, self.hmd, self.tau_mod = float(dmod), float(hmd), float(tau_mod)
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
        # safety(): pair keys i·N + j (i < j) of the flagged pairs only, never all N(N−1)/2
        self._wcv_prev = np.zeros(0, dtype=np.int64)  # sorted, in violation at the last call
        self._wcv_ever = KeyMap()  # pairs ever in violation (values unused)
        self._predicted = KeyMap()  # pairs an unresolved conflict was seen for
        self.wcv_events = 0
        self.wcv_pair_steps = 0
        self.induced_keys: set[int] = set()
        self._los_began = np.zeros((0, 2), dtype=np.int64)
        self._safety_calls = 0
        self.first_alert = math.nan
        self.flight_s = 0.0
        self.speed = np.zeros(n)  # m/s, last speed flown
        self.arrival = np.full(n, np.nan)  # s, when the aircraft finished its plan
        self._active = np.ones(n, dtype=bool)

    def contacts(self, positions, pairs: dict, began: dict, range_ij=None):
        """Record this step's pair sets and new episodes.

        positions : (N, 2) m; pairs : set → (P,) sorted keys ``i·N + j`` (``i < j``) of the
        pairs overlapping now, began : set → (E, 2) pairs that began overlapping in the last
        step (:class:`~.bodies.Airspace` ``pairs`` / ``began``; sets LOS, NMAC, RANGE);
        range_ij : optional ``(i, j)`` (P,) int64 aircraft of ``pairs[RANGE]``, in its
        order (:meth:`~.bodies.Airspace.pair_arrays`), so as not to divide the keys.

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
        self._los_began = los_began
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
            ri, rj = (range_keys // n, range_keys % n) if range_ij is None else range_ij
            pos = np.ascontiguousarray(positions, dtype=float)
            d = _closest_pair_distance(
                np.ascontiguousarray(ri, np.int64), np.ascontiguousarray(rj, np.int64), pos
            )
            self.min_sep = min(self.min_sep, float(d))
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
        moved = travelled > 0
        self.flight_s += self.dt * int(np.count_nonzero(moved))
        self.speed = np.where(moved, travelled / self.dt, self.speed)
        if following_policy.any():  # adding +0.0 elsewhere changes nothing: skip it
            self.avoid_turn += np.where(following_policy, np.abs(turned), 0.0)

    def finished(self, time, finished):
        """Aircraft (N,) bool that finished their plan (a route's last waypoint reached) in
        the step ending at ``time`` s and left the world: their arrival time. Aircraft taken
        out otherwise (the env's retired agents) never arrive."""
        self.arrival[finished] = float(time)

    def safety(self, time, positions, velocities, active, following, lookahead_s):
        """Well clear, induced losses and first alert at a step instant (after
        :meth:`contacts` and :meth:`conflicts` of the same instant).

        time : s; positions (N, 2) m, velocities (N, 2) m/s, true; active (N,) bool;
        following (N,) bool, flew the CDA policy in the step just flown; lookahead_s : s,
        the resolver's look-ahead. Only pairs of active aircraft closer than
        :func:`pair_reaches` (from the fastest active aircraft) can be flagged; they are
        found on grids of cells that wide (one numba pass, :func:`_pair_scan`): time and
        memory O(N log N + pairs in reach), state O(pairs ever flagged).
        """
        first = self._safety_calls == 0
        self._safety_calls += 1
        if self.alerts and math.isnan(self.first_alert):
            self.first_alert = float(time)
        self._active = np.array(active, dtype=bool)
        n_key = max(self.n, 1)

        if not first and self._los_began.size:
            a, b = self._los_began[:, 0], self._los_began[:, 1]
            keys = a * n_key + b
            fresh = self._predicted.get(keys) < 0
            self.induced_keys.update(int(k) for k in keys[fresh])
        pos = np.ascontiguousarray(positions, dtype=float)
        vel = np.ascontiguousarray(velocities, dtype=float)
        # non-finite positions fail every test of the pair scan: leave them off the grid
        ids = np.flatnonzero(self._active & np.isfinite(pos).all(axis=1))
        wcv = pred = np.zeros(0, dtype=np.int64)
        if 1 < ids.size <= _ONE_CELL:
            # few aircraft: every pair in one cell (the flags are exact tests, the grid
            # only skips pairs that cannot be flagged), no grid to build
            reaches = np.full(2, math.inf)
        elif ids.size > 1:
            speed = np.hypot(vel[ids, 0], vel[ids, 1])
            speed = speed[np.isfinite(speed)]
            reaches = np.array(
                pair_reaches(
                    speed.max() if speed.size else 0.0,
                    self.dmod,
                    self.tau_mod,
                    self.r_safe,
                    float(lookahead_s),
                )
            )
        if ids.size > 1:
            wcv, pred = _pair_scan(
                ids,
                pos,
                vel,
                np.ascontiguousarray(following, dtype=np.bool_),
                n_key,
                self.dmod**2,
                self.hmd**2,
                self.tau_mod,
                self.r_safe**2,
                float(lookahead_s),
                reaches,
            )
        wcv = np.sort(wcv)
        prev = self._wcv_prev
        if prev.size:
            at = np.minimum(np.searchsorted(prev, wcv), prev.size - 1)
            began = int(np.count_nonzero(prev[at] != wcv))
        else:
            began = int(wcv.size)
        self._wcv_prev = wcv
        if wcv.size:  # (putting nothing changes nothing)
            self._wcv_ever.put(wcv, np.zeros(wcv.size, dtype=np.int64))
        if pred.size:
            self._predicted.put(pred, np.zeros(pred.size, dtype=np.int64))
        self.wcv_events += began
        self.wcv_pair_steps += int(wcv.size)

    def tracking(self, track_pos, true_pos, mode_est=None, mode_true=None):
        """Add (P, 2) estimated vs true positions; optional (Q,) modes to compare."""
        if len(track_pos):
            self._add_errors(np.asarray(track_pos) - np.asarray(true_pos))
        self._add_modes(mode_est, mode_true)

    def track_states(self, x, intruder, positions, mode_est=None, mode_true=None):
        """:meth:`tracking` of the track states ``x`` (P, ≥3) ``[x, vx, y, …]`` of the
        intruders ``intruder`` (P,) int against their true ``positions`` (N, 2) m: the
        same errors (:func:`_track_errors`), without a strided copy and a gather."""
        if len(x):
            x = np.ascontiguousarray(x, dtype=float)
            pos = np.ascontiguousarray(positions, dtype=float)
            self._add_errors(_track_errors(x, np.ascontiguousarray(intruder, np.int64), pos))
        self._add_modes(mode_est, mode_true)

    def _add_errors(self, e):
        """Add the (P, 2) position errors ``e``, m (C-contiguous)."""
        self.sq_err += float(np.einsum("ij,ij->", e, e))
        self.track_samples += len(e)

    def _add_modes(self, mode_est, mode_true):
        if mode_est is not None and len(mode_est):
            self.mode_hits += int(np.count_nonzero(mode_est == mode_true))
            self.mode_samples += len(mode_est)

    def report(self, steps: int, time: float, progress, has_plan, planned_speed=None) -> dict:
        """The metrics dict; progress (N,) planned distance covered, m; has_plan (N,) bool;
        planned_speed (N,) m/s, the speed the plan is timed at where finite (aircraft whose
        speed the CDA policy may change), else the last speed flown."""
        extra = np.where(has_plan, self.flown - np.nan_to_num(progress), 0.0)
        planned = float(np.sum(np.where(has_plan, np.nan_to_num(progress), 0.0)))
        arrived = has_plan & np.isfinite(self.arrival)
        speed = self.speed
        if planned_speed is not None:
            speed = np.where(np.isfinite(planned_speed), planned_speed, speed)
        with np.errstate(divide="ignore", invalid="ignore"):
            delay = self.arrival[arrived] - np.asarray(progress)[arrived] / speed[arrived]
        hours = self.flight_s / 3600.0
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
            "wcv_events": self.wcv_events,
            "wcv_pairs": len(self._wcv_ever),
            "wcv_duration_s": self.wcv_pair_steps * self.dt,
            "induced_los_pairs": len(self.induced_keys),
            "flight_hours": hours,
            "alerts_per_flight_hour": self.alerts / hours if hours > 0 else math.nan,
            "first_alert_s": self.first_alert,
            "arrived": int(np.count_nonzero(arrived)),
            "not_arrived": int(np.count_nonzero(has_plan & self._active)),
            "arrival_delay_mean_s": float(delay.mean()) if delay.size else math.nan,
            "arrival_delay_max_s": float(delay.max()) if delay.size else math.nan,
        }
