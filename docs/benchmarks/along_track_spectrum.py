"""What the truth's along-track acceleration is made of: RMS, autocorrelation, spectrum.

    python docs/benchmarks/along_track_spectrum.py DIR [--split train|test]

DIR holds the traffic 2.8.1 ``calibration/*.json.gz`` samples (never committed), split as
``tune_tracker.py`` splits them; the truths on the 1 s grid (``evaluation.resample``). The
along-track acceleration is the derivative of the truth's speed. Printed: its RMS, its
autocorrelation at a few lags, the RMS left after centred moving averages (the slow part),
and the share of its power (Welch, 256 s segments) by period: what a state that changes
slowly (``presets.imm_cta``) could follow (``docs/tracking.md``); and the band edge of the
truth's own smoothing, for comparison.
"""

from __future__ import annotations

import numpy as np
from scipy.signal import freqz, savgol_coeffs, welch
from tune_tracker import split, split_arguments, truths_of

from airspace_sim.tracking.evaluation import SMOOTH_S

LAGS_S = (2, 5, 10, 20, 30)
WINDOWS_S = (11, 31, 61)
#: period bands (s) of the power shares: (shortest, longest)
BANDS_S = ((60, np.inf), (30, 60), (15, 30), (0, 15))


def main(argv=None) -> None:
    ap = split_arguments(__doc__, period=False)
    a = ap.parse_args(argv)
    accels = []
    for tr in truths_of(split(a.directory, a.split), 1.0):
        speed = np.hypot(tr.state[:, 1], tr.state[:, 3])
        accels.append(np.gradient(speed, 1.0))
    n = sum(v.size for v in accels)
    c0 = sum(np.sum(v * v) for v in accels)
    acf = [sum(np.sum(v[:-lag] * v[lag:]) for v in accels) / c0 for lag in LAGS_S]
    smooth = {
        w: np.sqrt(sum(np.sum(np.convolve(v, np.ones(w) / w, "same") ** 2) for v in accels) / n)
        for w in WINDOWS_S
    }
    power = 0.0
    for v in accels:
        f, p = welch(v, fs=1.0, nperseg=min(256, v.size))
        power = power + p * v.size
    period = np.divide(1.0, f, out=np.full_like(f, np.inf), where=f > 0)
    print(
        f"{a.split}: {len(accels)} segments, along-track acceleration RMS {np.sqrt(c0 / n):.2f} m/s²"
    )
    print("  autocorrelation " + ", ".join(f"{lag} s {r:+.2f}" for lag, r in zip(LAGS_S, acf)))
    print("  RMS after a moving average " + ", ".join(f"{w} s {r:.2f}" for w, r in smooth.items()))
    shares = [power[(period >= lo) & (period < hi)].sum() / power.sum() for lo, hi in BANDS_S]
    # the truth's smoothing (cubic Savitzky-Golay over SMOOTH_S): where it cuts, and where
    # its second-derivative filter (the acceleration) has its largest gain
    win = int(SMOOTH_S) | 1
    fr, h0 = freqz(savgol_coeffs(win, 3), worN=4096, fs=1.0)
    _, h2 = freqz(savgol_coeffs(win, 3, deriv=2), worN=4096, fs=1.0)
    cut = 1.0 / fr[np.argmax(np.abs(h0) < 2**-0.5)]
    print(
        f"  the truth's {win} s smoothing: -3 dB at a {cut:.0f} s period, its acceleration "
        f"filter's gain largest at {1.0 / fr[np.argmax(np.abs(h2))]:.0f} s"
    )
    print(
        "  power by period "
        + ", ".join(f"{lo:g}-{hi:g} s {100 * s:.0f}%" for (lo, hi), s in zip(BANDS_S, shares))
        + f"; peak at {period[np.argmax(power)]:.0f} s"
    )


if __name__ == "__main__":
    main()
