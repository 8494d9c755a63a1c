"""``airspace-sim bench-world``: world step time against the bare IMM step, by size.

For each number of aircraft, :func:`airspace_sim.world.benchmark.bench_world` times world
steps of the constant-density benchmark traffic (with trackers, and/or with perfect
surveillance), and — with trackers — the bare IMM step over the same number of tracks
(same preset, in this process, right after): the ratio says how much of a world step is
not tracking. Also steps per second, the peak resident memory and the memory per track.
Then how the cost per step grows (ratio of times per step and the exponent
``log(ratio) / log(N₂/N₁)``: 1 is linear, 2 quadratic; and the same in tracks), in wall-clock
and in process CPU time (the one to read on a shared machine), between consecutive sizes
and from 1000 aircraft to the largest::

    airspace-sim bench-world
    airspace-sim bench-world --sizes 100 1000 3000 10000
    airspace-sim bench-world --sizes 100 300 1000 --steps 30 --trackers on --json out/bench.json

Absolute numbers depend on the machine and its load; compare ratios from one run.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

from airspace_sim.commands._args import positive_int
from airspace_sim.errors import UserError

HELP = "benchmark world steps against the bare IMM step at 100, 1000 and 3000 aircraft"

DEFAULT_SIZES = (100, 1000, 3000)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--sizes",
        type=positive_int,
        nargs="+",
        default=list(DEFAULT_SIZES),
        metavar="N",
        help="numbers of aircraft (default: 100 1000 3000)",
    )
    parser.add_argument(
        "--steps",
        type=positive_int,
        default=10,
        help="timed steps per size, after at least 5 untimed warm-up steps, on until one "
        "step after the first conflict (default 10)",
    )
    parser.add_argument(
        "--trackers",
        choices=("both", "on", "off"),
        default="on",
        help="run with trackers (default), without (perfect surveillance), or both",
    )
    parser.add_argument("--json", metavar="PATH", help="also write the results as JSON")


#: the growth from this size to the largest is reported too (issue 12: 1000 → 10,000)
GROWTH_FROM = 1000


def _exponent(ratio: float, size_ratio: float) -> float:
    ok = ratio > 0 and size_ratio > 1
    return math.log(ratio) / math.log(size_ratio) if ok else float("nan")


def growth(rows: list[dict]) -> list[dict]:
    """Cost growth between consecutive sizes, and from :data:`GROWTH_FROM` aircraft to the
    largest size when those are not consecutive, per tracker setting: the wall-clock time
    ratio, its exponent in the number of aircraft and (``track_exponent``) in the number of
    tracks, and the same in process CPU time (``cpu_time_ratio``, ``cpu_exponent``,
    ``cpu_track_exponent``: what a shared machine's other jobs disturb least)."""
    out = []
    for trackers in dict.fromkeys(r["trackers"] for r in rows):
        rs = sorted((r for r in rows if r["trackers"] == trackers), key=lambda r: r["aircraft"])
        pairs = list(zip(rs, rs[1:], strict=False))
        start = [r for r in rs[:-2] if r["aircraft"] == GROWTH_FROM]
        pairs += [(start[0], rs[-1])] if start else []
        for a, b in pairs:
            ratio = b["ms_per_step"] / a["ms_per_step"]
            cpu = b["cpu_ms_per_step"] / a["cpu_ms_per_step"]
            tracks = (b.get("tracks") or 0.0) / (a.get("tracks") or math.inf)
            size = b["aircraft"] / a["aircraft"]
            out.append(
                {
                    "trackers": trackers,
                    "from": a["aircraft"],
                    "to": b["aircraft"],
                    "time_ratio": ratio,
                    "exponent": _exponent(ratio, size),
                    "track_exponent": _exponent(ratio, tracks),
                    "cpu_time_ratio": cpu,
                    "cpu_exponent": _exponent(cpu, size),
                    "cpu_track_exponent": _exponent(cpu, tracks),
                }
            )
    return out


def _in_tracks(g: dict, key: str) -> str:
    value = g.get(key, math.nan)
    return "" if math.isnan(value) else f", {value:.2f} in tracks"


def _opt(value, fmt: str, width: int) -> str:
    return f"{'-':>{width}}" if value is None else f"{value:>{width}{fmt}}"


def format_report(rows: list[dict], grow: list[dict]) -> str:
    lines = [
        f"{'aircraft':>8}  {'trackers':>8}  {'tracks':>8}  {'world ms/step':>13}  "
        f"{'IMM ms/step':>11}  {'world/IMM':>9}  {'CPU: world':>10}  {'IMM':>8}  {'ratio':>6}  "
        f"{'steps/s':>7}  {'peak MB':>8}  {'KB/track':>8}"
    ]
    for r in rows:
        imm = r.get("imm_ms_per_step")
        head = (
            f"{r['aircraft']:>8}  {('on' if r['trackers'] else 'off'):>8}  "
            f"{r['tracks']:>8.0f}  {r['ms_per_step']:>13.2f}  "
        )
        if imm is None:
            tail = f"{'-':>11}  {'-':>9}  {r['cpu_ms_per_step']:>10.2f}  {'-':>8}  {'-':>6}"
        else:
            tail = (
                f"{imm:>11.2f}  {r['ratio']:>9.2f}  {r['cpu_ms_per_step']:>10.2f}  "
                f"{r['imm_cpu_ms_per_step']:>8.2f}  {r['cpu_ratio']:>6.2f}"
            )
        kb = r.get("bytes_per_track")
        mem = (
            f"  {r['steps_per_second']:>7.2f}  {_opt(r.get('peak_rss_mb'), '.0f', 8)}  "
            f"{_opt(None if kb is None else kb / 1024, '.2f', 8)}"
        )
        lines.append(head + tail + mem)
    lines.append(
        "(medians over the timed steps, wall clock, then process CPU time, which other "
        "processes on the machine disturb less; IMM: the bare step of the world's tracker "
        "over the same number of tracks, same preset, timed right after in this process; "
        "steps/s: all timed steps; peak MB: the process's peak resident memory while the "
        "world was built and stepped; KB/track: that peak less the memory before, per track)"
    )
    late = [r for r in rows if r.get("kernels_loaded_timed")]
    for r in late:
        lines.append(
            f"warning: {r['kernels_loaded_timed']} numba kernels were compiled or loaded during "
            f"the timed steps at {r['aircraft']} aircraft (their time is in the medians' steps)"
        )
    if grow:
        lines.append("")
        for g in grow:
            lines.append(
                f"trackers {'on' if g['trackers'] else 'off'}: {g['from']} → {g['to']} aircraft "
                f"(×{g['to'] / g['from']:.3g}): time per step ×{g['time_ratio']:.2f}, "
                f"growth exponent {g['exponent']:.2f}{_in_tracks(g, 'track_exponent')} "
                f"(wall clock); CPU time per step ×{g['cpu_time_ratio']:.2f}, growth exponent "
                f"{g['cpu_exponent']:.2f}{_in_tracks(g, 'cpu_track_exponent')} (CPU) "
                "(1 = linear, 2 = quadratic)"
            )
    return "\n".join(lines)


def run(args) -> int:
    from airspace_sim.world.benchmark import bench_world

    settings = {"both": (False, True), "on": (True,), "off": (False,)}[args.trackers]
    rows = []
    for trackers in settings:
        for n in args.sizes:
            r = bench_world(n, args.steps, trackers)
            imm = r.get("imm")
            rows.append(
                {
                    "aircraft": n,
                    "trackers": trackers,
                    "steps": args.steps,
                    "tracks": r["mean_tracks"],
                    "ms_per_step": r["ms_per_step"],
                    "cpu_ms_per_step": r["cpu_ms_per_step"],
                    "steps_per_second": r["steps_per_s"],
                    "imm_ms_per_step": None if imm is None else imm["ms_per_step"],
                    "imm_cpu_ms_per_step": None if imm is None else imm["cpu_ms_per_step"],
                    "imm_kernel": None if imm is None else imm["kernel"],
                    "ratio": r.get("ratio"),
                    "cpu_ratio": r.get("cpu_ratio"),
                    "peak_rss_mb": r.get("peak_rss_mb"),
                    "bytes_per_track": r.get("bytes_per_track"),
                    "warmup_steps": r.get("warmup_steps"),
                    "kernels_loaded_timed": r.get("kernels_loaded_timed"),
                }
            )
    grow = growth(rows)
    print(format_report(rows, grow))
    if args.json:
        from airspace_sim.commands.run import jsonable

        path = Path(args.json)
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(
                json.dumps(jsonable({"results": rows, "growth": grow}), indent=2) + "\n"
            )
        except OSError as exc:
            raise UserError(f"--json {path}: cannot write: {exc}") from None
    return 0
