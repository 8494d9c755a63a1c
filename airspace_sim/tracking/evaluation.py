"""Trackers measured on recorded flights: the IMM against the best-tuned CV filter.

The paper's future work (§VII) asks how the IMM does on real flight data. Here a recorded
trajectory is the truth: it is resampled to the surveillance period (:func:`resample`: the
recorded positions re-timed and smoothed over half a minute), position measurements with
σ-white noise are drawn from it, and the trackers are run on them:

- the IMM of a :class:`~airspace_sim.dynamics.presets.Preset` (``imm_arguments``, R = σ² I),
  started from the first two measurements (:func:`two_point_initialisation`);
- constant-velocity Kalman filters over a grid of white-noise accelerations σ_a, the best
  one (by position RMSE over all flights) being "the best-tuned CV filter".

Figures (:class:`Evaluation`): position and velocity RMSE overall and in turns, the IMM's
average NIS against its χ²(2) band, and how often the IMM flags a turn. A second is
*turning* when the truth's turn rate is at least :data:`TURNING_DEG_S` in magnitude and
*straight* when it is below :data:`STRAIGHT_DEG_S`; the IMM *flags a turn to the left*
(right) when, by its own mixture, the aircraft turns left (right) at :data:`RATE_FLAG_DEG_S`
or more with probability over one half:
``Σ_j μ_j Pr_j(s Ω ≥ RATE_FLAG_DEG_S) > 1/2`` over the turning modes ``j``, with
``Pr_j`` an indicator of the known rate for a known-rate mode and, for an estimated-rate
(coordinated-turn) mode, the Gaussian probability ``Φ((s Ω̂_j − rate) / σ_Ωj)`` of its
mode-conditioned estimate and variance. For known-rate modes this is "the turning modes of
one side hold most of the probability"; an estimated-rate mode also fits straight flight
(Ω̂ ≈ 0), so its probability counts only as far as its rate estimate says it turns. The
flag is right when its side is the truth's. A second flag, for any tracker with Ω in its state, is the
combined estimate ``|Ω̂| ≥`` :data:`RATE_FLAG_DEG_S`. Turn rates are counter-clockwise
positive.

How good any causal filter can be on these truths (:func:`known_motion_rmse`): Kalman
filters told, at every step, what the IMM has to infer — the truth's own turn rate, the
regime (straight or not), its along-track acceleration — give the position RMSE a tracker
with that knowledge reaches; their ratios to the best-tuned CV filter are the floors of the
IMM / CV ratio (``docs/tracking.md``, ``docs/benchmarks/tracker_floor.py``). The turn
flags are also broken down by the time since the turn began (:attr:`Evaluation.onset`):
how much of the shortfall is detection delay; and both filters' position errors by phase
(:attr:`Evaluation.phases`: in a turn or after one, by the seconds since it began or ended):
where the IMM gains on the CV filter and where it loses. After the fact
(``evaluate(smoother=True)``, the default): both filters smoothed over each whole flight
or with a fixed lag (``smoother_lag_s``): the IMM by two filters
(:func:`airspace_sim.tracking.two_filter.smooth_two_filter`), the CV filter by the RTS
smoother; their position RMSEs and the smoothed IMM's turn flags.

Flights are given as arrays (times in seconds, east/north positions in metres in a local
frame), so any reader can feed this module; the ``evaluate-tracker`` command reads files.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np

from airspace_sim.dynamics import models
from airspace_sim.errors import UserError
from airspace_sim.tracking.consistency import CV_SIGMA_GRID, chi2_band
from airspace_sim.tracking.initialisation import two_point_initialisation

#: |ω| at or above this (deg/s) is a turning second.
TURNING_DEG_S = 1.0
#: |ω| below this (deg/s) is a straight second.
STRAIGHT_DEG_S = 0.25
#: Window (s) of the slow drift removed when re-timing positions (:func:`retime`).
RETIME_DRIFT_S = 120.0
#: The second turn flag: the IMM's combined turn-rate estimate at least this (deg/s).
RATE_FLAG_DEG_S = 0.5
#: A recorded gap longer than this (s) splits a flight: the truth is not interpolated across.
MAX_GAP_S = 30.0
#: Window (s) of the cubic Savitzky–Golay smoothing of recorded positions (:func:`resample`).
SMOOTH_S = 31.0
#: Seconds at the end of each recorded segment left out of its truth (:func:`resample`).
END_TRIM_S = SMOOTH_S
#: Seconds of each track left out of the statistics while the filters settle.
BURN_IN_S = 60.0
#: A turn begins when |ω| reaches this (deg/s) with a sign it keeps (:func:`since_onset`).
ONSET_DEG_S = 0.5
#: Edges (s) of the time-since-onset bins of :attr:`Evaluation.onset`, and of the
#: phases of :attr:`Evaluation.phases` (since a turn began, since it ended).
ONSET_BINS_S = (0.0, 15.0, 30.0, math.inf)


@dataclass(frozen=True)
class Truth:
    """One flight segment resampled every ``period_s``: t_s (K,), state (K, 5)
    ``[x, vx, y, vy, Ω]`` (m, m/s, rad/s, CCW positive)."""

    name: str
    t_s: np.ndarray
    state: np.ndarray


def resample(
    name: str,
    t_s,
    x_m,
    y_m,
    period_s: float,
    speed_mps=None,
    min_duration_s: float = 300.0,
    through_reports: bool = True,
):
    """Truth segments of one recorded flight at period ``period_s`` (list of :class:`Truth`).

    t_s (K,) increasing recorded times; x_m, y_m (K,) east/north positions in metres. The
    flight is split at gaps over :data:`MAX_GAP_S`; each segment's truth ends
    :data:`END_TRIM_S` before its last report, and truths shorter than ``min_duration_s``
    are left out. With ``speed_mps`` (K,), the recorded ground speed, positions are first
    re-timed (:func:`retime`); glitches should be gone before
    (:func:`airspace_sim.recorded.glitches.despike`, which :func:`airspace_sim.recorded.read`
    applies). The path is drawn on a 1 s grid by straight lines between the positions, except
    where positions interpolated on a straight line between reports were left out
    (:func:`airspace_sim.recorded.glitches.reported`): across those spans, by the cubic spline
    through the positions kept (``through_reports=False``: straight lines through every
    position, the truth before 2026-12-08). It is smoothed by a cubic Savitzky–Golay filter over
    :data:`SMOOTH_S` seconds, whose derivatives give the velocity and the turn rate
    ``ω = (vx ay − vy ax) / |v|²``.

    Why smooth: recorded positions are put on a time grid from irregular position reports
    (the traffic samples' 5 s positions advance by 280 m and 570 m alternately at constant
    speed), which an interpolating spline turns into accelerations of tens of m/s². Why not
    the recorded velocity: in the same samples the track angle disagrees with the
    positions' bearing by ~100° for half of some flights. Why the end is cut: a segment's
    last report is often off the track (in the traffic samples' ``collections/switzerland``
    the smoothed truth turned at over 1 °/s in the last half-minute of 264 segments, the
    recorded track angle by a median of 0.1°), and the smoothing spreads it over the last
    half-window; the first minute is left out of the statistics anyway (:data:`BURN_IN_S`).
    Why a spline where interpolations were: a straight line between reports (and the
    interpolated positions on it) is a polygon in turns, chords and corners no aircraft flies.
    Why not everywhere: between reports 10 s apart (``collections/switzerland``) the spline
    rings with what is left of their timing jitter; straight lines there agree with the
    recorded track rate, the spline does not (docs/tracking.md, "Reports and interpolated
    positions").
    """
    from scipy.interpolate import CubicSpline
    from scipy.signal import savgol_filter

    from airspace_sim.recorded.glitches import reported

    t = np.asarray(t_s, dtype=float)
    if t.size > 1 and np.any(np.diff(t) <= 0):
        raise UserError(f"flight {name}: times must increase")
    cuts = np.flatnonzero(np.diff(t) > MAX_GAP_S) + 1
    win = int(SMOOTH_S) | 1
    out = []
    for seg, (a, b) in enumerate(zip(np.r_[0, cuts], np.r_[cuts, t.size])):
        if b - a < 4 or t[b - 1] - t[a] - END_TRIM_S < max(min_duration_s, 2 * SMOOTH_S):
            continue
        xy = [np.asarray(v, dtype=float)[a:b] for v in (x_m, y_m)]
        k = reported(t[a:b], *xy) if through_reports else np.arange(b - a)
        ts, xy = t[a:b][k], [v[k] for v in xy]
        filled = np.diff(k) > 1  # (K'-1,) the span to the next position lost interpolations
        if speed_mps is not None:
            ts, keep = retime(ts, *xy, np.asarray(speed_mps, dtype=float)[a:b][k])
            xy = [v[keep] for v in xy]
            filled = np.maximum.reduceat(np.r_[filled, False], keep)[:-1]  # spans merged
        fine = np.arange(ts[0], ts[-1], 1.0)
        curved = filled[np.clip(np.searchsorted(ts, fine, side="right") - 1, 0, ts.size - 2)]
        cols = []
        for v in xy:
            f = np.interp(fine, ts, v)
            if curved.any():
                f = np.where(curved, CubicSpline(ts, v)(fine), f)
            cols.append([savgol_filter(f, win, 3, deriv=d, mode="interp") for d in (0, 1, 2)])
        (px, vx, ax), (py, vy, ay) = cols
        omega = (vx * ay - vy * ax) / np.maximum(vx**2 + vy**2, 1.0)
        g = np.arange(fine[0], fine[-1] - END_TRIM_S, period_s)
        state = np.stack([np.interp(g, fine, v) for v in (px, vx, py, vy, omega)], axis=1)
        out.append(Truth(f"{name}#{seg}", g, state))
    return out


def retime(t, x, y, speed):
    """Times at which the aircraft really was at the recorded positions: (K',) s and the
    kept indices (K',) int.

    Positions put on a time grid from irregular reports are right in space but late or
    early along the track (the traffic samples' 5 s positions advance 280 m and 570 m
    alternately at constant speed). The distance flown, integrated from the recorded
    ground speed ``speed`` (K,) m/s, says when each point of the path was reached: the
    time ``D⁻¹(s_k)`` of the position's distance ``s_k`` along the recorded path, minus the
    slow drift (a :data:`RETIME_DRIFT_S` moving average) between the two. Points whose new
    time does not increase are dropped.
    """
    s = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(x), np.diff(y)))])
    D = np.concatenate([[0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * np.diff(t))])
    tau = np.interp(s, D, t) if D[-1] > 0 else t.copy()
    delta = tau - t
    g = np.arange(t[0], t[-1] + 1.0, 1.0)
    tau = t + delta - np.interp(t, g, _moving_average(np.interp(g, t, delta), RETIME_DRIFT_S))
    keep = np.flatnonzero(tau > np.r_[-np.inf, np.maximum.accumulate(tau)[:-1]])
    return tau[keep], keep


def _moving_average(v: np.ndarray, width: float) -> np.ndarray:
    """Centred moving average of a 1 s series over ``width`` samples (shrinking at the ends)."""
    k = max(int(width) // 2, 1)
    c = np.concatenate([[0.0], np.cumsum(v)])
    i = np.arange(v.size)
    lo, hi = np.maximum(i - k, 0), np.minimum(i + k + 1, v.size)
    return (c[hi] - c[lo]) / (hi - lo)


@dataclass
class Evaluation:
    """Figures of one setting (σ, period) over all flights; RMSEs in m and m/s."""

    sigma_m: float
    period_s: float
    preset: str
    n_flights: int
    n_seconds: float
    pos_imm: float
    vel_imm: float
    pos_cv: float
    vel_cv: float
    cv_sigma: float
    pos_imm_turn: float
    pos_cv_turn: float
    vel_imm_turn: float
    vel_cv_turn: float
    nis: float
    nis_band: tuple
    turning_flagged: float
    turning_flagged_wrong_sign: float
    straight_flagged: float
    turning_rate_flagged: float
    straight_rate_flagged: float
    gated: int
    cv_grid: dict = field(default_factory=dict)
    #: per :data:`ONSET_BINS_S` bin [lo, hi) of seconds since the turn began: (lo, hi,
    #: share of the turning seconds, share of those flagged with the right sign)
    onset: list = field(default_factory=list)
    #: where the position errors are: per phase ("turn" and :data:`ONSET_BINS_S` bin of
    #: seconds since it began, or "after" a turn and the bin of seconds since it ended; a
    #: flight's seconds before its first turn count as long after one): (phase, lo, hi,
    #: share of the evaluated seconds, IMM position RMSE m, best CV position RMSE m)
    phases: list = field(default_factory=list)
    #: after the fact (``evaluate(smoother=True)``; None otherwise or for a model the
    #: smoother does not take): both filters smoothed over each whole flight (or with
    #: ``smoother_lag_s`` of look-ahead), position RMSE of the smoothed IMM and of the
    #: RTS-smoothed best CV filter, and the smoothed IMM's turn flags scored as the filter's
    pos_imm_smoothed: float | None = None
    pos_cv_smoothed: float | None = None
    smoothed_turning_flagged: float | None = None
    smoothed_turning_flagged_wrong_sign: float | None = None
    smoothed_straight_flagged: float | None = None
    #: the smoothers' look-ahead (s): None for the whole flight, else fixed-lag
    smoother_lag_s: float | None = None

    def to_dict(self) -> dict:
        """The figures as JSON-ready Python values."""
        d = asdict(self)
        d["cv_grid"] = {str(k): v for k, v in self.cv_grid.items()}
        d["onset"] = [
            {"from_s": lo, "to_s": None if math.isinf(hi) else hi, "share": share, "flagged": fl}
            for lo, hi, share, fl in self.onset
        ]
        d["phases"] = [
            {"phase": ph, "from_s": lo, "to_s": None if math.isinf(hi) else hi, "share": share,
             "pos_imm": imm, "pos_cv": cv}
            for ph, lo, hi, share, imm, cv in self.phases
        ]  # fmt: skip
        return d

    def lines(self) -> list[str]:
        lo, hi = self.nis_band
        return [
            f"sigma={self.sigma_m:g} m, period={self.period_s:g} s, preset={self.preset}: "
            f"{self.n_flights} flight segments, {self.n_seconds / 3600:.1f} h",
            f"  position RMSE  IMM {self.pos_imm:7.1f} m   best CV {self.pos_cv:7.1f} m "
            f"(sigma_a={self.cv_sigma:g} m/s^2)   ratio {self.pos_imm / self.pos_cv:.3f}",
            f"  velocity RMSE  IMM {self.vel_imm:7.2f} m/s best CV {self.vel_cv:7.2f} m/s"
            f"   ratio {self.vel_imm / self.vel_cv:.3f}",
            f"  in turns: position IMM {self.pos_imm_turn:.1f} m, CV {self.pos_cv_turn:.1f} m "
            f"(ratio {self.pos_imm_turn / self.pos_cv_turn:.3f}); velocity IMM "
            f"{self.vel_imm_turn:.2f} m/s, CV {self.vel_cv_turn:.2f} m/s "
            f"(ratio {self.vel_imm_turn / self.vel_cv_turn:.3f})",
            f"  NIS (m=2) average {self.nis:.3f}, 95% band [{lo:.3f}, {hi:.3f}]; gated "
            f"measurements {self.gated}",
            f"  turning seconds flagged as a turn of the right sign "
            f"{100 * self.turning_flagged:.1f}% (wrong sign {100 * self.turning_flagged_wrong_sign:.1f}%);"
            f" straight seconds flagged {100 * self.straight_flagged:.2f}%",
            f"  by the rate estimate (|Omega| >= {RATE_FLAG_DEG_S:g} deg/s, right sign): turning "
            f"{100 * self.turning_rate_flagged:.1f}%, straight {100 * self.straight_rate_flagged:.2f}%",
            "  turning seconds by time since the turn began: "
            + "; ".join(
                f"{lo:g}-{hi:g} s {100 * share:.0f}% of them, flagged {100 * fl:.0f}%"
                for lo, hi, share, fl in self.onset
            ),
            "  position RMSE by phase, IMM / CV m (share of the seconds): "
            + "; ".join(
                f"{ph} {lo:g}-{hi:g} s {imm:.1f} / {cv:.1f} ({100 * share:.0f}%)"
                for ph, lo, hi, share, imm, cv in self.phases
            ),
        ] + self._smoothed_lines()

    def _smoothed_label(self) -> str:
        if self.smoother_lag_s is None:
            return "after the fact (fixed-interval smoothers)"
        return f"{self.smoother_lag_s:g} s late (fixed-lag smoothers)"

    def _smoothed_lines(self) -> list[str]:
        if self.pos_imm_smoothed is None:
            return []
        return [
            f"  {self._smoothed_label()}: position RMSE IMM "
            f"{self.pos_imm_smoothed:.1f} m, CV {self.pos_cv_smoothed:.1f} m (ratio "
            f"{self.pos_imm_smoothed / self.pos_cv_smoothed:.3f}); turning seconds flagged "
            f"{100 * self.smoothed_turning_flagged:.1f}% (wrong sign "
            f"{100 * self.smoothed_turning_flagged_wrong_sign:.1f}%), straight "
            f"{100 * self.smoothed_straight_flagged:.2f}%",
        ]


def _stack(truths):
    """Flights side by side from their first sample: (T, F, 5) truth, NaN after the end."""
    T = max(tr.t_s.size for tr in truths)
    X = np.full((T, len(truths), models.N_STATE), np.nan)
    for f, tr in enumerate(truths):
        X[: tr.t_s.size, f] = tr.state
    return X


def _rmse(err) -> float:
    return float(np.sqrt(np.mean(np.sum(err**2, axis=-1)))) if err.size else float("nan")


def measurements(X, sigma_m: float, seed: int):
    """Position measurements (T, F, 2) m of stacked truths ``X`` (T, F, 5) (:func:`_stack`):
    ``(x, y) + N(0, σ² I)`` from ``numpy.random.default_rng(seed)``, NaN after each flight."""
    T, F, _ = X.shape
    rng = np.random.default_rng(seed)
    return X[..., [0, 2]] + sigma_m * rng.standard_normal((T, F, 2))


def _evaluated(X, period_s: float):
    """(T, F) bool: the seconds the statistics count (live, after the burn-in)."""
    ev = np.isfinite(X[..., 0])
    ev[: 2 + int(math.ceil(BURN_IN_S / period_s))] = False
    return ev


def since_onset(omega, period_s: float):
    """Seconds since the current turn began, (T, F), from turn rates ``omega`` (T, F) rad/s
    every ``period_s``: a turn is a run of samples with |ω| ≥ :data:`ONSET_DEG_S` of one
    sign; NaN outside turns."""
    w = np.asarray(omega, dtype=float)
    s = np.where(np.abs(w) >= math.radians(ONSET_DEG_S), np.sign(w), 0.0)  # NaN -> 0
    T = s.shape[0]
    k = np.arange(T)[:, None]
    new = (s != 0) & np.vstack([np.ones((1,) + s.shape[1:], bool), s[1:] != s[:-1]])
    start = np.maximum.accumulate(np.where(new, k, -1), axis=0)
    return np.where(s != 0, (k - start) * period_s, np.nan)


def since_turn_end(omega, period_s: float):
    """Seconds since the last turn ended, (T, F), from turn rates ``omega`` (T, F) rad/s
    every ``period_s``: NaN while turning (|ω| ≥ :data:`ONSET_DEG_S`, as
    :func:`since_onset`), infinite before a flight's first turn (NaN rates are not turns)."""
    w = np.abs(np.nan_to_num(np.asarray(omega, dtype=float)))
    turning = w >= math.radians(ONSET_DEG_S)
    k = np.arange(turning.shape[0]).reshape((-1,) + (1,) * (turning.ndim - 1))
    last = np.maximum.accumulate(np.where(turning, k, -1), axis=0)
    since = np.where(last >= 0, (k - last) * period_s, np.inf)
    return np.where(turning, np.nan, since)


def known_motion_rmse(
    truths,
    sigma_m: float,
    period_s: float,
    sigma_accel,
    along_track: bool = False,
    seed: int = 0,
    turn_rate: bool = True,
    along_track_window_s: float = 0.0,
) -> float:
    """Position RMSE (m) of a Kalman filter told the truth's own motion, on the measurements
    :func:`evaluate` draws (same ``seed``, same seconds counted).

    State ``[x, vx, y, vy]``; each step is the coordinated turn at the truth's turn rate of
    the step's start (Bar-Shalom, Li & Kirubarajan 2001, §11.7.1, the rate known), with
    white-noise acceleration ``sigma_accel`` m/s²: a number, or a pair (σ on straight
    seconds, |ω| < :data:`STRAIGHT_DEG_S`; σ elsewhere) — the filter is then told the regime
    too. With ``along_track`` the truth's along-track acceleration (the derivative of its
    speed) is a known input as well; with ``turn_rate=False`` the rate is not told (ω = 0:
    the constant-velocity Kalman filter of :func:`evaluate`'s grid). With
    ``along_track_window_s`` the filter is told only the along-track acceleration's
    centred moving average over that many seconds (its slow part, what a state that
    changes slowly could follow). Such a filter has what an IMM over these modes has to
    infer: its RMSE, over the best-tuned CV filter's, is a floor for the IMM / CV ratio of
    any tracker that models the turn but not the speed changes (``docs/tracking.md``).
    """
    if not truths:
        raise UserError("evaluate-tracker: no flight segment long enough to evaluate")
    X = _stack(truths)
    Z = measurements(X, sigma_m, seed)
    T, F, _ = X.shape
    R = models.measurement_noise(sigma_m)
    x0, P0 = two_point_initialisation(Z[0], Z[1], period_s, R, 0.0, math.radians(3.0) ** 2)
    x, P = np.nan_to_num(x0[:, :4]), P0[:, :4, :4].copy()
    w = np.nan_to_num(X[..., 4]) if turn_rate else np.zeros((T, F))
    if np.ndim(sigma_accel) == 0:
        sa = np.full((T, F), float(sigma_accel))
    else:
        quiet, other = (float(v) for v in sigma_accel)
        sa = np.where(np.abs(np.degrees(np.nan_to_num(X[..., 4]))) < STRAIGHT_DEG_S, quiet, other)
    Q1 = models.white_noise_acceleration(1.0, period_s)[:4, :4]
    a = np.zeros((T, F, 2))
    if along_track:
        v = np.nan_to_num(X[..., [1, 3]])
        speed = np.hypot(v[..., 0], v[..., 1])
        at = np.gradient(speed, period_s, axis=0)
        if along_track_window_s > 0:
            width = along_track_window_s / period_s
            at = np.stack([_moving_average(c, width) for c in at.T], axis=1)
        a = (at / np.maximum(speed, 1.0))[..., None] * v
    H = models.position_measurement_matrix()[:, :4]
    est = np.full((T, F, 4), np.nan)
    for k in range(2, T):
        Fk = _turn_transition(w[k - 1], period_s)
        xp = np.einsum("fij,fj->fi", Fk, x)
        xp[:, [0, 2]] += 0.5 * period_s**2 * a[k - 1]
        xp[:, [1, 3]] += period_s * a[k - 1]
        Pp = Fk @ P @ np.swapaxes(Fk, 1, 2) + sa[k - 1][:, None, None] ** 2 * Q1
        ok = np.all(np.isfinite(Z[k]), axis=1)
        S = H @ Pp @ H.T + R
        K = Pp @ H.T @ np.linalg.inv(S)
        xu = xp + np.einsum("fij,fj->fi", K, np.nan_to_num(Z[k]) - xp @ H.T)
        IKH = np.eye(4) - K @ H
        Pu = IKH @ Pp @ np.swapaxes(IKH, 1, 2) + K @ R @ np.swapaxes(K, 1, 2)  # Joseph form
        x = np.where(ok[:, None], xu, xp)
        P = np.where(ok[:, None, None], Pu, Pp)
        est[k] = x
    ev = _evaluated(X, period_s)
    return _rmse((est - X[..., :4])[ev][:, [0, 2]])


def _turn_transition(omega, T: float):
    """(F, 4, 4) coordinated-turn transitions of ``[x, vx, y, vy]`` at rates ``omega`` (F,)
    rad/s over ``T`` s (the constant-velocity one at ω = 0)."""
    u = omega * T
    small = np.abs(u) < 1e-9
    safe = np.where(small, 1.0, omega)
    s = np.where(small, T, np.sin(u) / safe)
    c = np.where(small, 0.5 * omega * T * T, (1.0 - np.cos(u)) / safe)
    co, si = np.cos(u), np.sin(u)
    F = np.zeros(omega.shape + (4, 4))
    F[:, 0, 0] = F[:, 2, 2] = 1.0
    F[:, 0, 1], F[:, 0, 3], F[:, 2, 1], F[:, 2, 3] = s, -c, c, s
    F[:, 1, 1], F[:, 1, 3], F[:, 3, 1], F[:, 3, 3] = co, -si, si, co
    return F


#: Standard deviation (m/s²) of the along-track acceleration a track starts with (a = 0).
INITIAL_ALONG_TRACK_SD = 1.0


def _initial_state(Z, period_s: float, R, n_state: int):
    """Tracks started from the first two measurements of Z (T, F, 2): x0 (F, n_state),
    P0 (F, n_state, n_state); Ω = 0 (sd 3 °/s) and, in the 6-state layout, a = 0
    (sd :data:`INITIAL_ALONG_TRACK_SD`)."""
    x0, P0 = two_point_initialisation(Z[0], Z[1], period_s, R, 0.0, math.radians(3.0) ** 2)
    if n_state == models.N_STATE:
        return x0, P0
    F = x0.shape[0]
    x6, P6 = np.zeros((F, n_state)), np.zeros((F, n_state, n_state))
    x6[:, :5], P6[:, :5, :5] = x0, P0
    P6[:, 5, 5] = INITIAL_ALONG_TRACK_SD**2
    return x6, P6


def turn_probabilities(mu, x_modes, P_modes, known, turning_modes, rate):
    """(...,), (...,): the probability, by an IMM's mixture, of a left and of a right turn at
    ``rate`` rad/s or more. mu (..., M) mode probabilities, x_modes (..., M, n) and P_modes
    (..., M, n, n) the mode-conditioned estimates (an IMM's, after a step, or a smoother's);
    known (M,) each mode's known turn rate (NaN: estimated, use the mode's Ω̂ and its
    variance); turning_modes (M,) bool."""
    from scipy.special import ndtr

    w = x_modes[..., 4]  # (..., M) Ω̂_j
    sd = np.sqrt(np.maximum(P_modes[..., 4, 4], 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        left = np.where(np.isnan(known), ndtr((w - rate) / sd), known >= rate)
        right = np.where(np.isnan(known), ndtr((-w - rate) / sd), known <= -rate)
    m = np.where(turning_modes, mu, 0.0)
    return np.sum(m * np.nan_to_num(left), axis=-1), np.sum(m * np.nan_to_num(right), axis=-1)


#: Memory (bytes) a batch of flights' smoothing may take: the forward record's K·B·M·n²
#: covariances for a one-mode filter (the RTS smoother), :func:`two_filter_records` times
#: that for an IMM's two filters; flights are batched by length under it.
SMOOTHER_BATCH_BYTES = 2**27


def two_filter_records(n_modes: int) -> int:
    """How many forward records' memory the two-filter smoother holds at once: both filters'
    records, the backward one in forward time, the fused one, one fused pair per mode for
    the mode being merged, and the fusion's work arrays."""
    return 6 + n_modes


def _smoothed_runs(Z, x0, P0, mu0, model: dict, lengths, period_s: float, lag=None):
    """Each flight's measurements Z (T, F, 2) from step 2 on, smoothed by the IMM of
    ``model`` by two filters (:func:`airspace_sim.tracking.two_filter.smooth_two_filter`),
    over the whole flight or with ``lag`` steps of look-ahead; with one mode by the filter
    and :func:`airspace_sim.tracking.smoother.smooth` (the Rauch–Tung–Striebel smoother,
    exact); in batches of flights of similar length under :data:`SMOOTHER_BATCH_BYTES` (a
    batch's record is as long as its longest flight). Re-running the filters costs less than keeping every flight's record from
    :func:`evaluate`'s own run at once. Yields ``(flights (b,), L, Smoothed)`` with the
    records of steps ``2..L-1``; ``lengths`` (F,) each flight's number of measured steps,
    ``period_s`` the step (s)."""
    from airspace_sim.tracking import IMM
    from airspace_sim.tracking.smoother import forward_record, smooth
    from airspace_sim.tracking.two_filter import smooth_two_filter

    M, n = len(mu0), x0.shape[1]
    two_filter = M > 1
    budget = SMOOTHER_BATCH_BYTES // (two_filter_records(M) if two_filter else 1)
    order = np.argsort(lengths, kind="stable")
    i = 0
    while i < order.size:
        # flights sorted by length: a batch of j holds j records of its last one's length
        longest = np.maximum(lengths[order[i:]], 3)
        cost = np.arange(1, longest.size + 1) * longest * M * n * (n + 1) * 8
        b = order[i : i + max(1, int(np.count_nonzero(cost <= budget)))]
        i += b.size
        L = int(lengths[b].max())
        n_steps = lengths[b] - 2
        if two_filter:
            sm = smooth_two_filter(Z[2:L, b], model, x0[b], P0[b], mu0, period_s, n_steps, lag)
        else:
            imm = IMM(**model, x0=x0[b], P0=P0[b], mu0=mu0, gate_probability=1.0)
            sm = smooth(*forward_record(imm, Z[2:L, b]), model, n_steps=n_steps, lag=lag)
        yield b, L, sm


def _right_flags(p_left, p_right, X):
    """(T, F) bool: a turn flagged (probability over one half) of the truth's sign."""
    left, rightward = p_left > 0.5, p_right > 0.5
    return (left & (X[..., 4] > 0)) | (rightward & (X[..., 4] < 0))


def _flags(p_left, p_right, X, ev) -> dict:
    """The turn flags' scores over the evaluated seconds ``ev`` (T, F): turning seconds
    flagged with the right sign, with the wrong one, straight seconds flagged."""
    omega = np.degrees(X[..., 4])
    turning = ev & (np.abs(omega) >= TURNING_DEG_S)
    straight = ev & (np.abs(omega) < STRAIGHT_DEG_S)
    flagged = (p_left > 0.5) | (p_right > 0.5)
    right = _right_flags(p_left, p_right, X)
    return dict(
        turning_flagged=float(right[turning].mean()),
        turning_flagged_wrong_sign=float((flagged & ~right)[turning].mean()),
        straight_flagged=float(flagged[straight].mean()),
    )


def _smoothed_figures(
    X, Z, ev, imm_run, cv_run, flags, period_s: float, lag=None, keep=()
) -> tuple[dict, dict]:
    """The :class:`Evaluation` fields of the smoothed IMM and CV filter: ``imm_run`` and
    ``cv_run`` the (x0, P0, mu0, model) of each, ``flags`` the (known, turning_modes, rate) of
    :func:`turn_probabilities`, ``period_s`` the step (s), ``lag`` steps of fixed-lag (None:
    fixed-interval). Errors are summed batch by batch, not kept per step, except for the
    flights ``keep`` (F',): second, the smoothed IMM's :class:`Record` fields of those."""
    T, F, _ = X.shape
    lengths = np.isfinite(Z[..., 0]).sum(axis=0)
    p_left, p_right = np.full((T, F), np.nan), np.full((T, F), np.nan)
    keep = np.asarray(keep, dtype=int)
    slot = np.full(F, -1)
    slot[keep] = np.arange(keep.size)
    kept_x = np.full((T, keep.size, models.N_STATE), np.nan)
    kept_mu = np.full((T, keep.size, len(imm_run[2])), np.nan)
    sse = [0.0, 0.0]
    for i, run in enumerate((imm_run, cv_run)):
        for b, L, sm in _smoothed_runs(Z, *run, lengths, period_s, lag=lag):
            x = sm.x
            e = (x[..., [0, 2]] - X[2:L, b][..., [0, 2]])[ev[2:L, b]]
            sse[i] += float(np.sum(e**2))
            if run is imm_run:
                p_left[2:L, b], p_right[2:L, b] = turn_probabilities(
                    sm.mu, sm.x_modes, sm.P_modes, *flags
                )
                j = slot[b]
                kept_x[2:L, j[j >= 0]] = x[:, j >= 0, : models.N_STATE]
                kept_mu[2:L, j[j >= 0]] = sm.mu[:, j >= 0]
    n = max(int(ev.sum()), 1)
    after = ~np.isfinite(X[:, keep, 0])  # a batch's record runs on past its shorter flights
    kept_x[after], kept_mu[after] = np.nan, np.nan
    kept_p = [np.where(after, np.nan, p[:, keep]) for p in (p_left, p_right)]
    return dict(
        pos_imm_smoothed=math.sqrt(sse[0] / n),
        pos_cv_smoothed=math.sqrt(sse[1] / n),
        **{f"smoothed_{k}": v for k, v in _flags(p_left, p_right, X, ev).items()},
    ), dict(smoothed=kept_x, smoothed_mu=kept_mu, smoothed_p_left=kept_p[0],
            smoothed_p_right=kept_p[1])  # fmt: skip


@dataclass(frozen=True)
class Record:
    """Every step of an evaluation for some of its flight segments (what
    :mod:`airspace_sim.tracking.evaluation_plot` draws): T steps of ``period_s`` s from each
    segment's first sample, F' segments, NaN after a segment's end (and for the first two
    steps, the filters' start). States ``[x, vx, y, vy, Ω]`` (m, m/s, rad/s, CCW positive)."""

    #: (F',) the segments' names (:attr:`Truth.name`)
    names: tuple
    period_s: float
    #: (M,) the IMM's modes (:meth:`~airspace_sim.dynamics.presets.Preset.mode_names`)
    mode_names: tuple
    #: (T, F', 5) the truth
    truth: np.ndarray
    #: (T, F', 2) the measurements (m)
    z: np.ndarray
    #: (T, F') bool: the steps the statistics count (after the burn-in)
    evaluated: np.ndarray
    #: (T, F', 5) the IMM's combined estimate
    imm: np.ndarray
    #: (T, F', M) its mode probabilities
    mu: np.ndarray
    #: (T, F') its probability of a left / right turn (:func:`turn_probabilities`)
    p_left: np.ndarray
    p_right: np.ndarray
    #: (T, F', 4) ``[x, vx, y, vy]`` of the best-tuned CV filter
    cv: np.ndarray
    #: the smoothed IMM, as ``imm``, ``mu``, ``p_left``, ``p_right``; None without smoother
    smoothed: np.ndarray | None = None
    smoothed_mu: np.ndarray | None = None
    smoothed_p_left: np.ndarray | None = None
    smoothed_p_right: np.ndarray | None = None


def evaluate(
    truths,
    preset,
    sigma_m: float,
    period_s: float,
    seed: int = 0,
    cv_sigmas=CV_SIGMA_GRID,
    gate_probability: float = 1.0,
    smoother: bool = True,
    smoother_lag_s: float | None = None,
) -> Evaluation:
    """Run the preset's IMM and the CV grid on noisy measurements of ``truths``.

    ``truths``: :class:`Truth` segments sampled every ``period_s`` s; ``preset`` a
    :class:`~airspace_sim.dynamics.presets.Preset` whose tracker model
    (:meth:`~airspace_sim.dynamics.presets.Preset.filter_model`) is run, its ``dt``
    replaced by ``period_s``; measurements ``z = H x + N(0, σ² I)`` from
    ``numpy.random.default_rng(seed)``. All flights run in one batch, aligned at their first
    sample; statistics skip the first :data:`BURN_IN_S` seconds of each.

    No gate by default (``gate_probability=1``): the measurements have no outliers, and a
    track whose model misses a manoeuvre would otherwise be gated for the rest of the
    flight (there is no re-initialisation here), which measures track loss, not accuracy.
    ``gated`` counts the measurements the given gate rejected.

    ``smoother``: also smooth both filters over each whole flight (the IMM with
    :func:`~airspace_sim.tracking.two_filter.smooth_two_filter`, the best CV filter with the
    RTS smoother) and score the smoothed turn flags and positions (always without a gate):
    the turns a recorded flight holds, labelled after the fact. ``smoother_lag_s``: fixed-lag
    smoothers instead (the same, with ``lag``), each step given the measurements up to that
    many seconds later (rounded to whole steps): the flags of a tracker that reports that
    late. Not for models with the along-track acceleration
    (their smoothed fields stay None).
    """
    return evaluate_with_record(
        truths, preset, sigma_m, period_s, (), seed, cv_sigmas, gate_probability, smoother,
        smoother_lag_s,
    )[0]  # fmt: skip


def evaluate_with_record(
    truths,
    preset,
    sigma_m: float,
    period_s: float,
    flights,
    seed: int = 0,
    cv_sigmas=CV_SIGMA_GRID,
    gate_probability: float = 1.0,
    smoother: bool = True,
    smoother_lag_s: float | None = None,
) -> tuple[Evaluation, Record]:
    """:func:`evaluate`, and the :class:`Record` of its every step for the truths at indices
    ``flights`` (F',) int (the same run: the figures do not depend on what is recorded)."""
    from airspace_sim.tracking import IMM

    if not truths:
        raise UserError("evaluate-tracker: no flight segment long enough to evaluate")
    p = preset.with_(dt=period_s, measurement_sigma=sigma_m).filter_model()
    X = _stack(truths)
    T, F, _ = X.shape
    Z = measurements(X, sigma_m, seed)  # NaN after each flight
    R = models.measurement_noise(sigma_m)
    x0, P0 = _initial_state(Z, period_s, R, p.n_state)
    mu0 = p.mu0()
    ev = _evaluated(X, period_s)
    keep = np.asarray(flights, dtype=int).reshape(-1)
    if keep.size and (keep.min() < 0 or keep.max() >= F):
        raise UserError(f"evaluate: flights to record must be in 0..{F - 1}, got {keep.tolist()}")
    kept_mu = np.full((T, keep.size, len(mu0)), np.nan)

    imm = IMM(**p.imm_arguments(), x0=x0, P0=P0, mu0=mu0, gate_probability=gate_probability)
    turning_modes = np.asarray(p.turning_modes(), dtype=bool)
    known = np.where(p.estimated(), np.nan, np.asarray(p.turn_rates))  # NaN: estimated
    flag_rate = math.radians(RATE_FLAG_DEG_S)
    est = np.full((T, F, models.N_STATE), np.nan)
    p_left = np.full((T, F), np.nan)
    p_right = np.full((T, F), np.nan)
    nis = np.full((T, F), np.nan)
    gated = 0
    for k in range(2, T):
        imm.step(Z[k])
        est[k] = imm.x[:, : models.N_STATE]
        kept_mu[k] = imm.mu[keep]
        p_left[k], p_right[k] = turn_probabilities(
            imm.mu, imm.x_modes, imm.P_modes, known, turning_modes, flag_rate
        )
        nis[k] = imm.nis
        gated += int(np.count_nonzero(imm.gated & ev[k]))

    # the CV filter as a one-mode IMM: the same kernel (fast on long batches), and the
    # one-mode IMM is a Kalman filter (tests/test_imm_filterpy.py)
    def cv_model(sigma_a):
        return dict(
            transitions=models.constant_velocity(period_s)[None],
            process_noise=models.white_noise_acceleration(sigma_a, period_s)[None],
            measurement_matrix=models.position_measurement_matrix(),
            measurement_noise=R, transition_matrix=[[1.0]],
        )  # fmt: skip

    grid, cv_est = {}, {}
    for s in cv_sigmas:
        kf = IMM(**cv_model(s), x0=x0[:, :5], P0=P0[:, :5, :5], mu0=[1.0],
                 gate_probability=gate_probability)  # fmt: skip
        e = np.full((T, F, 4), np.nan)
        for k in range(2, T):
            kf.step(Z[k])
            e[k] = kf.x[:, :4]
        cv_est[s] = e
        grid[float(s)] = _rmse((e - X[..., :4])[ev][:, [0, 2]])
    best = min(grid, key=grid.get)
    cv = cv_est[best]
    smoothed, kept_smoothed = {}, {}
    if smoother and not p.along_track().any():
        if smoother_lag_s is not None and not (
            math.isfinite(smoother_lag_s) and smoother_lag_s >= 0
        ):
            raise UserError(f"evaluate: smoother lag must be >= 0 s, got {smoother_lag_s!r}")
        lag = None if smoother_lag_s is None else int(round(smoother_lag_s / period_s))
        flags = (known, turning_modes, flag_rate)
        cv_run = (x0[:, :5], P0[:, :5, :5], [1.0], cv_model(best))
        imm_run = (x0, P0, mu0, p.imm_arguments())
        smoothed, kept_smoothed = _smoothed_figures(
            X, Z, ev, imm_run, cv_run, flags, period_s, lag, keep
        )
        smoothed["smoother_lag_s"] = None if lag is None else lag * period_s

    omega = np.degrees(X[..., 4])
    turning = ev & (np.abs(omega) >= TURNING_DEG_S)
    straight = ev & (np.abs(omega) < STRAIGHT_DEG_S)
    right = _right_flags(p_left, p_right, X)
    same_sign = np.sign(est[..., 4]) == np.sign(X[..., 4])
    by_rate = np.abs(np.degrees(est[..., 4])) >= RATE_FLAG_DEG_S
    e_imm, e_cv = est[..., :4] - X[..., :4], cv - X[..., :4]
    ni = nis[ev & np.isfinite(nis)]
    onset_s = since_onset(X[..., 4], period_s)
    onset = []
    for lo, hi in zip(ONSET_BINS_S[:-1], ONSET_BINS_S[1:]):
        b = turning & (onset_s >= lo) & (onset_s < hi)
        share = float(b.sum() / max(turning.sum(), 1))
        onset.append((lo, hi, share, float(right[b].mean()) if b.any() else float("nan")))
    phases = []
    after_s = since_turn_end(X[..., 4], period_s)
    for phase, t_s in (("turn", onset_s), ("after", after_s)):
        for lo, hi in zip(ONSET_BINS_S[:-1], ONSET_BINS_S[1:]):
            b = ev & (t_s >= lo) & ((t_s < hi) | math.isinf(hi))  # NaN: the other phase
            rmse = [_rmse(e[b][:, [0, 2]]) for e in (e_imm, e_cv)]
            phases.append((phase, lo, hi, float(b.sum() / max(ev.sum(), 1)), *rmse))
    after = ~np.isfinite(X[:, keep, 0])  # the filters predict on past a flight's end

    def kept(a):
        return np.where(after.reshape(after.shape + (1,) * (a.ndim - 2)), np.nan, a)

    record = Record(
        names=tuple(truths[f].name for f in keep), period_s=period_s,
        mode_names=p.mode_names(), truth=X[:, keep], z=Z[:, keep], evaluated=ev[:, keep],
        imm=kept(est[:, keep]), mu=kept(kept_mu), p_left=kept(p_left[:, keep]),
        p_right=kept(p_right[:, keep]), cv=kept(cv[:, keep]), **kept_smoothed,
    )  # fmt: skip
    return Evaluation(
        sigma_m=sigma_m,
        period_s=period_s,
        preset=p.name,
        n_flights=F,
        n_seconds=float(ev.sum() * period_s),
        pos_imm=_rmse(e_imm[ev][:, [0, 2]]),
        vel_imm=_rmse(e_imm[ev][:, [1, 3]]),
        pos_cv=grid[best],
        vel_cv=_rmse(e_cv[ev][:, [1, 3]]),
        cv_sigma=best,
        pos_imm_turn=_rmse(e_imm[turning][:, [0, 2]]),
        pos_cv_turn=_rmse(e_cv[turning][:, [0, 2]]),
        vel_imm_turn=_rmse(e_imm[turning][:, [1, 3]]),
        vel_cv_turn=_rmse(e_cv[turning][:, [1, 3]]),
        nis=float(ni.mean()),
        nis_band=chi2_band(2, int(ni.size), 0.95),
        **_flags(p_left, p_right, X, ev),
        turning_rate_flagged=float((by_rate & same_sign)[turning].mean()),
        straight_rate_flagged=float(by_rate[straight].mean()),
        gated=gated,
        cv_grid=grid,
        onset=onset,
        phases=phases,
        **smoothed,
    ), record
