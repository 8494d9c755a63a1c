"""``airspace-sim bench-world``: world steps per second at N = 100 and 1000 aircraft.

Calls :func:`airspace_sim.world.benchmark.bench_world` for each size, without and with
trackers, and prints steps per second and how the cost per step grows with N (the ratio of
times per step, and the exponent ``log(ratio) / log(N₂/N₁)``: 1 is linear, 2 quadratic)::

    airspace-sim bench-world
    airspace-sim bench-world --sizes 100 300 1000 --steps 30 --trackers on --json out/bench.json

Absolute numbers depend on the machine and its load; compare ratios from one run.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

from airspace_sim.errors import UserError

HELP = "benchmark world steps per second at 100 and 1000 aircraft, with and without trackers"


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {value}")
    return value


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--sizes",
        type=_positive_int,
        nargs="+",
        default=[100, 1000],
        metavar="N",
        help="numbers of aircraft (default: 100 1000)",
    )
    parser.add_argument(
        "--steps",
        type=_positive_int,
        default=10,
        help="timed steps per size, after 5 untimed warm-up steps (default 10)",
    )
    parser.add_argument(
        "--trackers",
        choices=("both", "on", "off"),
        default="both",
        help="run with trackers, without, or both (default)",
    )
    parser.add_argument("--json", metavar="PATH", help="also write the results as JSON")


def steps_per_second(result) -> float:
    """Steps per second from what ``bench_world`` returns (a number or a dict)."""
    if isinstance(result, dict):
        for key in ("steps_per_s", "steps_per_second", "sps"):
            if key in result:
                return float(result[key])
        for key in ("seconds_per_step", "s_per_step"):
            if key in result:
                return 1.0 / float(result[key])
        raise TypeError(f"bench_world returned a dict without steps per second: {sorted(result)}")
    return float(result)


def growth(rows: list[dict]) -> list[dict]:
    """Cost growth between consecutive sizes, per tracker setting."""
    out = []
    for trackers in dict.fromkeys(r["trackers"] for r in rows):
        rs = sorted((r for r in rows if r["trackers"] == trackers), key=lambda r: r["aircraft"])
        for a, b in zip(rs, rs[1:], strict=False):
            ratio = a["steps_per_second"] / b["steps_per_second"]  # time per step, b over a
            n_ratio = b["aircraft"] / a["aircraft"]
            exponent = (
                math.log(ratio) / math.log(n_ratio) if ratio > 0 and n_ratio > 1 else float("nan")
            )
            out.append(
                {
                    "trackers": trackers,
                    "from": a["aircraft"],
                    "to": b["aircraft"],
                    "time_ratio": ratio,
                    "exponent": exponent,
                }
            )
    return out


def format_report(rows: list[dict], grow: list[dict]) -> str:
    lines = [
        f"{'aircraft':>8}  {'trackers':>8}  {'steps/s':>10}  {'ms/step':>9}  "
        f"{'aircraft-steps/s':>16}  {'tracks':>8}"
    ]
    for r in rows:
        sps = r["steps_per_second"]
        tracks = (r.get("raw") or {}).get("mean_tracks")
        tracks = "-" if tracks is None else f"{tracks:.0f}"
        lines.append(
            f"{r['aircraft']:>8}  {('on' if r['trackers'] else 'off'):>8}  {sps:>10.1f}  "
            f"{1000.0 / sps:>9.2f}  {sps * r['aircraft']:>16.0f}  {tracks:>8}"
        )
    if grow:
        lines.append("")
        for g in grow:
            lines.append(
                f"trackers {'on' if g['trackers'] else 'off'}: {g['from']} → {g['to']} aircraft "
                f"(×{g['to'] / g['from']:.3g}): time per step ×{g['time_ratio']:.2f}, "
                f"growth exponent {g['exponent']:.2f} (1 = linear, 2 = quadratic)"
            )
    return "\n".join(lines)


def run(args) -> int:
    try:
        from airspace_sim.world.benchmark import bench_world
    except ImportError as exc:
        raise UserError(f"the world benchmark is not available ({exc})") from None

    settings = {"both": (False, True), "on": (True,), "off": (False,)}[args.trackers]
    rows = []
    for trackers in settings:
        for n in args.sizes:
            result = bench_world(n, args.steps, trackers)
            rows.append(
                {
                    "aircraft": n,
                    "trackers": trackers,
                    "steps": args.steps,
                    "steps_per_second": steps_per_second(result),
                    "raw": result if isinstance(result, dict) else None,
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
