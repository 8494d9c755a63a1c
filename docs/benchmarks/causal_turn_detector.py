"""How well does a simple causal turn detector do? Local polynomial fits of the last W seconds.

    python docs/benchmarks/causal_turn_detector.py DIR --split train|test --period 4|1 \\
        [--windows 8,12,16,20,24,28,32,40,48,64] [--orders 2,3]

DIR holds the traffic 2.8.1 ``calibration/*.json.gz`` samples or is one collection file (never
committed), split and measured as ``tune_tracker.py`` does (seed 0). At every step the
measured positions of the last W seconds are fitted by a polynomial of the given order
(Savitzky–Golay coefficients evaluated at the window's end: a causal estimate), whose first
and second derivatives give the turn rate ``ω = (vx ay − vy ax) / |v|²``; a turn is flagged
when |ω| is over a threshold, and the threshold is the one (0.5–6 °/s by 0.25) that flags the
most turning seconds with the right sign at ≤ 2% of the straight seconds (the flag target),
chosen on the split itself (optimistic). The IMM's flags on the same seconds are
``evaluate-tracker``'s; this says whether a detector that needs no model does better.
"""

from __future__ import annotations

import math
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from tune_tracker import measured, split_arguments  # noqa: E402

from airspace_sim.tracking import evaluation as E  # noqa: E402

#: Candidate thresholds on |ω| (deg/s).
THRESHOLDS_DEG_S = np.arange(0.5, 6.01, 0.25)
#: The flag target's share of straight seconds.
STRAIGHT_BUDGET = 0.02


def causal_derivative(Z, window: int, order: int, deriv: int, period: float):
    """(T, F, 2): the ``deriv``-th derivative at each step of the polynomial fitted to the
    last ``window`` measurements Z (T, F, 2) (NaN for the first window − 1 steps)."""
    from scipy.signal import lfilter, savgol_coeffs

    c = savgol_coeffs(window, order, deriv=deriv, pos=window - 1, delta=period, use="dot")
    out = lfilter(c[::-1], 1.0, Z, axis=0)  # c[-1] weighs the newest measurement
    out[: window - 1] = np.nan
    return out


def best_flags(omega, X, ev):
    """(threshold deg/s, turning flagged, straight flagged) of the best threshold at the
    straight budget, or None."""
    best = None
    for thr in THRESHOLDS_DEG_S:
        t = math.radians(thr)
        f = E._flags(np.where(omega >= t, 1.0, 0.0), np.where(omega <= -t, 1.0, 0.0), X, ev)
        if f["straight_flagged"] <= STRAIGHT_BUDGET and (
            best is None or f["turning_flagged"] > best[1]
        ):
            best = (float(thr), f["turning_flagged"], f["straight_flagged"])
    return best


def main(argv=None) -> None:
    ap = split_arguments(__doc__)
    ap.add_argument("--preset", default="imm-ct", help="(for the measurements' sigma only)")
    ap.add_argument(
        "--windows", default="8,12,16,20,24,28,32,40,48,64", help="seconds, comma-separated"
    )
    ap.add_argument("--orders", default="2,3", help="polynomial orders, comma-separated")
    a = ap.parse_args(argv)
    _, p, X, Z, ev = measured(a)
    print(f"{a.split} {a.period:g} s, sigma {p.measurement_sigma:g} m: best threshold at "
          f"<= {100 * STRAIGHT_BUDGET:g}% of straight seconds")  # fmt: skip
    for w_s in (float(v) for v in a.windows.split(",")):
        window = int(round(w_s / a.period))
        for order in (int(v) for v in a.orders.split(",")):
            if window < order + 2:
                continue
            v = causal_derivative(Z, window, order, 1, a.period)
            acc = causal_derivative(Z, window, order, 2, a.period)
            speed2 = np.maximum(np.sum(v**2, axis=-1), 1.0)
            omega = np.nan_to_num((v[..., 0] * acc[..., 1] - v[..., 1] * acc[..., 0]) / speed2)
            best = best_flags(omega, X, ev)
            res = "none" if best is None else (
                f"|omega| >= {best[0]:g} deg/s: {100 * best[1]:.1f}% / {100 * best[2]:.2f}%")  # fmt: skip
            print(f"  window {w_s:g} s, order {order}: {res}", flush=True)


if __name__ == "__main__":
    main()
