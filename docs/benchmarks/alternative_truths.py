"""Is it the truth? The IMM / CV ratio on truths built other ways from the same recordings.

    python docs/benchmarks/alternative_truths.py DIR --split train --period 4 \\
        --truth speed|track [--heading-smooth-s 6] [--preset imm-ct]

DIR holds the traffic 2.8.1 ``calibration/*.json.gz`` samples (never committed), split as
``tune_tracker.py`` splits them. ``evaluation.resample`` (the truth of every figure in
``docs/tracking.md``) takes the speed and the heading from the re-timed, smoothed positions;
its along-track acceleration is mostly a 15–30 s oscillation. Here, instead:

- ``speed``: the heading from those smoothed positions (optionally smoothed again by a
  Gaussian of ``--heading-smooth-s`` seconds), the speed from the recorded ground speed
  (cubic Savitzky–Golay over 31 s), the positions integrated from the two;
- ``track``: the heading from the recorded track angle (plus the flight's median offset to
  the positions' bearing: ~100° in most calibration samples, a constant), smoothed over
  11 s only, so turns begin as sharply as the aircraft's own track says; speed as above.

Both are flown exactly (positions the integral of the velocity, ω the heading's rate). One
line per run: the preset's evaluation (``evaluation.evaluate``).
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter1d
from scipy.signal import savgol_filter
from tune_tracker import SIGMA_BY_PERIOD, flights_of, preset, split, split_arguments, truths_of

from airspace_sim.tracking.evaluation import (
    MAX_GAP_S,
    SMOOTH_S,
    Truth,
    evaluate,
    retime,
)

#: window (s) of the ``track`` truth's heading smoothing
TRACK_SMOOTH_S = 11


def _flown(name, fine, heading, speed, x0, y0, period_s):
    """A Truth every ``period_s`` of the motion at ``heading`` (rad) and ``speed`` (m/s) on
    the 1 s grid ``fine``, from (x0, y0)."""
    vx, vy = speed * np.cos(heading), speed * np.sin(heading)
    px = x0 + np.concatenate([[0.0], np.cumsum(0.5 * (vx[1:] + vx[:-1]))])
    py = y0 + np.concatenate([[0.0], np.cumsum(0.5 * (vy[1:] + vy[:-1]))])
    omega = np.gradient(heading, 1.0)
    g = np.arange(fine[0], fine[-1], period_s)
    state = np.stack([np.interp(g, fine, v) for v in (px, vx, py, vy, omega)], axis=1)
    return Truth(name, g, state)


def truths(files, period_s, how, heading_smooth_s=0.0):
    out = []
    win = int(SMOOTH_S) | 1
    for f in flights_of(files):
        cuts = np.flatnonzero(np.diff(f.t_s) > MAX_GAP_S) + 1
        for seg, (a, b) in enumerate(zip(np.r_[0, cuts], np.r_[cuts, f.t_s.size])):
            t = f.t_s[a:b]
            if b - a < 4 or t[-1] - t[0] < max(300.0, 2 * SMOOTH_S):
                continue  # as resample
            x, y, vx, vy = (v[a:b] for v in (f.x_m, f.y_m, f.vx, f.vy))
            ground = np.hypot(vx, vy)
            if not np.all(np.isfinite(ground)):
                continue
            fine = np.arange(t[0], t[-1], 1.0)
            speed = savgol_filter(np.interp(fine, t, ground), win, 3, mode="interp")
            if how == "speed":
                ts, keep = retime(t, x, y, ground)
                vel = [
                    savgol_filter(np.interp(fine, ts, v[keep]), win, 3, deriv=1, mode="interp")
                    for v in (x, y)
                ]
                heading = np.unwrap(np.arctan2(vel[1], vel[0]))
                if heading_smooth_s > 0:
                    heading = gaussian_filter1d(heading, heading_smooth_s, mode="nearest")
            else:
                track = np.unwrap(np.arctan2(vy, vx))
                bearing = np.arctan2(np.gradient(y), np.gradient(x))
                offset = np.angle(np.median(np.exp(1j * (bearing - track))))
                heading = savgol_filter(
                    np.interp(fine, t, track + offset), TRACK_SMOOTH_S, 3, mode="interp"
                )
            out.append(_flown(f"{f.id}#{seg}", fine, heading, speed, x[0], y[0], period_s))
    return out


def main(argv=None) -> None:
    ap = split_arguments(__doc__)
    ap.add_argument("--truth", choices=("resample", "speed", "track"), default="speed")
    ap.add_argument("--heading-smooth-s", type=float, default=0.0)
    ap.add_argument("--preset", default="imm-ct")
    a = ap.parse_args(argv)
    files = split(a.directory, a.split)
    if a.truth == "resample":  # the evaluation's own, for comparison in one run
        tr = truths_of(files, a.period)
    else:
        tr = truths(files, a.period, a.truth, a.heading_smooth_s)
    speed = np.concatenate([np.hypot(t.state[:, 1], t.state[:, 3]) for t in tr])
    along = np.concatenate(
        [np.gradient(np.hypot(t.state[:, 1], t.state[:, 3]), a.period) for t in tr]
    )
    ev = evaluate(tr, preset(a.preset), SIGMA_BY_PERIOD[a.period], a.period, smoother=False)
    print(
        f"{a.split} {a.period:g}s truth={a.truth} heading-smooth={a.heading_smooth_s:g}s "
        f"{a.preset}: ratio {ev.pos_imm / ev.pos_cv:.3f} (IMM {ev.pos_imm:.1f} m, CV "
        f"{ev.pos_cv:.1f} m @ {ev.cv_sigma:g}); along-track acceleration RMS "
        f"{np.sqrt(np.mean(along**2)):.2f} m/s² (speed {speed.mean():.0f} m/s); turning "
        f"{100 * ev.turning_flagged:.1f}% / straight {100 * ev.straight_flagged:.2f}%; onset "
        + ", ".join(f"{lo:g}-{hi:g} s {100 * s:.0f}%" for lo, hi, s, _ in ev.onset),
        flush=True,
    )


if __name__ == "__main__":
    main()
