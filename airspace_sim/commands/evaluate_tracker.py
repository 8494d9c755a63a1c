"""``airspace-sim evaluate-tracker FILE...``: the IMM against the best-tuned CV filter on
recorded flights (:mod:`airspace_sim.tracking.evaluation`), at σ = 50 m every 1 s and
σ = 100 m every 4 s."""

from __future__ import annotations

HELP = (
    "Measure a tracker preset on recorded flights: IMM vs best-tuned CV filter RMSE, NIS, "
    "turns flagged, and after the fact by fixed-interval smoothers (sigma=50 m at 1 s, "
    "sigma=100 m at 4 s)."
)

#: (σ m, period s) settings of issue 10.
SETTINGS = ((50.0, 1.0), (100.0, 4.0))


def add_arguments(parser) -> None:
    from airspace_sim.recorded.glitches import SPIKE_M

    parser.add_argument(
        "files", nargs="*", metavar="FILE",
        help="recorded trajectories (any format airspace_sim.recorded.read takes)",
    )  # fmt: skip
    parser.add_argument(
        "--sample", action="append", default=[], metavar="NAME",
        help="a traffic-wheel sample (e.g. calibration/munich, or calibration/* for a folder); "
        "repeatable",
    )  # fmt: skip
    parser.add_argument(
        "--preset", action="append", default=None, metavar="NAME",
        help="tracker preset(s) to measure (repeatable; default imm-ct, the tracker for "
        "recorded traffic)",
    )  # fmt: skip
    parser.add_argument("--seed", type=int, default=0, help="measurement-noise seed (default 0)")
    parser.add_argument(
        "--no-retime", action="store_true",
        help="do not re-time the recorded positions by the recorded ground speed",
    )  # fmt: skip
    parser.add_argument(
        "--keep-glitches", action="store_true",
        help=f"keep recorded positions lying over {SPIKE_M:g} m across the track from their "
        "neighbours' path (dropped by default: recording glitches, not turns)",
    )  # fmt: skip
    parser.add_argument(
        "--no-smoother", action="store_true",
        help="skip the fixed-interval smoothers (the after-the-fact line: each whole flight "
        "smoothed, turns flagged and positions scored)",
    )  # fmt: skip
    parser.add_argument(
        "--lag", type=float, default=None, metavar="S",
        help="smooth with S seconds of look-ahead (fixed-lag: the flags of a tracker that "
        "reports S s late) instead of over each whole flight",
    )  # fmt: skip
    parser.add_argument(
        "--json", metavar="PATH", default=None, help="also write the figures as JSON to PATH"
    )
    parser.add_argument(
        "--plot", metavar="DIR", default=None,
        help="also draw PNGs into DIR: per preset and setting, the flags by time since the "
        "turn began and the errors by phase, and the segments with the most turning seconds "
        "(path, turn rate, flags, mode probabilities, errors)",
    )  # fmt: skip
    parser.add_argument(
        "--plot-flights", type=int, default=3, metavar="N",
        help="with --plot: how many segments to draw (default 3; 0: the summaries only)",
    )  # fmt: skip
    parser.add_argument(
        "--plot-window", type=float, default=900.0, metavar="S",
        help="with --plot: seconds of each segment to draw, those with the most turning "
        "seconds (default 900)",
    )  # fmt: skip


def _paths(args) -> list:
    import fnmatch

    from airspace_sim.errors import UserError
    from airspace_sim.recorded import samples

    paths = list(args.files)
    for pattern in args.sample:
        names = [n for n in samples.names() if fnmatch.fnmatch(n, pattern)]
        if not names:
            paths.append(samples.path(pattern))  # a one-line error naming how to get them
        paths += [samples.path(n) for n in names]
    if not paths:
        raise UserError("evaluate-tracker: give FILE... or --sample NAME")
    return paths


def run(args) -> int:
    import json
    from pathlib import Path

    import numpy as np
    from tqdm import tqdm

    from airspace_sim.dynamics import presets
    from airspace_sim.errors import UserError
    from airspace_sim.recorded import read
    from airspace_sim.recorded.glitches import SPIKE_M
    from airspace_sim.tracking.evaluation import evaluate_with_record, resample
    from airspace_sim.tracking.evaluation_plot import most_turning

    if args.lag is not None and args.no_smoother:
        raise UserError("evaluate-tracker: --lag needs the smoothers; drop --no-smoother")
    plots = _plot_folder(args)
    paths = _paths(args)
    glitch_m = None if args.keep_glitches else SPIKE_M
    flights = [f for p in paths for f in read(p, glitch_m=glitch_m)]
    chosen = [presets.get(name) for name in (args.preset or [presets.RECORDED_TRACKER])]
    results = []
    for sigma, period in SETTINGS:
        truths = []
        for f in flights:
            speed = None if args.no_retime else np.hypot(f.vx, f.vy)
            if speed is not None and not np.all(np.isfinite(speed)):
                speed = None  # no ground speed on some rows: keep the recorded times
            truths += resample(f.id, f.t_s, f.x_m, f.y_m, period, speed_mps=speed)
        drawn = most_turning(truths, args.plot_flights) if plots else []
        for p in tqdm(chosen, desc=f"sigma={sigma:g} m, {period:g} s", leave=False):
            ev, record = evaluate_with_record(
                truths, p, sigma, period, drawn, seed=args.seed, smoother=not args.no_smoother,
                smoother_lag_s=args.lag,
            )  # fmt: skip
            tqdm.write("\n".join(ev.lines()))
            results.append(ev)
            if plots:
                _draw(plots, ev, record, args.plot_window)
    if args.json:
        path = Path(args.json)
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(json.dumps([r.to_dict() for r in results], indent=2))
        except OSError as exc:
            raise UserError(f"--json {path}: cannot write ({exc.strerror})") from None
    return 0


def _plot_folder(args):
    """The folder of ``--plot`` (made), or None; its options checked."""
    import math
    from pathlib import Path

    from airspace_sim.errors import UserError

    if args.plot is None:
        return None
    if args.plot_flights < 0:
        raise UserError(f"--plot-flights: must be >= 0, got {args.plot_flights}")
    if not (math.isfinite(args.plot_window) and args.plot_window > 0):
        raise UserError(f"--plot-window: must be a number of seconds > 0, got {args.plot_window}")
    folder = Path(args.plot)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(f"--plot {folder}: cannot make the folder ({exc.strerror})") from None
    return folder


def _draw(folder, ev, record, window_s: float) -> None:
    """The summary PNG of ``ev`` and one PNG per segment of ``record`` (its ``window_s``
    seconds with the most turning) into ``folder``."""
    import re

    from tqdm import tqdm

    from airspace_sim.tracking.evaluation_plot import plot_flight, plot_summary

    stem = f"{ev.preset}-{ev.period_s:g}s"
    written = [plot_summary(ev, folder / f"{stem}-summary.png")]
    for f, name in enumerate(record.names):
        safe = re.sub(r"[^A-Za-z0-9_.-]+", "_", name)
        written.append(plot_flight(record, f, folder / f"{stem}-{f + 1}-{safe}.png", window_s))
    tqdm.write(f"  plots: {', '.join(str(p) for p in written)}")
