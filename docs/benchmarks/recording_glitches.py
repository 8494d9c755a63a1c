"""Positions that are not reports (glitches, interpolations), and what they did to the truth.

    python docs/benchmarks/recording_glitches.py FILE... [--min-m 100]

FILE: recorded trajectories (the traffic 2.8.1 samples, never committed). Per file:

- positions as recorded, and how many ``glitches.despike`` drops (over ``glitches.SPIKE_M``
  across the track from their neighbours' path; ``recorded.read`` drops them by default);
- the local peaks of ``glitches.track_residual`` (the largest within two positions either
  side) over ``--min-m``, counted by size;
- positions lying on the straight line between their neighbours (to
  ``glitches.INTERPOLATED_M``), and how many of them ``glitches.reported`` leaves out of a
  truth;
- segment ends, the glitches dropped: how many truths made *without* the end cut
  (``evaluation.END_TRIM_S`` set to 0 here) turn at ≥ 1 °/s in their last 30 s, and, for
  those, the median change of the recorded track angle and of the truth's heading over the
  last 40 s (deg);
- with ``--track-rate``: how far the truth's turn rate is from the recorded track angle's (its
  derivative, averaged over 11 s), on the truth's turning seconds after the first minute:
  median and share under 0.5 °/s, for the truth as ``evaluation.resample`` makes it and for
  the polygon through every position (``resample(through_reports=False)``, the truth before
  2026-12-08).

docs/tracking.md, "Glitches and segment ends" and "Reports and interpolated positions",
quotes it.
"""

from __future__ import annotations

import argparse

import numpy as np

from airspace_sim.recorded import glitches, read
from airspace_sim.tracking import evaluation as E

#: Edges (m) of the residual-peak counts.
PEAK_BINS_M = (300.0, 500.0, 1000.0, 3000.0, np.inf)


def segments(t):
    """(start, stop) of the runs of ``t`` (K,) s between gaps over ``glitches.RUN_GAP_S``."""
    cuts = np.flatnonzero(np.diff(t) > glitches.RUN_GAP_S) + 1
    return list(zip(np.r_[0, cuts], np.r_[cuts, t.size]))


def residual_peaks(r):
    """The values of ``r`` (K,) that are the largest within two places either side."""
    v = np.nan_to_num(r)
    return v[glitches.local_peaks(r) & (v > 0)]


def end_bends(flights):
    """(count, median |recorded track change|, median |truth heading change|) over the
    truths made without the end cut that turn at ≥ 1 °/s in their last 30 s."""
    cut, E.END_TRIM_S = E.END_TRIM_S, 0.0
    try:
        rows = []
        for f in flights:
            speed = np.hypot(f.vx, f.vy)
            for tr in E.resample(f.id, f.t_s, f.x_m, f.y_m, 1.0,
                                 speed_mps=speed if np.all(np.isfinite(speed)) else None):  # fmt: skip
                t, w = tr.t_s, np.degrees(tr.state[:, 4])
                if not np.any(np.abs(w[t > t[-1] - 30.0]) >= 1.0):
                    continue
                sel = (f.t_s >= t[-1] - 40.0) & (f.t_s <= t[-1] + 1.0)
                track = np.unwrap(np.arctan2(f.vy[sel], f.vx[sel]))
                h = np.unwrap(np.arctan2(tr.state[:, 3], tr.state[:, 1]))[t >= t[-1] - 40.0]
                if track.size > 1:
                    rows.append((abs(track[-1] - track[0]), abs(h[-1] - h[0])))
    finally:
        E.END_TRIM_S = cut
    if not rows:
        return 0, float("nan"), float("nan")
    a = np.degrees(np.array(rows))
    return len(rows), float(np.median(a[:, 0])), float(np.median(a[:, 1]))


def track_rate_gaps(flights, through_reports: bool) -> np.ndarray:
    """|ω − recorded track rate| (deg/s) on the truths' turning seconds after the first
    minute (1 s truths)."""
    d = []
    for f in flights:
        heading = np.unwrap(np.arctan2(f.vy, f.vx))
        speed = np.hypot(f.vx, f.vy)
        for tr in E.resample(f.id, f.t_s, f.x_m, f.y_m, 1.0,
                             speed_mps=speed if np.all(np.isfinite(speed)) else None,
                             through_reports=through_reports):  # fmt: skip
            rate = np.gradient(np.interp(tr.t_s, f.t_s, heading), tr.t_s)
            rate = np.convolve(rate, np.ones(11) / 11, mode="same")
            w = tr.state[:, 4]
            turning = (np.abs(np.degrees(w)) >= E.TURNING_DEG_S) & (tr.t_s >= tr.t_s[0] + 60.0)
            d.append(np.degrees(np.abs(w - rate))[turning])
    d = np.concatenate(d) if d else np.zeros(0)
    return d[np.isfinite(d)]  # no recorded track: not compared


def agreement(d) -> str:
    """The median and the share under 0.5 deg/s of the gaps ``d``."""
    if not d.size:
        return "no turning second"
    return f"median {np.median(d):.2f} deg/s, under 0.5 deg/s {np.mean(d < 0.5):.1%}"


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("files", nargs="+")
    ap.add_argument("--min-m", type=float, default=100.0)
    ap.add_argument("--track-rate", action="store_true")
    a = ap.parse_args(argv)
    gaps = {True: [], False: []}
    for path in a.files:
        flights = list(read(path, glitch_m=None))
        n = dropped = on_line = left_out = 0
        peaks = []
        for f in flights:
            for lo, hi in segments(f.t_s):
                t, x, y = f.t_s[lo:hi], f.x_m[lo:hi], f.y_m[lo:hi]
                n += hi - lo
                dropped += hi - lo - glitches.despike(t, x, y).size
                peaks.append(residual_peaks(glitches.track_residual(t, x, y)))
                left_out += hi - lo - glitches.reported(t, x, y).size
                on_line += hi - lo - glitches.reported(t, x, y, max_gap_s=np.inf).size
        p = np.concatenate(peaks) if peaks else np.zeros(0)
        edges = (a.min_m,) + PEAK_BINS_M
        counts = ", ".join(
            f"{lo:g}-{hi:g} m: {int(np.count_nonzero((p >= lo) & (p < hi)))}"
            for lo, hi in zip(edges[:-1], edges[1:])
        )
        clean = read(path)
        bends, track, heading = end_bends(clean)
        print(f"{path}: {len(flights)} flights, {n} positions, {dropped} dropped; residual "
              f"peaks {counts}; on a line between their neighbours {on_line / max(n, 1):.1%}, "
              f"left out of the truth {left_out / max(n, 1):.1%}; ends turning >= 1 deg/s: "
              f"{bends} (recorded track change median {track:.1f} deg, truth heading "
              f"{heading:.1f} deg)")  # fmt: skip
        if a.track_rate:
            for through in (True, False):
                gaps[through].append(track_rate_gaps(clean, through))
                print(f"  truth {'as made' if through else 'polygon through every position'}: |omega - "
                      f"recorded track rate| in turning s {agreement(gaps[through][-1])}")  # fmt: skip
    if a.track_rate and len(a.files) > 1:
        for through in (True, False):
            print(f"all files, truth {'as made' if through else 'polygon through every position'}: "
                  f"{agreement(np.concatenate(gaps[through]))}")  # fmt: skip


if __name__ == "__main__":
    main()
