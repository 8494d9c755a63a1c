"""``airspace-sim replay FILE``: recorded flights in the world, tracked and screened for conflicts.

Examples::

    airspace-sim replay traffic:switzerland --start 21600 --duration 3600
    airspace-sim replay flights.parquet --r-safe 9260 --json out/replay.json
    airspace-sim replay traffic:calibration/ajaccio --render out/ajaccio --every 10 --gif
    airspace-sim replay traffic:switzerland --scenario my_ownship.toml   # simulated + real
    airspace-sim replay states.csv --set sensor.sigma=100 --set sensor.period=4

FILE is a trajectory file (OpenSky state vectors or the ``traffic`` library's CSV, Parquet
or JSON records; :mod:`airspace_sim.recorded.readers`) or ``traffic:NAME``, a sample of the
``traffic`` 2.8.1 wheel (:mod:`airspace_sim.recorded.samples`). Every recorded flight flies
its recording (:mod:`airspace_sim.recorded.autopilot`); every aircraft tracks the others
with the scenario's sensor and tracker and runs the detection. ``--scenario`` adds the
scenario's own aircraft (e.g. a simulated ownship with a resolver, positions in the
recording's local frame) and settings; ``--set`` changes any key, as for ``run``
(``recorded.min_altitude_ft=10000``, ``sensor.sigma=30``, ...).

The report: the world's metrics (as ``run``) and the replay's own, about the pairs of real
aircraft (:mod:`airspace_sim.recorded.analysis`): losses of separation at ``r_safe``
(horizontal, and with ``--vertical-ft``), alerts and how many losses they predicted, track
errors against the recording, mode identification against the recorded turn rate.
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

from airspace_sim.commands._args import (
    add_set_option,
    frame_size,
    non_negative_int,
    positive_float,
    positive_int,
)
from airspace_sim.errors import UserError

HELP = "replay recorded flights (OpenSky / traffic files) in the world: alerts, LoS, tracking"


def _non_negative_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number ≥ 0, got {text!r}") from None
    if not (math.isfinite(value) and value >= 0):
        raise argparse.ArgumentTypeError(f"expected a number ≥ 0, got {text!r}")
    return value


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from airspace_sim.recorded.glitches import SPIKE_M

    parser.add_argument("file", help="trajectory file, or traffic:NAME (a traffic wheel sample)")
    parser.add_argument(
        "--scenario",
        metavar="TOML",
        help="scenario whose settings and aircraft join the replay (its [recorded] file is "
        "replaced by FILE)",
    )
    add_set_option(parser)
    parser.add_argument(
        "--start",
        type=_non_negative_float,
        metavar="S",
        help="seconds into the recording at which the replay starts (default 0)",
    )
    parser.add_argument(
        "--duration",
        type=positive_float,
        metavar="S",
        help="seconds to replay (default: to the end of the recording)",
    )
    parser.add_argument(
        "--r-safe",
        type=positive_float,
        metavar="M",
        help="separation radius in metres (default: the scenario's, 3000)",
    )
    parser.add_argument(
        "--velocity",
        choices=("reported", "positions"),
        help="flight velocities from the reported ground speed and track (default) or from "
        "differenced positions (for data whose track disagrees with its positions)",
    )
    parser.add_argument(
        "--keep-glitches",
        action="store_true",
        help=f"keep recorded positions lying over {SPIKE_M:g} m across the track from their "
        "neighbours' path (dropped by default: recording glitches)",
    )
    parser.add_argument(
        "--vertical-ft",
        type=positive_float,
        default=1000.0,
        metavar="FT",
        help="vertical separation for the 3-D losses, ft (default 1000)",
    )
    parser.add_argument(
        "--seed", type=non_negative_int, help="random seed (default: the scenario's seed)"
    )
    parser.add_argument("--render", metavar="DIR", help="write PNG frames and summary.json")
    video = parser.add_mutually_exclusive_group()
    video.add_argument("--gif", action="store_true", help="also write DIR/run.gif")
    video.add_argument("--mp4", action="store_true", help="also write DIR/run.mp4")
    parser.add_argument(
        "--every", type=positive_int, default=1, metavar="N", help="render every N-th step"
    )
    parser.add_argument(
        "--size", type=frame_size, default=(800, 800), metavar="WxH", help="frame size"
    )
    parser.add_argument("--fps", type=positive_float, default=10.0, help="GIF/MP4 frame rate")
    parser.add_argument(
        "--owners", metavar="IDS", help="whose tracks to draw: ids or 'all' (as for run)"
    )
    parser.add_argument("--json", metavar="PATH", help="write the summary as JSON to PATH")
    parser.add_argument("--quiet", action="store_true", help="no progress bar and no table")


def build_scenario(args):
    """The replay's validated Scenario: ``--scenario`` (or the defaults) with a
    ``[recorded]`` section for FILE, ``--start``, ``--r-safe``, the ``--set`` overrides,
    and a duration to the end of the recording unless one is given."""
    from airspace_sim import scenarios
    from airspace_sim.recorded.scenario import load_flights

    if args.scenario:
        path = scenarios.resolve(args.scenario)
        source = scenarios.loader.display_path(path)
        data = scenarios.loader.parse_toml(path.read_text(encoding="utf-8"), source)
        data.setdefault("name", path.stem)
    else:
        source = "<replay>"
        data = {"name": f"replay {Path(args.file).name}"}
    recorded = dict(data.get("recorded") or {})
    recorded["file"] = str(Path(args.file).resolve()) if Path(args.file).exists() else args.file
    if args.start is not None:
        recorded["start_s"] = args.start
    if args.velocity is not None:
        recorded["velocity"] = args.velocity
    if args.keep_glitches:
        recorded["keep_glitches"] = True
    data["recorded"] = recorded
    if args.r_safe is not None:
        data.setdefault("separation", {})["r_safe"] = args.r_safe
    if args.duration is not None:
        data["duration"] = args.duration
    sc = scenarios.from_dict(data, source, args.overrides)
    explicit = args.duration is not None or any(
        o.split("=", 1)[0].strip() == "duration" for o in args.overrides
    )
    if not explicit and not (args.scenario and "duration" in data):
        flights = load_flights(sc.recorded, sc.source)
        span = flights.end_s - (flights.start_s + sc.recorded.start_s)
        if span <= 0:
            raise UserError(
                f"{args.file}: --start {sc.recorded.start_s:g} s is after the recording's end "
                f"({flights.end_s - flights.start_s:g} s)"
            )
        data["duration"] = math.ceil(span / sc.dt) * sc.dt
        sc = scenarios.from_dict(data, source, args.overrides)
    return sc


def run(args) -> int:
    """Replay; on Ctrl-C or SIGTERM (exit 130 / 143, like ``run``) the steps so far are
    summarised, ``--json`` and ``--render`` (frames, video) written, then the run ends."""
    from airspace_sim.commands._args import check_output
    from airspace_sim.commands._signals import SigtermFlag, Terminated
    from airspace_sim.commands.run import (
        Frames,
        format_table,
        jsonable,
        step_world,
        track_owners,
        write_summary,
    )
    from airspace_sim.recorded.analysis import ReplayStats
    from airspace_sim.world import World

    if (args.gif or args.mp4) and not args.render:
        raise UserError(
            f"--{'gif' if args.gif else 'mp4'} needs --render DIR (the frames go there)"
        )
    if args.json:  # before the replay, not after it ran
        check_output("--json", args.json)
    if args.render:
        check_output("--render", args.render, folder=True)
    sc = build_scenario(args)
    seed = sc.seed if args.seed is None else args.seed
    t_build = time.perf_counter()
    world = World(sc, seed=seed)
    build_s = time.perf_counter() - t_build
    if not world.moved.any():
        raise UserError(f"{args.file}: no recorded flight during the replay's {sc.duration:g} s")
    stats = ReplayStats(world, vertical_ft=args.vertical_ft)
    stats.observe()
    frames = None
    if args.render:
        first = world.snapshot()
        video = "gif" if args.gif else "mp4" if args.mp4 else None
        frames = Frames(
            Path(args.render), args.size, video, args.fps, track_owners(first, args.owners)
        )
        frames.add(first)
    steps = sc.n_steps
    # SIGTERM only sets a flag, checked between steps: the replay stops as on Ctrl-C; one
    # that comes while the outputs are written waits for them, then ends the replay
    with SigtermFlag() as sigterm:
        t0, cpu0 = time.perf_counter(), time.process_time()
        stopped = step_world(
            world,
            steps,
            sc.name,
            args.quiet,
            frames,
            args.every,
            sigterm,
            after_step=lambda k: stats.observe(),
        )
        wall = time.perf_counter() - t0
        cpu = time.process_time() - cpu0  # this process's CPU s: on a shared machine wall
        # time also counts the waits for a core
        video_path = frames.close() if frames is not None else None
        summary = {
            "scenario": sc.name,
            "source": sc.source,
            "file": sc.recorded.file,
            "seed": seed,
            "overrides": list(args.overrides),
            "start_s": sc.recorded.start_s,
            "steps": world.step_count,
            "dt": float(world.dt),
            "simulated_time": float(world.time),
            "wall_time": round(wall, 3),
            "build_time": round(build_s, 3),
            "steps_per_second": round(world.step_count / wall, 1) if wall > 0 else None,
            "real_time_factor": round(world.time / wall, 1) if wall > 0 else None,
            "cpu_time": round(cpu, 3),
            "real_time_factor_cpu": round(world.time / cpu, 1) if cpu > 0 else None,
            "interrupted": stopped is not None,
            "replay": jsonable(stats.report()),
            "metrics": jsonable(world.metrics()),
        }
        write_summary(args, summary, frames, video_path)
        if not args.quiet:
            both = {"replay": summary["replay"], "world": summary["metrics"]}
            print(format_table({**summary, "metrics": both}))
            if frames is not None:
                print(f"\n{len(frames.paths)} frames in {frames.directory}")
        if stopped is not None:
            raise stopped
        if sigterm.received:
            raise Terminated
    return 0
