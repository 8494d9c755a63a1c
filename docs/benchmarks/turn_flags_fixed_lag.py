"""Turn flags with a delay: the IMM's fixed-lag smoother over recorded flights.

    python docs/benchmarks/turn_flags_fixed_lag.py DIR --split train|test --period 4|1 \\
        [--preset imm-ct] [--lags 0,5,10,15,20,30]

DIR holds the traffic 2.8.1 ``calibration/*.json.gz`` samples or is one collection file
(never committed), split as ``tune_tracker.py`` splits them; measurements as
``evaluation.evaluate`` draws them (seed 0). A causal tracker confirms a turn only once it has
bent the track beyond the noise; a tracker that may report ``lag`` seconds late uses the
measurements up to then (``tracking.smooth_two_filter(..., lag=steps)``; before 2026-12-08
``tracking.smooth(..., lag=steps)``, expectation correction). Printed per lag: turning
seconds flagged with the right sign / with the wrong sign / straight seconds flagged (the
flag rule and the seconds of ``evaluate``), and the position RMSE. Lag 0 is the filter,
"inf" the fixed-interval (two-filter) smoother. Each lag of L steps costs L backward passes. First, how
long the turns are: for every turning second (|ω| ≥ 1 °/s), the duration and heading change
of the turn it belongs to (its run of same-sign |ω| ≥ 0.5 °/s), percentiles.
"""

from __future__ import annotations

import math
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from tune_tracker import measured, split_arguments  # noqa: E402

from airspace_sim.dynamics import models  # noqa: E402
from airspace_sim.tracking import evaluation as E  # noqa: E402


def turn_extents(truths, period):
    """For every turning step of ``truths``: (duration s, |heading change| deg) of its turn,
    the run of same-sign |ω| ≥ :data:`~airspace_sim.tracking.evaluation.ONSET_DEG_S` around it."""
    out = []
    for tr in truths:
        w = np.degrees(tr.state[:, 4])
        side = np.where(np.abs(w) >= E.ONSET_DEG_S, np.sign(w), 0.0)
        edges = np.flatnonzero(np.diff(side) != 0) + 1
        for run, ws in zip(np.split(side, edges), np.split(w, edges)):
            if run[0] != 0:
                n_turning = int(np.count_nonzero(np.abs(ws) >= E.TURNING_DEG_S))
                out += [(ws.size * period, abs(ws.sum()) * period)] * n_turning
    return np.array(out).reshape(-1, 2)


def flags_at_lag(p, X, Z, period, lag_steps):
    """(T, F, 4) estimates and the (T, F) left / right turn probabilities of the IMM of the
    tracker model ``p`` smoothed with ``lag_steps`` of look-ahead (None: the whole flight)."""
    T, F, _ = X.shape
    R = models.measurement_noise(p.measurement_sigma)
    x0, P0 = E._initial_state(Z, period, R, p.n_state)
    known = np.where(p.estimated(), np.nan, np.asarray(p.turn_rates))
    turning = np.asarray(p.turning_modes(), dtype=bool)
    rate = math.radians(E.RATE_FLAG_DEG_S)
    lengths = np.isfinite(Z[..., 0]).sum(axis=0)
    est = np.full((T, F, 4), np.nan)
    left, right = np.full((T, F), np.nan), np.full((T, F), np.nan)
    runs = E._smoothed_runs(Z, x0, P0, p.mu0(), p.imm_arguments(), lengths, period, lag_steps)
    for b, L, sm in runs:
        est[2:L, b] = sm.x[..., :4]
        left[2:L, b], right[2:L, b] = E.turn_probabilities(
            sm.mu, sm.x_modes, sm.P_modes, known, turning, rate
        )
    return est, left, right


def main(argv=None) -> None:
    ap = split_arguments(__doc__)
    ap.add_argument("--preset", default="imm-ct")
    ap.add_argument("--lags", default="0,5,10,15,20,30", help="seconds, comma-separated")
    a = ap.parse_args(argv)
    truths, p, X, Z, ev = measured(a)
    sigma = p.measurement_sigma
    ext = turn_extents(truths, a.period)
    q = (10, 25, 50, 75, 90)
    print(f"turning seconds' turns, percentiles {q}: duration s "
          f"{np.percentile(ext[:, 0], q).round(0).tolist()}, heading change deg "
          f"{np.percentile(ext[:, 1], q).round(0).tolist()}")  # fmt: skip
    print(f"{a.split} {a.period:g} s, sigma {sigma:g} m, {a.preset}: lag s: turning right sign"
          " / wrong sign / straight flagged; position RMSE", flush=True)  # fmt: skip
    for lag_s in [float(v) for v in a.lags.split(",")] + [math.inf]:
        t0 = time.process_time()
        steps = None if math.isinf(lag_s) else int(round(lag_s / a.period))
        est, left, right = flags_at_lag(p, X, Z, a.period, steps)
        f = E._flags(left, right, X, ev)
        rmse = E._rmse((est - X[..., :4])[ev][:, [0, 2]])
        print(f"  lag {lag_s:g} s: {100 * f['turning_flagged']:5.1f}% / "
              f"{100 * f['turning_flagged_wrong_sign']:4.1f}% / {100 * f['straight_flagged']:5.2f}%;"
              f" {rmse:6.1f} m  ({time.process_time() - t0:.0f} s cpu)", flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
