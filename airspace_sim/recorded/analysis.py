"""What a replay measures about the real aircraft in it: separation, alerts, tracks, modes.

:class:`ReplayStats` watches a :class:`~airspace_sim.world.World` holding recorded aircraft
(``world.moved``) after every step and reports, for the pairs of real aircraft:

- **losses of separation**: pairs closer than ``r_safe`` horizontally (the world's pymunk LoS
  set, the 2-D view the detection has), and the subset also closer than ``vertical_ft``
  vertically by their recorded barometric altitudes (the "3-D" losses a controller counts);
- **predicted losses (alerts)**: a pair is alerted while either aircraft's confirmed track
  of the other (age ≥ the resolver's ``confirm_s``) predicts a closest approach below
  ``r_safe`` within the look-ahead (straight-line CPA from the track and the ownship's true
  state, :func:`airspace_sim.avoidance.cpa.cpa_min_ratio`). An alert episode is *true* if
  the pair loses separation before it ends or within the look-ahead after; a loss is
  *alerted* if an episode overlapped the look-ahead before it began, and the lead time is
  from that episode's start;
- **tracks against the recording**: position (RMSE, median, 95th percentile), velocity and
  turn-rate errors of the confirmed tracks of real aircraft, against the recording as
  flown in the world;
- **mode identification against the recorded turn rate**: track-seconds of intruders
  turning (|ω| ≥ :data:`TURNING_DEG_S`, recorded) and flying straight (|ω| ≤
  :data:`STRAIGHT_DEG_S`), and how many the tracker flags as a turn (of the right sign for
  turns). A tracker of known-rate modes flags a turn when its most probable mode is one
  (``rule = "mode"``); any other (an estimated-rate mode, a single filter) when its turn
  rate estimate Ω̂ exceeds :data:`FLAG_DEG_S` (``rule = "omega"``).

All times s, distances m, rates as named.
"""

from __future__ import annotations

import math

import numpy as np

from airspace_sim.avoidance.cpa import cpa_min_ratio
from airspace_sim.recorded.flights import FOOT_M, Timeline
from airspace_sim.world.bodies import LOS

#: m: bin edges of the track position error histogram (0.2 % wide, 1 m to 10 000 km)
ERROR_BINS_M = np.geomspace(1.0, 1e7, 8061)
TURNING_DEG_S = 1.0  #: recorded |ω| at or above this is a turn, deg/s
STRAIGHT_DEG_S = 0.25  #: recorded |ω| at or below this is straight flight, deg/s
FLAG_DEG_S = 0.5  #: rule "omega": |Ω̂| at or above this flags a turn, deg/s


class _Episodes:
    """Start and end times (s) of the episodes of each pair key (a set that changes)."""

    def __init__(self):
        self.current = np.zeros(0, dtype=np.int64)
        self.spans: dict[int, list[list[float]]] = {}
        self.steps = 0

    def update(self, keys: np.ndarray, t: float) -> None:
        keys = np.unique(keys)
        for k in np.setdiff1d(keys, self.current):
            self.spans.setdefault(int(k), []).append([t, math.nan])
        for k in np.setdiff1d(self.current, keys):
            self.spans[int(k)][-1][1] = t
        self.current = keys
        self.steps += keys.size

    def close(self, t: float) -> None:
        for k in self.current:
            self.spans[int(k)][-1][1] = t

    @property
    def count(self) -> int:
        return sum(len(v) for v in self.spans.values())


class ReplayStats:
    """Accumulate a replay's measurements (module docstring); call :meth:`observe` after
    the world is built and after every step, then :meth:`report`.

    world : the World; vertical_ft : vertical separation standard for the 3-D losses, ft.
    """

    def __init__(self, world, vertical_ft: float = 1000.0):
        self.world = w = world
        self.n = w.n
        self.real = np.asarray(w.moved, dtype=bool)
        self.r_safe = float(w.r_safe)
        self.lookahead_s = float(w.lookahead)
        self.confirm_steps = int(w.policy.confirm_steps)
        self.vertical_m = float(vertical_ft) * FOOT_M
        self._members = np.flatnonzero(self.real)
        recs = [w.specs[i].recording for i in self._members]
        self._timeline = (
            Timeline([r.flight for r in recs], [r.offset_s for r in recs]) if recs else None
        )
        preset = w.tracker_preset.filter_model()
        self.mode_rates = np.asarray(preset.turn_rates, dtype=float)
        known = preset.pin_turn_rate and not preset.estimated().any()
        self.rule = "mode" if known and w.tracks.n_modes == preset.n_modes > 1 else "omega"
        self.los = _Episodes()
        self.los3d = _Episodes()
        self.alerts = _Episodes()
        self.ever = np.zeros(self.n, dtype=bool)
        self.max_present = 0
        self.sq_pos = self.sq_vel = self.sq_rate = 0.0
        self.track_steps = self.rate_steps = 0
        self.err_hist = np.zeros(ERROR_BINS_M.size + 1, dtype=np.int64)  # + under/overflow
        self.turning = self.turning_flagged = self.straight = self.straight_flagged = 0
        self.dt = float(w.dt)

    # ----------------------------------------------------------------- per step
    def observe(self) -> None:
        """Record the world as it is now (after construction or a step)."""
        w = self.world
        t = float(w.time)
        # recorded turn rate and altitude of every aircraft now (NaN: not recorded)
        self._rate = np.full(self.n, np.nan)
        self._alt = np.full(self.n, np.nan)
        if self._timeline is not None:
            self._rate[self._members] = self._timeline.linear(t, "turn_rate")
            self._alt[self._members] = self._timeline.linear(t, "altitude_m")
        real_now = self.real & w.active
        self.ever |= real_now
        self.max_present = max(self.max_present, int(real_now.sum()))
        # losses of separation between real aircraft
        n = max(self.n, 1)
        keys = w.airspace.pairs[LOS]
        i, j = keys // n, keys % n
        both = self.real[i] & self.real[j]
        keys, i, j = keys[both], i[both], j[both]
        self.los.update(keys, t)
        if keys.size:
            dz = np.abs(self._alt[i] - self._alt[j])
            self.los3d.update(keys[~(dz >= self.vertical_m)], t)  # unknown altitude: a loss
        else:
            self.los3d.update(keys, t)
        # tracks of real intruders by real ownships, confirmed
        view = w.tracks.view()
        ok = (
            (view.age >= self.confirm_steps)
            & self.real[view.intruder]
            & w.active[view.intruder]
            & w.active[view.owner]
        )
        own, intr, x = view.owner[ok], view.intruder[ok], view.x[ok]
        mu = view.mu[ok]
        if own.size:
            self._alerts(own, intr, x, t)
            self._tracking(intr, x, mu, t)
        else:
            self.alerts.update(np.zeros(0, np.int64), t)

    def _alerts(self, own, intr, x, t) -> None:
        w = self.world
        real_own = self.real[own]
        vo = w.velocities[own]
        rp = np.stack([x[:, 0], x[:, 2]], axis=1) - w.positions[own]
        rv = np.stack([x[:, 1], x[:, 3]], axis=1) - vo
        P = own.size
        ratio = cpa_min_ratio(
            vo,
            rp[:, None, :],
            rv[:, None, :],
            np.ones((P, 1), bool),
            np.zeros((P, 1)),
            self.r_safe,
            self.lookahead_s,
        )[:, 0]
        hit = (ratio < 1.0) & real_own
        a, b = own[hit], intr[hit]
        self.alerts.update(np.minimum(a, b) * max(self.n, 1) + np.maximum(a, b), t)

    def _tracking(self, intr, x, mu, t) -> None:
        w = self.world
        e = np.stack([x[:, 0], x[:, 2]], axis=1) - w.positions[intr]
        ev = np.stack([x[:, 1], x[:, 3]], axis=1) - w.velocities[intr]
        self.sq_pos += float(np.einsum("ij,ij->", e, e))
        self.err_hist += np.bincount(
            np.searchsorted(ERROR_BINS_M, np.hypot(e[:, 0], e[:, 1])),
            minlength=self.err_hist.size,
        )
        self.sq_vel += float(np.einsum("ij,ij->", ev, ev))
        self.track_steps += intr.size
        omega = self._rate[intr]
        known = np.isfinite(omega)
        self.sq_rate += float(np.sum((x[known, 4] - omega[known]) ** 2))
        self.rate_steps += int(known.sum())
        if self.rule == "mode" and np.isfinite(mu).all():
            flag = np.sign(self.mode_rates[np.argmax(mu, axis=1)])
        else:
            flag = np.where(np.abs(x[:, 4]) >= math.radians(FLAG_DEG_S), np.sign(x[:, 4]), 0.0)
        turning = known & (np.abs(omega) >= math.radians(TURNING_DEG_S))
        straight = known & (np.abs(omega) <= math.radians(STRAIGHT_DEG_S))
        self.turning += int(turning.sum())
        self.turning_flagged += int((turning & (flag == np.sign(omega))).sum())
        self.straight += int(straight.sum())
        self.straight_flagged += int((straight & (flag != 0)).sum())

    # ------------------------------------------------------------------ report
    def _judge(self) -> dict:
        """Alert episodes against loss episodes, per pair (module docstring)."""
        T = self.lookahead_s
        alerted = missed = true_alerts = false_alerts = 0
        leads = []
        for key, losses in self.los.spans.items():
            episodes = self.alerts.spans.get(key, [])
            for s, _ in losses:
                before = [a0 for a0, a1 in episodes if a0 <= s and a1 >= s - T]
                if before:
                    alerted += 1
                    leads.append(s - min(before))
                else:
                    missed += 1
        for key, episodes in self.alerts.spans.items():
            losses = self.los.spans.get(key, [])
            for a0, a1 in episodes:
                if any(a0 <= s <= a1 + T for s, _ in losses):
                    true_alerts += 1
                else:
                    false_alerts += 1
        return {
            "los_alerted": alerted,
            "los_missed": missed,
            "alerts_true": true_alerts,
            "alerts_false": false_alerts,
            "lead_time_median_s": float(np.median(leads)) if leads else math.nan,
        }

    def _error_quantile(self, q: float) -> float:
        """Quantile ``q`` of the track position errors (m, to the histogram's 0.2 %)."""
        total = int(self.err_hist.sum())
        if not total:
            return math.nan
        k = int(np.searchsorted(np.cumsum(self.err_hist), q * total))
        return float(ERROR_BINS_M[min(k, ERROR_BINS_M.size - 1)])

    def report(self) -> dict:
        """The measurements as a flat-ish dict (JSON-ready apart from NaN)."""
        t = float(self.world.time)
        for e in (self.los, self.los3d, self.alerts):
            e.close(t)
        dt = self.dt
        rms = lambda s, n: math.sqrt(s / n) if n else math.nan  # noqa: E731
        frac = lambda a, b: a / b if b else math.nan  # noqa: E731
        return {
            "real_aircraft": int(self.ever.sum()),
            "max_simultaneous": self.max_present,
            "r_safe_m": self.r_safe,
            "vertical_ft": self.vertical_m / FOOT_M,
            "lookahead_s": self.lookahead_s,
            "los_pairs": len(self.los.spans),
            "los_episodes": self.los.count,
            "los_s": self.los.steps * dt,
            "los3d_pairs": len(self.los3d.spans),
            "los3d_episodes": self.los3d.count,
            "alert_pairs": len(self.alerts.spans),
            "alert_episodes": self.alerts.count,
            **self._judge(),
            "track_s": self.track_steps * dt,
            "track_position_rmse_m": rms(self.sq_pos, self.track_steps),
            "track_position_median_m": self._error_quantile(0.5),
            "track_position_p95_m": self._error_quantile(0.95),
            "track_velocity_rmse_ms": rms(self.sq_vel, self.track_steps),
            "track_turn_rate_rmse_deg_s": math.degrees(rms(self.sq_rate, self.rate_steps)),
            "mode_rule": self.rule,
            "turning_s": self.turning * dt,
            "turning_flagged": frac(self.turning_flagged, self.turning),
            "straight_s": self.straight * dt,
            "straight_flagged": frac(self.straight_flagged, self.straight),
        }
