"""Why a ring's late aircraft are late: the life of each aircraft still flying at the end.

    python docs/benchmarks/late_arrivals_trace.py 64 0 KIND [--policy resume_rule='"no-worse"' ...]

Arguments as for ring_hold_trace.py (ring size, seed, ``kind:key=value``, policy knobs). For
each late aircraft (at most ``--show``): seconds in conflict, holding (or part-resuming) and
on its autopilot; when it last flew the policy, its distance to go, distance from the centre
and heading error from direct then; and every 60 s a cell ``S R/E``: S its state (C conflict,
H hold, A on its autopilot: direct or turning toward it), R its distance from the centre (km), E its heading error from direct
(deg, CCW positive). Last, when the whole fleet last held (10/50/90/100th percentiles).
"""

from __future__ import annotations

import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from ring_hold_trace import ring_arguments, ring_world  # noqa: E402

from airspace_sim.geometry import wrap_angle  # noqa: E402

DIRECT, CONFLICT, HOLD, GONE = 0, 1, 2, 3


def main(argv=None):
    ap = ring_arguments(__doc__)
    ap.add_argument("--show", type=int, default=12, help="late aircraft printed (default 12)")
    args = ap.parse_args(argv)
    sc, w, dest = ring_world(args)
    steps = int(round(sc.duration / sc.dt))
    state = np.full((steps, w.n), GONE, dtype=np.int8)
    radius, error, to_go = (np.zeros((steps, w.n)) for _ in range(3))
    for s in range(steps):
        w.step()
        flying = np.where(w.policy.conflict, CONFLICT, np.where(w.policy.following, HOLD, DIRECT))
        state[s] = np.where(w.active, flying, GONE)
        radius[s] = np.hypot(w.positions[:, 0], w.positions[:, 1]) / 1000.0
        to = dest - w.positions
        to_go[s] = np.hypot(to[:, 0], to[:, 1]) / 1000.0
        heading = np.arctan2(w.velocities[:, 1], w.velocities[:, 0])
        error[s] = np.degrees(wrap_angle(np.arctan2(to[:, 1], to[:, 0]) - heading))
    late = np.flatnonzero(w.active)
    print(f"{late.size} of {w.n} aircraft still flying at t = {steps * sc.dt:.0f} s")
    every = max(int(round(60.0 / sc.dt)), 1)
    for i in late[: args.show]:
        life = state[:, i]
        policy = np.flatnonzero((life == CONFLICT) | (life == HOLD))
        last = int(policy.max()) if policy.size else 0
        print(
            f"#{i}: conflict {np.sum(life == CONFLICT) * sc.dt:.0f} s, hold "
            f"{np.sum(life == HOLD) * sc.dt:.0f} s, autopilot {np.sum(life == DIRECT) * sc.dt:.0f} s;"
            f" last on the policy at t = {last * sc.dt:.0f} s: {to_go[last, i]:.1f} km to go, "
            f"{radius[last, i]:.1f} km from the centre, {error[last, i]:.0f} deg off direct; "
            f"{to_go[-1, i]:.1f} km to go at the end"
        )
        cells = (
            f"{t * sc.dt:.0f}:{'ACH-'[life[t]]}{radius[t, i]:.0f}/{error[t, i]:.0f}"
            for t in range(0, steps, every)
        )
        print("   ", " ".join(cells))
    last_hold = np.array(
        [np.flatnonzero(state[:, i] == HOLD).max(initial=-1) * sc.dt for i in range(w.n)]
    )
    q = np.percentile(last_hold, [10, 50, 90, 100])
    print(
        "last hold, s (10/50/90/100th percentile of the fleet):", " / ".join(f"{x:.0f}" for x in q)
    )
    m = w.metrics()
    print({k: m[k] for k in ("los_pairs", "nmac_pairs", "extra_path_pct", "not_arrived")})
    return 0


if __name__ == "__main__":
    sys.exit(main())
