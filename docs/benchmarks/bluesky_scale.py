"""Throughput side by side: our world vs BlueSky 1.1.1 on the same random traffic.

    python docs/benchmarks/bluesky_scale.py --sizes 100 300 1000 --repeats 4 \\
        --bluesky-python /path/to/bluesky-venv/bin/python [--steps 60] [--out rows.jsonl]

Run it with the project's venv (``airspace_sim`` importable); BlueSky (``pip install
bluesky-simulator==1.1.1``) lives in its own venv, given by ``--bluesky-python``, and this
file re-runs itself there with ``--side bluesky``, reading the traffic from a JSON file
this side wrote. BlueSky is driven by ``bluesky_driver.py`` (shared with
``bluesky_rings.py``).

Traffic: :func:`airspace_sim.world.benchmark.random_scenario` (the ``random`` pattern at
constant density: ``n`` aircraft in a square of side 10 km·√n, routes across it at 230 m/s,
initially more than r_safe = 3 km apart), the aircraft of seed ``--seed`` as our world
builds them; BlueSky gets the same starts, headings, speeds and destinations.

- ours: :func:`~airspace_sim.world.benchmark.bench_world` with trackers: 1 s steps, every
  neighbour within 40 km tracked by the IMM from σ = 50 m measurements, resolver ``bands``
  (look-ahead 120 s); reports mean tracks and the process's peak RSS during the run.
- BlueSky, twice: detection only (``ASAS ON``, ``RESO OFF``) and detection + MVP, both on
  true states, protected zone 3 km, look-ahead 120 s, ``DT 1`` (so detection, every 1 s of
  simulated time, runs once per step); mean conflict pairs per step reported.

Each run: ``--warmup`` untimed steps (numba compilation on our side), then ``--steps``
timed ones; throughput = simulated seconds per wall second. The systems alternate within
each repeat (ours first on even repeats, BlueSky first on odd ones); the table gives
medians over the repeats and the ratio ours / BlueSky of the medians. One JSON line per
run, then the Markdown table. Aircraft do not reach their destinations within the default
65 s (half a side is ≥ 50 km away).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time

import bluesky_driver  # docs/benchmarks/, next to this file (sys.path[0])
import numpy as np

R_SAFE, LOOKAHEAD, MARGIN, DT = 3000.0, 120.0, 0.1, 1.0
MODES = {"detect": "OFF", "mvp": "MVP"}  # BlueSky run -> RESO method
LABELS = {
    "ours": "ours (IMM tracks, bands)",
    "detect": "BlueSky detection only",
    "mvp": "BlueSky detection + MVP",
}


def our_traffic(n, seed):
    """The traffic of :func:`random_scenario` (n, seed) as our world builds it: a dict of
    ``ids``, ``start`` (n, 2) m, ``heading`` (n,) rad CCW from east, ``speed`` (n,) m/s,
    ``dest`` (n, 2) m (the route's one waypoint), as JSON-ready lists."""
    from airspace_sim.scenarios import build_aircraft
    from airspace_sim.world.benchmark import random_scenario

    specs = build_aircraft(random_scenario(n, seed=seed), np.random.default_rng(seed))
    assert all(len(s.waypoints) == 1 for s in specs)
    return {
        "ids": [s.id for s in specs],
        "start": [list(s.position) for s in specs],
        "heading": [math.radians(s.heading_deg) for s in specs],
        "speed": [s.speed for s in specs],
        "dest": [list(s.waypoints[0]) for s in specs],
    }


def run_ours(n, seed, steps, warmup):
    from airspace_sim.world.benchmark import bench_world

    r = bench_world(n, steps=steps, trackers=True, warmup=warmup, seed=seed, compare_imm=False)
    return {
        "sim_s_per_wall_s": r["steps_per_s"] * DT,
        "tracks": r["mean_tracks"],
        "peak_rss_mb": r.get("peak_rss_mb"),
        "ms_per_step": r["ms_per_step"],
    }


def run_bluesky(traffic, mode, steps, warmup, cd="ON"):
    """One BlueSky run on ``traffic`` (:func:`our_traffic`), ``mode`` a key of MODES."""
    import bluesky as bs
    from bluesky.traffic.asas import ConflictDetection

    bluesky_driver.reset(DT)
    bluesky_driver.create(
        [i.upper() for i in traffic["ids"]],  # the stack upper-cases callsigns
        np.array(traffic["start"]),
        np.array(traffic["heading"]),
        np.array(traffic["dest"]),
        np.array(traffic["speed"]),
    )
    bluesky_driver.configure_asas(R_SAFE, LOOKAHEAD, MARGIN, MODES[mode], cd=cd)
    bs.sim.step()  # processes the stack (t = DT)
    for _ in range(warmup):
        bs.sim.step()
    conf = 0
    t0 = time.perf_counter()
    for _ in range(steps):
        bs.sim.step()
        conf += len(bs.traf.cd.confpairs_unique)
    elapsed = time.perf_counter() - t0
    assert bs.traf.ntraf == len(traffic["ids"])
    return {
        "sim_s_per_wall_s": steps * DT / elapsed,
        "conflict_pairs": conf / steps,
        "ms_per_step": 1000.0 * elapsed / steps,
        "cd": ConflictDetection.selected().__name__,
    }


def bluesky_side(args):
    """Inside BlueSky's venv: one JSON line per mode."""
    import contextlib
    import io

    with open(args.traffic) as f:
        traffic = json.load(f)
    for mode in args.modes:
        with contextlib.redirect_stdout(io.StringIO()):  # BlueSky's chatter
            out = run_bluesky(traffic, mode, args.steps, args.warmup, args.bluesky_cd)
        print(json.dumps(dict(out, side=mode)), flush=True)
    return 0


def run_bluesky_subprocess(args, traffic_file, modes):
    cmd = [args.bluesky_python, os.path.abspath(__file__), "--side", "bluesky"]
    cmd += ["--traffic", traffic_file, "--modes", *modes, "--steps", str(args.steps)]
    cmd += ["--warmup", str(args.warmup), "--bluesky-cd", args.bluesky_cd]
    proc = subprocess.run(cmd, stdout=subprocess.PIPE, text=True, check=False)
    if proc.returncode:
        raise SystemExit(f"BlueSky side failed ({proc.returncode})")
    return [json.loads(line) for line in proc.stdout.splitlines() if line.startswith("{")]


def median(rows, key):
    vals = [r[key] for r in rows if r.get(key) is not None]
    return float(np.median(vals)) if vals else math.nan


def table(rows):
    lines = [
        "| aircraft | our tracks | ours | BlueSky detection only | BlueSky detection + MVP "
        "| ours / detection | ours / detection + MVP | BlueSky conflict pairs | our peak RSS |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for n in sorted({r["n"] for r in rows}):
        by = {s: [r for r in rows if r["n"] == n and r["side"] == s] for s in LABELS}
        med = {s: median(by[s], "sim_s_per_wall_s") for s in LABELS}
        tracks, rss = median(by["ours"], "tracks"), median(by["ours"], "peak_rss_mb")
        conf = median(by["detect"], "conflict_pairs")

        def fmt(x, spec="{:.3g}"):
            return "–" if math.isnan(x) else spec.format(x)

        lines.append(
            f"| {n} | {fmt(tracks / 1000, '{:.1f}k')} | {fmt(med['ours'])} | {fmt(med['detect'])} "
            f"| {fmt(med['mvp'])} | {fmt(med['ours'] / med['detect'], '{:.2f}')} "
            f"| {fmt(med['ours'] / med['mvp'], '{:.2f}')} | {fmt(conf, '{:.0f}')} "
            f"| {fmt(rss, '{:.0f} MB')} |"
        )
    counts = sorted(
        {
            sum(r["side"] == s and r["n"] == n for r in rows)
            for n in {r["n"] for r in rows}
            for s in LABELS
        }
        - {0}
    )
    lines.append("")
    lines.append(
        "Simulated seconds per wall second, medians of "
        + "/".join(map(str, counts))
        + " runs per system; ratios are ours over BlueSky's medians."
    )
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[100, 300, 1000])
    ap.add_argument("--repeats", type=int, default=4)
    ap.add_argument("--steps", type=int, default=60, help="timed 1 s steps per run")
    ap.add_argument("--warmup", type=int, default=5, help="untimed steps before them")
    ap.add_argument("--seed", type=int, default=0, help="traffic seed (same on both sides)")
    ap.add_argument("--bluesky-python", help="interpreter of the BlueSky venv (else ours only)")
    ap.add_argument(
        "--bluesky-cd",
        default="ON",
        help="BlueSky detection method (ON = STATEBASED, numpy; CSTATEBASED: its C++ one)",
    )
    ap.add_argument("--out", help="append the JSON lines to this file too")
    ap.add_argument("--table", metavar="JSONL", help="only print the table of earlier runs' lines")
    ap.add_argument("--side", choices=["both", "bluesky"], default="both", help=argparse.SUPPRESS)
    ap.add_argument("--traffic", help=argparse.SUPPRESS)
    ap.add_argument("--modes", nargs="+", choices=list(MODES), default=list(MODES))
    args = ap.parse_args(argv)
    if args.side == "bluesky":
        return bluesky_side(args)
    if args.table:
        with open(args.table) as f:
            print(table([json.loads(line) for line in f if line.startswith("{")]))
        return 0
    rows = []
    emit = bluesky_driver.emitter(rows, args.out)

    with tempfile.TemporaryDirectory() as tmp:
        for n in args.sizes:
            traffic_file = os.path.join(tmp, f"traffic{n}.json")
            with open(traffic_file, "w") as f:
                json.dump(our_traffic(n, args.seed), f)
            for rep in range(args.repeats):
                order = ["ours", "bluesky"] if rep % 2 == 0 else ["bluesky", "ours"]
                for who in order:
                    common = {"n": n, "repeat": rep, "seed": args.seed, "steps": args.steps}
                    if who == "ours":
                        emit(
                            dict(
                                run_ours(n, args.seed, args.steps, args.warmup),
                                **common,
                                side="ours",
                            )
                        )
                    elif args.bluesky_python:
                        for r in run_bluesky_subprocess(args, traffic_file, args.modes):
                            emit(dict(r, **common))
    print()
    print(table(rows))
    print(f"load average at the end: {os.getloadavg()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
