"""How far from the floor: Kalman filters told the truth's motion, against the IMM / CV ratio.

    python docs/benchmarks/tracker_floor.py DIR --split train|test --period 4|1 [--preset imm-ct]

DIR holds the traffic 2.8.1 ``calibration/*.json.gz`` samples (never committed), split as
``tune_tracker.py`` splits them. On the same measurements as ``evaluate`` (seed 0), each
filter's σ_a is the best of a grid on the split it runs on (optimistic for the oracles):

- CV: the best-tuned constant-velocity filter (the denominator of every ratio);
- rate: told the truth's turn rate at every step, one σ_a;
- rate + regime: also told straight or not (σ_a quiet on straight seconds, another elsewhere);
- rate + along-track: also told the truth's along-track acceleration (a known input);
- rate + along-track, 30 / 60 s average: told only that acceleration's moving average
  (its slow part: what an along-track acceleration state that changes slowly, as in the
  ``imm-cta`` preset, could hope to follow).

An IMM over CV and coordinated-turn modes has to infer what the first two are told: their
ratios are practical floors of its ratio (``docs/tracking.md``). With ``--preset`` the
preset's own ratio is printed too (``evaluation.evaluate``). Process CPU time is printed.
"""

from __future__ import annotations

import itertools
import time

from tune_tracker import SIGMA_BY_PERIOD, preset, split, split_arguments, truths_of

from airspace_sim.tracking.evaluation import evaluate, known_motion_rmse

GRIDS = {
    "CV": [dict(sigma_accel=s, turn_rate=False) for s in (1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 8.0)],
    "rate": [dict(sigma_accel=s) for s in (0.5, 0.7, 1.0, 1.5, 2.0, 3.0)],
    "rate + regime": [
        dict(sigma_accel=p) for p in itertools.product((0.1, 0.2, 0.3, 0.5), (1.0, 1.5, 2.0, 3.0))
    ],
    "rate + along-track": [dict(sigma_accel=s, along_track=True) for s in (0.2, 0.3, 0.5, 1.0)],
    "rate + along-track, 30 s average": [
        dict(sigma_accel=s, along_track=True, along_track_window_s=30.0)
        for s in (0.3, 0.5, 0.7, 1.0, 1.5, 2.0, 3.0)
    ],
    "rate + along-track, 60 s average": [
        dict(sigma_accel=s, along_track=True, along_track_window_s=60.0)
        for s in (0.3, 0.5, 0.7, 1.0, 1.5, 2.0, 3.0)
    ],
}


def main(argv=None) -> None:
    ap = split_arguments(__doc__)
    ap.add_argument("--preset", action="append", default=[])
    a = ap.parse_args(argv)
    sigma = SIGMA_BY_PERIOD[a.period]
    truths = truths_of(split(a.directory, a.split), a.period)
    t0 = time.process_time()
    cv = None
    for name, grid in GRIDS.items():
        scores = [(known_motion_rmse(truths, sigma, a.period, **kw), kw) for kw in grid]
        rmse, kw = min(scores, key=lambda s: s[0])
        cv = rmse if cv is None else cv
        print(f"{a.split} {a.period:g}s {name}: {rmse:.1f} m (sigma_a {kw['sigma_accel']}) "
              f"ratio {rmse / cv:.3f}", flush=True)  # fmt: skip
    for name in a.preset:
        ev = evaluate(truths, preset(name), sigma, a.period, smoother=False)
        print(f"{a.split} {a.period:g}s preset {name}: IMM {ev.pos_imm:.1f} m, its CV "
              f"{ev.pos_cv:.1f} m, ratio {ev.pos_imm / ev.pos_cv:.3f}", flush=True)  # fmt: skip
    print(f"cpu {time.process_time() - t0:.1f} s")


if __name__ == "__main__":
    main()
