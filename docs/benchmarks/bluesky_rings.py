"""Side by side on the converging ring: our resolver on IMM tracks vs BlueSky's MVP on truth.

    python docs/benchmarks/bluesky_rings.py --sizes 32 64 --seeds 0-4 \\
        --bluesky-python /path/to/bluesky-venv/bin/python [--jitter 50] [--out rows.jsonl] \\
        [--ours shipped|bands]

Run it with the project's venv (``airspace_sim`` importable); BlueSky (``pip install
bluesky-simulator==1.1.1``) lives in its own venv, given by ``--bluesky-python``, and this
file re-runs itself there with ``--side bluesky``. Neither side imports the other.

The same traffic on both sides (:func:`ring_traffic`): ``n`` aircraft evenly on a circle of
radius ``max(1.1·r_safe / sin(π/n), 20 km)`` (:func:`airspace_sim.world.benchmark.
ring_scenario`'s default), each at 230 m/s heading for the diametrically opposite point,
with optional start jitter (``--jitter`` m, uniform in a disc, drawn from the seed; the
destination stays the unjittered opposite point). r_safe 3000 m, look-ahead 120 s, margin
10%, run for ``2R/v + 300 s`` with 1 s steps.

- ours: :func:`~airspace_sim.world.benchmark.ring_scenario` (IMM tracks from σ = 50 m
  measurements, heading only, 3°/s) with ``--ours``' resolver: ``shipped`` (default) the
  whole ``[resolver]`` of ``scenarios/ring.toml`` (kind, params, margin, resume rule), or
  ``bands`` with the policy's defaults; metrics from ``World.metrics()``.
- BlueSky 1.1.1: ``ASAS ON``, ``RESO MVP`` (heading *and* speed, its default; ``--mvp-hdg``
  for heading only), ``ZONER`` = r_safe, ``DTLOOK`` 120 s, ``RFACH`` 1.1, true states, its
  own turn and speed dynamics (OpenAP B744 at FL200, CAS set for 230 m/s TAS), each
  aircraft on a one-waypoint route (``ADDWPT``) so that it resumes after a resolution. The
  positions are on BlueSky's sphere (R = 6371 km, centre 0°N 0°E), read back to metres with
  the flat-earth formula BlueSky's resolution uses.

Measured alike on both sides, every 1 s step: ``los_pairs`` (distinct pairs ever closer
than r_safe), ``nmac_pairs`` (< 152.4 m), ``extra_pct`` (100·Σ(flown − planned covered)/Σ
planned covered), arrivals (an aircraft arrives within one step's travel of its
destination, or once past abeam of it, and leaves), ``delay_mean_s`` / ``delay_max_s``
(arrival time − straight time ``2R/v``, over the arrived), ``not_arrived`` (still flying at
the end). One JSON line per (side, n, seed), then a Markdown table of medians and ranges.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import time

import bluesky_driver  # docs/benchmarks/, next to this file (sys.path[0])
import numpy as np

R_SAFE, NMAC, SPEED, LOOKAHEAD, MARGIN, DT = 3000.0, 152.4, 230.0, 120.0, 0.1, 1.0


def ring_traffic(n: int, seed: int, jitter: float = 0.0):
    """``(start (n, 2) m, heading (n,) rad CCW from east, dest (n, 2) m, radius m,
    duration s)`` of the ring (module docstring)."""
    radius = max(1.1 * R_SAFE / math.sin(math.pi / n), 20000.0)
    a = 2 * math.pi * np.arange(n) / n
    p0 = radius * np.stack([np.cos(a), np.sin(a)], axis=1)
    dest = -p0
    start = p0.copy()
    if jitter > 0:
        rng = np.random.default_rng([seed, n, 7])
        r = jitter * np.sqrt(rng.uniform(size=n))
        t = rng.uniform(0, 2 * math.pi, n)
        start += np.stack([r * np.cos(t), r * np.sin(t)], axis=1)
    heading = np.arctan2(dest[:, 1] - start[:, 1], dest[:, 0] - start[:, 0])
    duration = math.ceil(2 * radius / SPEED + 300.0)
    return start, heading, dest, radius, duration


class Tally:
    """The metrics of the module docstring from true positions sampled every step."""

    def __init__(self, start, dest):
        self.n = len(start)
        self.start, self.dest = start, dest
        self.plan = np.hypot(*(dest - start).T)
        self.flown = np.zeros(self.n)
        self.arrival = np.full(self.n, np.nan)
        self.los, self.nmac = set(), set()
        self.prev = start.copy()

    def sample(self, t, pos, flying):
        """t s; pos (n, 2) m; flying (n,) bool. Returns (n,) bool: arrived now."""
        self.flown += np.where(flying, np.hypot(*(pos - self.prev).T), 0.0)
        self.prev = pos.copy()
        idx = np.flatnonzero(flying)
        if idx.size > 1:
            d = np.hypot(*(pos[idx, None, :] - pos[None, idx, :]).transpose(2, 0, 1))
            i, j = np.nonzero(np.triu(d < R_SAFE, 1))
            self.los.update(zip(idx[i].tolist(), idx[j].tolist()))
            i, j = np.nonzero(np.triu(d < NMAC, 1))
            self.nmac.update(zip(idx[i].tolist(), idx[j].tolist()))
        to = self.dest - pos
        near = np.hypot(*to.T) <= SPEED * DT
        passed = np.einsum("ij,ij->i", to, self.dest - self.start) < 0
        now = flying & (near | passed)
        self.arrival[now] = t
        return now

    def result(self, pos, flying):
        covered = np.where(flying, self.plan - np.hypot(*(self.dest - pos).T), self.plan)
        arrived = np.isfinite(self.arrival)
        delay = self.arrival[arrived] - self.plan[arrived] / SPEED
        return {
            "los_pairs": len(self.los),
            "nmac_pairs": len(self.nmac),
            "extra_pct": 100.0 * float((self.flown - covered).sum() / covered.sum()),
            "delay_mean_s": float(delay.mean()) if delay.size else math.nan,
            "delay_max_s": float(delay.max()) if delay.size else math.nan,
            "not_arrived": int(np.count_nonzero(flying)),
        }


#: ``--ours`` → the side's label in the rows and the table
OURS = {"shipped": "ours (ring.toml, IMM)", "bands": "ours (bands, IMM)"}


def our_scenario(n, seed, ours="shipped", **kw):
    """``ring_scenario(n, seed=seed, **kw)`` with ``ours``' resolver: ``"shipped"`` the whole
    ``[resolver]`` of ``scenarios/ring.toml``, ``"bands"`` the generator's own."""
    import dataclasses

    from airspace_sim.scenarios import load
    from airspace_sim.world.benchmark import ring_scenario

    sc = ring_scenario(n, seed=seed, **kw)
    if ours == "shipped":
        sc = dataclasses.replace(sc, resolver=load("ring").resolver)
    return sc


def run_ours(n, seed, jitter, ours="shipped"):
    """Our world on the ring, IMM tracks, ``ours``' resolver (module docstring)."""
    import dataclasses

    from airspace_sim.scenarios import build_aircraft
    from airspace_sim.world import World

    start, heading, dest, radius, duration = ring_traffic(n, seed, jitter)
    sc = our_scenario(n, seed, ours, radius=radius, duration=duration)
    specs = None  # unjittered: the generator's own specs, bit for bit
    if jitter > 0:
        specs = [
            dataclasses.replace(s, position=tuple(p), heading_deg=math.degrees(h))
            for s, p, h in zip(build_aircraft(sc, np.random.default_rng(seed)), start, heading)
        ]
    w = World(sc, seed=seed, aircraft=specs)
    tally = Tally(start, dest)
    while not w.done:
        flying = w.active.copy()  # an aircraft that arrives in a step leaves in it
        w.step()
        tally.sample(w.time, w.positions, flying)
    m = w.metrics()
    out = tally.result(w.positions, w.active)
    # the world's own numbers agree with the tally (same definitions)
    out["world_los_pairs"], out["world_not_arrived"] = m["los_pairs"], m["not_arrived"]
    return out


def run_bluesky(n, seed, jitter, hdg_only=False):
    """BlueSky MVP on the ring, true states (module docstring)."""
    import bluesky as bs

    bluesky_driver.reset(DT)
    start, heading, dest, radius, duration = ring_traffic(n, seed, jitter)
    ids = [f"R{i}" for i in range(n)]
    bluesky_driver.create(ids, start, heading, dest, SPEED)
    bluesky_driver.configure_asas(R_SAFE, LOOKAHEAD, MARGIN, "MVP", hdg_only)
    bs.sim.step()  # processes the stack (t = DT)
    tally = Tally(start, dest)
    flying = np.ones(n, dtype=bool)
    pos = start.copy()
    t = float(bs.sim.simt)
    while t < duration and flying.any():
        bs.sim.step()
        t = float(bs.sim.simt)
        pos = pos.copy()
        live = [bs.traf.id2idx(a) for a in ids]
        for i, k in enumerate(live):
            if k >= 0:
                pos[i] = bluesky_driver.metres(bs.traf.lat[k : k + 1], bs.traf.lon[k : k + 1])[0]
        done = tally.sample(t, pos, flying)
        for i in np.flatnonzero(done):
            bs.stack.stack(f"DEL {ids[i]}")
        flying &= ~done
    return tally.result(pos, flying)


def parse_seeds(text):
    out = []
    for part in text.split(","):
        a, _, b = part.partition("-")
        out.extend(range(int(a), int(b) + 1) if b else [int(a)])
    return out


def table(rows):
    def span(vals, fmt):
        vals = [v for v in vals if not (isinstance(v, float) and math.isnan(v))]
        if not vals:
            return "–"
        lo, hi = min(vals), max(vals)
        return fmt.format(lo) if lo == hi else f"{fmt.format(lo)}–{fmt.format(hi)}"

    keys = sorted({(r["n"], r["jitter"]) for r in rows})
    lines = [
        "| aircraft | jitter m | side | LoS pairs per run | NMAC pairs | extra path % "
        "| mean delay s | max delay s | not arrived |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for n, jit in keys:
        for side in (*OURS.values(), "BlueSky MVP (truth)"):
            rs = [r for r in rows if r["n"] == n and r["jitter"] == jit and r["side"] == side]
            if not rs:
                continue
            lines.append(
                f"| {n} | {jit:g} | {side} | {', '.join(str(r['los_pairs']) for r in rs)} "
                f"| {span([r['nmac_pairs'] for r in rs], '{}')} "
                f"| {span([r['extra_pct'] for r in rs], '{:.0f}')} "
                f"| {span([r['delay_mean_s'] for r in rs], '{:.0f}')} "
                f"| {span([r['delay_max_s'] for r in rs], '{:.0f}')} "
                f"| {span([r['not_arrived'] for r in rs], '{}')} |"
            )
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[32, 64, 100, 200])
    ap.add_argument("--seeds", default="0-4")
    ap.add_argument("--jitter", type=float, default=0.0, help="start jitter, m (disc radius)")
    ap.add_argument("--bluesky-python", help="interpreter of the BlueSky venv (else ours only)")
    ap.add_argument("--mvp-hdg", action="store_true", help="MVP heading-only (RMETHH HDG)")
    ap.add_argument("--side", choices=["both", "ours", "bluesky"], default="both")
    ap.add_argument("--out", help="append the JSON lines to this file too")
    ap.add_argument(
        "--ours", choices=sorted(OURS), default="shipped", help="our resolver (module docstring)"
    )
    args = ap.parse_args(argv)
    seeds = parse_seeds(args.seeds)
    if args.side == "bluesky":  # inside the BlueSky venv: one JSON line per run
        import contextlib
        import io

        for n in args.sizes:
            out = None
            for seed in seeds:
                t0 = time.perf_counter()
                # true states and no jitter: the seed changes nothing, so run it once
                if out is None or args.jitter > 0:
                    with contextlib.redirect_stdout(io.StringIO()):  # BlueSky's chatter
                        out = run_bluesky(n, seed, args.jitter, args.mvp_hdg)
                    out["wall_s"] = round(time.perf_counter() - t0, 1)
                    first = seed
                else:
                    out = dict(out, same_as_seed=first)
                out.update(n=n, seed=seed, jitter=args.jitter, side="BlueSky MVP (truth)")
                print(json.dumps(out), flush=True)
        return 0
    rows = []
    emit = bluesky_driver.emitter(rows, args.out)

    for n in args.sizes:
        if args.side in ("both", "ours"):
            for seed in seeds:
                t0 = time.perf_counter()
                out = run_ours(n, seed, args.jitter, args.ours)
                out.update(n=n, seed=seed, jitter=args.jitter, side=OURS[args.ours])
                out["wall_s"] = round(time.perf_counter() - t0, 1)
                emit(out)
        if args.side in ("both", "bluesky") and args.bluesky_python:
            cmd = [
                args.bluesky_python,
                os.path.abspath(__file__),
                "--side",
                "bluesky",
                "--sizes",
                str(n),
                "--seeds",
                args.seeds,
                "--jitter",
                str(args.jitter),
            ]
            cmd += ["--mvp-hdg"] if args.mvp_hdg else []
            proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True)
            for line in proc.stdout:
                if line.startswith("{"):
                    emit(json.loads(line))
            if proc.wait():
                raise SystemExit(f"BlueSky side failed ({proc.returncode})")
    print()
    print(table(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
