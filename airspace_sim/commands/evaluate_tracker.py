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
    from airspace_sim.tracking.evaluation import evaluate, resample

    if args.lag is not None and args.no_smoother:
        raise UserError("evaluate-tracker: --lag needs the smoothers; drop --no-smoother")
    paths = _paths(args)
    flights = [f for p in paths for f in read(p)]
    chosen = [presets.get(name) for name in (args.preset or [presets.RECORDED_TRACKER])]
    results = []
    for sigma, period in SETTINGS:
        truths = []
        for f in flights:
            speed = None if args.no_retime else np.hypot(f.vx, f.vy)
            if speed is not None and not np.all(np.isfinite(speed)):
                speed = None  # no ground speed on some rows: keep the recorded times
            truths += resample(f.id, f.t_s, f.x_m, f.y_m, period, speed_mps=speed)
        for p in tqdm(chosen, desc=f"sigma={sigma:g} m, {period:g} s", leave=False):
            ev = evaluate(truths, p, sigma, period, seed=args.seed, smoother=not args.no_smoother,
                          smoother_lag_s=args.lag)  # fmt: skip
            tqdm.write("\n".join(ev.lines()))
            results.append(ev)
    if args.json:
        path = Path(args.json)
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(json.dumps([r.to_dict() for r in results], indent=2))
        except OSError as exc:
            raise UserError(f"--json {path}: cannot write ({exc.strerror})") from None
    return 0
