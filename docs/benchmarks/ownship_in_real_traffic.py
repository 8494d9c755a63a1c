"""A simulated ownship crosses recorded traffic: the paper's detection and avoidance against
real flights (its §VII future work), with and without avoidance, for a choice of trackers.

    python docs/benchmarks/ownship_in_real_traffic.py [--sample switzerland] [--cases 40] \\
        [--kinds none bands scenarios/ring.toml] [--tracker realistic imm-ct] [--out rows.jsonl]
    python docs/benchmarks/ownship_in_real_traffic.py --summarize rows.jsonl ...

Each case (seeded, the same for every kind and tracker): a start time in the recording, an
entry point on a circle of ``--radius`` m around the data's centre, and an exit point on the
far side, ``--offset`` m to either side of the centre at most; the ownship (``route``
autopilot, ``--speed`` m/s, 3 °/s turns) flies from one to the other through the recorded
traffic (``recorded.min_altitude_ft``, default 10000 ft: the world is 2-D, so en-route
traffic only). Only the ownship tracks and runs the resolver (``recorded.track = false``);
the recorded aircraft never avoid. A kind is a resolver kind with the default ``[resolver]``
settings, or a scenario file whose whole ``[resolver]`` table is used (``scenarios/ring.toml``:
the shipped intent resolver and its policy). One JSON line per case × kind × tracker: the
ownship's losses of separation with real aircraft (pairs closer than r_safe) and, for each,
when the intruder came into the world and when the loss began (an aircraft climbing through
``min_altitude_ft`` or starting its recording appears at once, perhaps near the ownship:
the summary counts the losses to intruders that came in under a look-ahead before, and those
that began within :data:`WARM_UP_S` of the ownship's own appearance), its closest approach,
alerts, extra path and whether it arrived; then a summary per kind × tracker.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time

import numpy as np

from airspace_sim.recorded.scenario import load_flights
from airspace_sim.scenarios import from_dict
from airspace_sim.world import World


def arguments(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    src = ap.add_mutually_exclusive_group()
    src.add_argument("--sample", default="switzerland", help="traffic wheel collection")
    src.add_argument("--file", help="a trajectory file instead (any format replay reads)")
    ap.add_argument("--cases", type=int, default=40)
    ap.add_argument("--seed", type=int, default=0, help="seed of the cases")
    ap.add_argument(
        "--kinds", nargs="+", default=["none", "bands", "scenarios/ring.toml"],
        help="resolver kinds, or scenario files whose [resolver] table to use",
    )  # fmt: skip
    ap.add_argument("--tracker", nargs="+", default=["realistic", "imm-ct"], help="presets")
    ap.add_argument(
        "--centre", nargs=2, type=float, metavar=("LAT", "LON"),
        help="centre of the crossings, degrees (default: the data's centre)",
    )  # fmt: skip
    ap.add_argument("--radius", type=float, default=60000.0, help="entry circle radius, m")
    ap.add_argument("--offset", type=float, default=20000.0, help="exit offset, m")
    ap.add_argument("--speed", type=float, default=230.0, help="ownship ground speed, m/s")
    ap.add_argument("--min-altitude-ft", type=float, default=10000.0)
    ap.add_argument("--r-safe", type=float, default=3000.0)
    ap.add_argument("--out", help="also append the JSON lines to this file")
    ap.add_argument(
        "--summarize", nargs="+", metavar="JSONL", help="only print the summary of these lines"
    )
    return ap.parse_args(argv)


def cases(a, span_s: float):
    """(start_s, entry (2,) m, exit (2,) m) per case, from ``a.seed``."""
    rng = np.random.default_rng(a.seed)
    crossing_s = 2.0 * a.radius / a.speed
    out = []
    for _ in range(a.cases):
        start = float(rng.uniform(0.0, max(span_s - crossing_s - 300.0, 0.0)))
        theta = float(rng.uniform(0.0, 2.0 * math.pi))
        side = float(rng.uniform(-a.offset, a.offset))
        u = np.array([math.cos(theta), math.sin(theta)])
        entry = a.radius * u
        exit_ = -a.radius * u + side * np.array([-u[1], u[0]])
        out.append((start, entry, exit_))
    return out


def resolver_table(kind: str) -> dict:
    """``[resolver]`` of a kind: ``{"kind": kind}``, or a scenario file's whole table."""
    if not kind.endswith(".toml"):
        return {"kind": kind}
    import tomllib

    from airspace_sim.scenarios import resolve

    with open(resolve(kind), "rb") as f:
        return tomllib.load(f)["resolver"]


def scenario(a, start, entry, exit_, kind, tracker):
    heading = math.degrees(math.atan2(exit_[1] - entry[1], exit_[0] - entry[0]))
    duration = math.ceil(np.hypot(*(exit_ - entry)) / a.speed + 300.0)
    data = {
        "name": "ownship in real traffic",
        "duration": float(duration),
        "separation": {"r_safe": a.r_safe},
        "tracker": {"model": tracker},
        "resolver": resolver_table(kind),
        "recorded": {
            "file": a.file or f"traffic:{a.sample}",
            "start_s": start,
            "min_altitude_ft": a.min_altitude_ft,
            "track": False,
            **(
                {}
                if a.centre is None
                else dict(zip(("centre_lat_deg", "centre_lon_deg"), a.centre))
            ),
        },
        "aircraft": [
            {
                "id": "own",
                "position": [float(entry[0]), float(entry[1])],
                "heading_deg": heading,
                "speed": a.speed,
                "autopilot": "route",
                "waypoints": [[float(exit_[0]), float(exit_[1])]],
            }
        ],
    }
    return from_dict(data, "<ownship_in_real_traffic>")


def fly(sc):
    """The ownship's figures: run the world, watching its distance to every real aircraft."""
    w = World(sc)
    own = w.index("own")
    closest = np.full(w.n, np.inf)
    entered = np.where(w.active, 0.0, np.nan)  # s: when each aircraft came into the world
    lost = np.full(w.n, np.nan)  # s: when it first came within r_safe of the ownship
    while not w.done and w.active[own]:
        w.step()
        entered = np.where(np.isnan(entered) & w.active, w.time, entered)
        d = np.hypot(*(w.positions - w.positions[own]).T)
        d[own] = np.inf
        closest = np.where(w.active, np.minimum(closest, d), closest)
        lost = np.where(np.isnan(lost) & w.active & (d < sc.separation.r_safe), w.time, lost)
    m = w.metrics()
    los = np.isfinite(lost)
    return {
        "los_pairs": int(np.count_nonzero(los)),
        # per loss: when the intruder came into the world and when the loss began, s
        "los_entered_s": [round(float(v)) for v in entered[los]],
        "los_at_s": [round(float(v)) for v in lost[los]],
        "closest_m": round(float(closest.min()), 1),
        "alerts": m["alerts"],
        "extra_path_pct": m["extra_path_pct"],
        "arrived": m["arrived"],
        "aircraft": w.n - 1,
    }


def sc_lookahead(kind: str) -> float:
    """The look-ahead (s) a kind's resolver runs with."""
    return from_dict({"name": "k", "resolver": resolver_table(kind)}).resolver.lookahead


#: s: a loss that begins this soon after the ownship appears at its entry point (at t = 0,
#: perhaps beside a real aircraft) is counted apart: no detection could have prevented it
WARM_UP_S = 30.0


def summary(rows) -> None:
    """One line per kind × tracker of ``rows`` (the JSON lines), in the order they come."""
    for kind, tracker in dict.fromkeys((x["kind"], x["tracker"]) for x in rows):
        r = [x for x in rows if x["kind"] == kind and x["tracker"] == tracker]
        losses = [(e, t) for x in r for e, t in zip(x["los_entered_s"], x["los_at_s"])]
        start = sum(t < WARM_UP_S for _, t in losses)
        lookahead = sc_lookahead(kind)
        late = sum(0 < e and t - e < lookahead for e, t in losses)
        path = [x["extra_path_pct"] for x in r if x["arrived"]]
        print(
            f"{kind} {tracker}: {len(r)} crossings, LoS pairs {len(losses)} in "
            f"{sum(x['los_pairs'] > 0 for x in r)} ({start} within {WARM_UP_S:g} s of the "
            f"start, {late} with an intruder that came into the world under a look-ahead "
            f"before), closest median {np.median([x['closest_m'] for x in r]):.0f} m, min "
            f"{min(x['closest_m'] for x in r):.0f} m; alerts {sum(x['alerts'] for x in r)}; "
            f"arrived {len(path)}/{len(r)}, their extra path median {np.median(path):.2f}%, "
            f"mean {np.mean(path):.2f}%"
        )


def main(argv=None) -> int:
    a = arguments(argv)
    if a.summarize:
        summary([json.loads(line) for f in a.summarize for line in open(f) if line.strip()])
        return 0
    probe = scenario(a, 0.0, np.zeros(2), np.ones(2), "none", "realistic")
    flights = load_flights(probe.recorded, probe.source)
    todo = cases(a, flights.end_s - flights.start_s)
    rows = []
    for i, (start, entry, exit_) in enumerate(todo):
        for tracker in a.tracker:
            for kind in a.kinds:
                t0 = time.perf_counter()
                row = {"case": i, "start_s": round(start), "kind": kind, "tracker": tracker}
                row.update(fly(scenario(a, start, entry, exit_, kind, tracker)))
                row["wall_s"] = round(time.perf_counter() - t0, 1)
                rows.append(row)
                line = json.dumps(row)
                print(line, flush=True)
                if a.out:
                    with open(a.out, "a") as out:  # a killed run keeps its lines
                        print(line, file=out)
    summary(rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
