"""The ring's roundabout drawn: every aircraft's position and heading at a few times, for the
shipped ring resolver with and without its off-course waiver (``resume_off_course_deg``).

    python docs/benchmarks/plot_ring_roundabout.py --n 64 --seed 0 --times 180 420 660 \\
        --out docs/ring_off_course.png
    python docs/benchmarks/plot_ring_roundabout.py --n 100 --seed 4 --shipped-only \\
        --times 360 600 720 840 --highlight 43 46 --out docs/ring100_late.png

Both rows fly ``scenarios/ring.toml``'s whole ``[resolver]`` on :func:`ring_scenario`'s ring
(IMM tracks from σ = 50 m); the upper row with the waiver off (180°: no heading is that far off
course), left out with ``--shipped-only``. Arrows: orange holds or part-resumes (the CDA
policy's ``following`` while clear), red in conflict, green on its route; grey, the last 90 s
of each track; dashed, the ring of destinations; in blue the aircraft given by
``--highlight``, with a dotted line to their destination. Positions in km.
"""

from __future__ import annotations

import argparse
import dataclasses

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from airspace_sim.scenarios import load  # noqa: E402
from airspace_sim.world import World  # noqa: E402
from airspace_sim.world.benchmark import ring_scenario  # noqa: E402


def snapshots(n, seed, times, off_course_deg):
    """Destinations (N, 2) m (a ring's aircraft fly to the opposite point) and, at each of
    ``times``, (t s, positions (N, 2) m, velocities (N, 2) m/s, active, conflict, following,
    trail (≤ 90, N, 2) m)."""
    sc = ring_scenario(n)
    resolver = dataclasses.replace(load("ring").resolver, resume_off_course_deg=off_course_deg)
    w = World(dataclasses.replace(sc, resolver=resolver), seed=seed)
    dest = -w.positions.copy()
    trail, out = [], []
    for step in range(1, max(times) + 1):
        w.step()
        trail = (trail + [w.positions.copy()])[-90:]
        if step in times:
            p = w.policy
            out.append(
                (step, w.positions.copy(), w.velocities.copy(), w.active.copy(),
                 p.conflict.copy(), p.following.copy(), np.array(trail))
            )  # fmt: skip
    return dest, out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=64)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--times", type=int, nargs="+", default=[180, 420, 660])
    ap.add_argument("--out", default="ring_off_course.png")
    ap.add_argument("--highlight", type=int, nargs="*", default=[], help="aircraft indices")
    ap.add_argument("--shipped-only", action="store_true", help="only the shipped row")
    args = ap.parse_args(argv)
    shipped = load("ring").resolver.resume_off_course_deg
    rows = [
        ("no waiver", 180.0),
        (f"resume_off_course_deg = {shipped:g} (shipped)", shipped),
    ][1 if args.shipped_only else 0 :]
    radius_km = ring_scenario(args.n).traffic.radius / 1000.0
    fig, axs = plt.subplots(
        len(rows), len(args.times), figsize=(4 * len(args.times), 4.2 * len(rows)), squeeze=False
    )
    for r, (label, deg) in enumerate(rows):
        dest, snaps = snapshots(args.n, args.seed, args.times, deg)
        for c, (t, pos, vel, on, conflict, following, trail) in enumerate(snaps):
            ax = axs[r, c]
            colour = np.where(conflict, "tab:red", np.where(following, "tab:orange", "tab:green"))
            for i in np.flatnonzero(on):
                ax.plot(trail[:, i, 0] / 1e3, trail[:, i, 1] / 1e3, "-", color="0.8", lw=0.6)
            for i in args.highlight:
                if on[i]:
                    ax.plot(
                        trail[:, i, 0] / 1e3, trail[:, i, 1] / 1e3, "-", color="tab:blue", lw=1.5
                    )
                    x, y = pos[i] / 1e3
                    ax.plot([x, dest[i, 0] / 1e3], [y, dest[i, 1] / 1e3], ":", color="tab:blue")
                    ax.annotate(str(i), (x, y), color="tab:blue", fontsize=9)
            p = pos[on] / 1e3
            ax.quiver(p[:, 0], p[:, 1], vel[on, 0], vel[on, 1], color=colour[on], scale=5000,
                      width=0.005)  # fmt: skip
            ax.add_patch(plt.Circle((0, 0), radius_km, fill=False, ls="--", color="tab:blue"))
            lim = 1.45 * radius_km
            ax.set(xlim=(-lim, lim), ylim=(-lim, lim), aspect="equal")
            holding = int((following & ~conflict & on).sum())
            ax.set_title(f"t = {t} s: {int(on.sum())} flying, {holding} holding", fontsize=10)
            if c == 0:
                ax.set_ylabel(f"{label}\nkm", fontsize=10)
    fig.suptitle(
        f"{args.n}-ring, seed {args.seed}: orange holds or part-resumes, red in conflict, "
        "green on its route",
        fontsize=11,
    )
    fig.tight_layout()
    fig.savefig(args.out, dpi=70)
    print(args.out)


if __name__ == "__main__":
    main()
