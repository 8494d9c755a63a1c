"""Where the running IMM misses turns: its state on the turning seconds it flags and misses.

    python docs/benchmarks/turn_flag_misses.py DIR --split train|test --period 1|4 \\
        [--preset imm-ct]

DIR holds the traffic 2.8.1 ``calibration/*.json.gz`` samples or is one collection file (never
committed), split and measured as ``tune_tracker.py`` does (seed 0), run by
``evaluation.evaluate_with_record`` (every flight recorded, no smoother). For the turning
seconds in each bin of time since the turn began (``evaluation.ONSET_BINS_S``), those
flagged with the right side and those missed: how many, the IMM's mean mode probabilities,
the median of the truth's |ω| and of the IMM's combined Ω̂ signed by the truth's side
(°/s; 0 would be "no turn seen"), and how often the truth's rate changed by over 1 °/s in
the last 15 s (a turn whose rate moves: the filter's Ω̂ lags it).
"""

from __future__ import annotations

import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from tune_tracker import SIGMA_BY_PERIOD, preset, split, split_arguments, truths_of  # noqa: E402

from airspace_sim.tracking import evaluation as E  # noqa: E402

#: Look-back (s) for the change of the truth's rate.
RATE_CHANGE_WINDOW_S = 15.0


def rate_changed(omega, period_s: float, window_s: float = RATE_CHANGE_WINDOW_S):
    """(T, F) bool: the truth's ω (T, F) rad/s spanned over 1 °/s (max − min) over the last
    ``window_s`` seconds, this step included."""
    w = np.degrees(omega)
    n = max(int(round(window_s / period_s)), 1)
    hi, lo = w.copy(), w.copy()
    for s in range(1, n + 1):
        prev = np.full_like(w, np.nan)
        prev[s:] = w[:-s]
        hi, lo = np.fmax(hi, prev), np.fmin(lo, prev)
    return hi - lo > 1.0


def rows(record, period_s: float) -> list[str]:
    """One line per onset bin and outcome (flagged / missed) of ``record``
    (``evaluation.Record``)."""
    X, on = record.truth, record.evaluated
    w = X[..., 4]
    turning = on & (np.abs(np.degrees(w)) >= E.TURNING_DEG_S)
    right = E._right_flags(record.p_left, record.p_right, X)
    since = E.since_onset(w, period_s)
    moved = rate_changed(w, period_s)
    out = []
    for lo, hi in zip(E.ONSET_BINS_S[:-1], E.ONSET_BINS_S[1:]):
        b = turning & (since >= lo) & (since < hi)
        for what, sel in (("flagged", b & right), ("missed", b & ~right)):
            if not sel.any():
                continue
            mu = ", ".join(
                f"{name} {m:.2f}" for name, m in zip(record.mode_names, record.mu[sel].mean(axis=0))
            )
            seen = np.degrees(record.imm[..., 4] * np.sign(w))[sel]
            out.append(
                f"{lo:g}-{hi:g} s {what}: {sel.sum() / max(turning.sum(), 1):.1%} of the turning "
                f"steps; mu {mu}; |omega| {np.median(np.abs(np.degrees(w[sel]))):.2f} deg/s, "
                f"signed Omega-hat {np.median(seen):.2f} deg/s; rate moved > 1 deg/s in "
                f"{RATE_CHANGE_WINDOW_S:g} s: {moved[sel].mean():.0%}"
            )
    return out


def main(argv=None) -> None:
    ap = split_arguments(__doc__)
    ap.add_argument("--preset", default="imm-ct")
    a = ap.parse_args(argv)
    truths = truths_of(split(a.directory, a.split), a.period)
    sigma = SIGMA_BY_PERIOD[a.period]
    ev, record = E.evaluate_with_record(
        truths, preset(a.preset), sigma, a.period, range(len(truths)), smoother=False
    )
    print(f"{a.split} {a.period:g}s {a.preset}: turning flagged {ev.turning_flagged:.1%}, "
          f"straight {ev.straight_flagged:.2%}")  # fmt: skip
    for line in rows(record, a.period):
        print("  " + line)


if __name__ == "__main__":
    main()
