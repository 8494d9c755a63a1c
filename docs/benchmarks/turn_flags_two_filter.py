"""Turn flags after the fact: the IMM run forward and backward in time over recorded flights.

    python docs/benchmarks/turn_flags_two_filter.py DIR --split train|test --period 4|1 \\
        [--preset imm-ct]

DIR holds the traffic 2.8.1 ``calibration/*.json.gz`` samples (never committed), split as
``tune_tracker.py`` splits them; measurements as ``evaluation.evaluate`` draws them (seed 0).
A causal tracker confirms a turn only once it has bent the track beyond the noise, so the
first ~15 s of every turn go unflagged (docs/tracking.md, "The turn flags"). Offline, the
same IMM can also run over each flight reversed in time (a left turn flown backwards is a
right turn), whose flags lag at the other end of each turn. Printed, for the forward
filter, the backward one and their combinations (turning seconds flagged with the right sign
/ with the wrong sign / straight seconds flagged, the seconds ``evaluate`` counts):

- OR / AND of the two filters' flags (each: the probability of a turn at ≥ 0.5 °/s > 1/2);
- two-filter: p_f·p_b/π against (1 − p_f)(1 − p_b)/(1 − π), the mode-probability form of
  two-filter smoothing, at a prior π and a threshold (exact for a stationary reversible chain
  when the backward filter stops before the current measurement and is predicted one step,
  tests/test_turn_flags_two_filter.py; here both filters include it, so it counts twice);
- mean: (p_f + p_b)/2 above a threshold.

An experiment for docs/tracking.md, not a tracker: the thresholds and priors are chosen
on the training half. It combines the two filters' turn probabilities only; the two-filter
IMM smoother, which fuses their mode-conditioned estimates pair by pair, is
``airspace_sim.tracking.smooth_two_filter`` (docs/tracking.md, "Two filters").
"""

from __future__ import annotations

import math
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from tune_tracker import measured, split_arguments  # noqa: E402

from airspace_sim.dynamics import models  # noqa: E402
from airspace_sim.tracking import IMM  # noqa: E402
from airspace_sim.tracking import evaluation as E  # noqa: E402


def turn_probabilities(p, Z, period):
    """(T, F), (T, F): the IMM's probability of a left and of a right turn at each step of
    the measurements ``Z`` (T, F, 2) m, as ``evaluation.evaluate`` computes its flags."""
    T, F, _ = Z.shape
    R = models.measurement_noise(p.measurement_sigma)
    x0, P0 = E._initial_state(Z, period, R, p.n_state)
    imm = IMM(**p.imm_arguments(), x0=x0, P0=P0, mu0=p.mu0(), gate_probability=1.0)
    turning = np.asarray(p.turning_modes(), dtype=bool)
    known = np.where(p.estimated(), np.nan, np.asarray(p.turn_rates))
    rate = math.radians(E.RATE_FLAG_DEG_S)
    left, right = np.full((T, F), np.nan), np.full((T, F), np.nan)
    for k in range(2, T):
        imm.step(Z[k])
        left[k], right[k] = E.turn_probabilities(
            imm.mu, imm.x_modes, imm.P_modes, known, turning, rate
        )
    return left, right


def two_filter(forward, backward, prior):
    """The probability of the mode given both filters' evidence: ``forward``, ``backward``
    arrays of its probability by each filter, ``prior`` its stationary probability."""
    yes = forward * backward / prior
    return yes / np.maximum(yes + (1 - forward) * (1 - backward) / (1 - prior), 1e-300)


def reversed_in_time(a, n):
    """``a`` (T, F, ...) with each flight's first ``n`` (F,) steps reversed (NaN after), and
    the (T, F) index that maps a step back."""
    T = a.shape[0]
    k = np.arange(T)[:, None]
    index = np.where(k < n[None, :], n[None, :] - 1 - k, k)
    out = a[index, np.arange(a.shape[1])[None, :]]
    out[k >= n[None, :]] = np.nan
    return out, index


def main(argv=None) -> None:
    ap = split_arguments(__doc__)
    ap.add_argument("--preset", default="imm-ct")
    a = ap.parse_args(argv)
    _, p, X, Z, ev = measured(a)
    sigma = p.measurement_sigma
    left_f, right_f = turn_probabilities(p, Z, a.period)
    n = np.isfinite(Z[..., 0]).sum(axis=0)
    Zr, index = reversed_in_time(Z, n)
    left_r, right_r = turn_probabilities(p, Zr, a.period)
    cols = np.arange(X.shape[1])[None, :]
    gone = np.arange(X.shape[0])[:, None] >= n[None, :]
    left_b, right_b = np.full_like(left_f, np.nan), np.full_like(left_f, np.nan)
    left_b[index, cols], right_b[index, cols] = right_r, left_r  # backwards, turns swap sides
    left_b[gone] = right_b[gone] = np.nan

    omega = np.degrees(X[..., 4])
    turning = ev & (np.abs(omega) >= E.TURNING_DEG_S)
    straight = ev & (np.abs(omega) < E.STRAIGHT_DEG_S)
    print(f"{a.split} half, {a.period:g} s, sigma {sigma:g} m, {a.preset}: "
          f"{turning.sum() * a.period:.0f} turning s, {straight.sum() * a.period:.0f} straight s")  # fmt: skip

    def score(name, lf, rf):
        flagged = lf | rf
        right = (lf & (X[..., 4] > 0)) | (rf & (X[..., 4] < 0))
        print(f"  {name:30s} {100 * right[turning].mean():5.1f}% / "
              f"{100 * (flagged & ~right)[turning].mean():4.1f}% / "
              f"{100 * flagged[straight].mean():5.2f}%")  # fmt: skip

    lf, rf = np.nan_to_num(left_f), np.nan_to_num(right_f)
    lb, rb = np.nan_to_num(left_b), np.nan_to_num(right_b)
    score("forward (the tracker)", lf > 0.5, rf > 0.5)
    score("backward", lb > 0.5, rb > 0.5)
    score("OR", (lf > 0.5) | (lb > 0.5), (rf > 0.5) | (rb > 0.5))
    score("AND", (lf > 0.5) & (lb > 0.5), (rf > 0.5) & (rb > 0.5))
    for prior in (0.1, 0.2, 0.3):
        for threshold in (0.5, 0.7):
            score(f"two-filter pi {prior} > {threshold}",
                  two_filter(lf, lb, prior) > threshold,
                  two_filter(rf, rb, prior) > threshold)  # fmt: skip
    for threshold in (0.35, 0.4, 0.45):
        score(f"mean > {threshold}", (lf + lb) / 2 > threshold, (rf + rb) / 2 > threshold)


if __name__ == "__main__":
    main()
