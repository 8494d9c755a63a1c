"""Where a ring's detour comes from: every 20 s, how many aircraft are in conflict (flying the
resolver's advice) and how many hold their heading because the turn back is refused.

    python docs/benchmarks/ring_hold_trace.py 64 0 bands [--policy resume_margin=0.3]

Arguments: ring size, seed, resolver kind (``kind:key=value`` as in resolver_candidates.py).
Prints per line: active aircraft, in conflict, holding, mean and max heading error from
direct-to-destination (deg), mean and min distance from the centre (km); then the metrics.
"""

from __future__ import annotations

import argparse
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from resolver_candidates import scenario  # noqa: E402

from airspace_sim.geometry import wrap_angle  # noqa: E402
from airspace_sim.world import World  # noqa: E402


def ring_arguments(doc: str) -> argparse.ArgumentParser:
    """The arguments of a ring trace: ring size, seed, resolver kind, ``--policy`` knobs."""
    ap = argparse.ArgumentParser(description=doc.split("\n\n")[0])
    ap.add_argument("n", type=int)
    ap.add_argument("seed", type=int)
    ap.add_argument("kind")
    ap.add_argument("--policy", nargs="*", default=[], metavar="KEY=VALUE")
    return ap


def ring_world(args):
    """``(scenario, world, destinations (N, 2) m)`` of the ring ``args`` name (a ring's
    aircraft fly to the opposite point)."""
    sc, _ = scenario(f"ring:{args.n}:{args.seed}", args.kind, args.policy)
    w = World(sc, seed=args.seed)
    return sc, w, -w.positions.copy()


def main(argv=None):
    args = ring_arguments(__doc__).parse_args(argv)
    sc, w, dest = ring_world(args)
    for s in range(int(round(sc.duration / sc.dt))):
        w.step()
        a = w.active
        if not a.any():
            break
        if s % 20:
            continue
        to = dest - w.positions
        err = np.degrees(
            np.abs(
                wrap_angle(
                    np.arctan2(to[:, 1], to[:, 0])
                    - np.arctan2(w.velocities[:, 1], w.velocities[:, 0])
                )
            )
        )[a]
        conflict = w.policy.conflict & a
        hold = w.policy.following & ~w.policy.conflict & a
        rad = np.hypot(w.positions[:, 0], w.positions[:, 1])[a] / 1000
        print(
            f"t={s:4d} active={a.sum():3d} conflict={conflict.sum():3d} hold={hold.sum():3d} "
            f"heading error mean={err.mean():5.1f} max={err.max():5.1f} deg "
            f"radius mean={rad.mean():6.1f} min={rad.min():6.1f} km"
        )
    m = w.metrics()
    print({k: m[k] for k in ("los_pairs", "nmac_pairs", "extra_path_pct", "not_arrived")})
    return 0


if __name__ == "__main__":
    sys.exit(main())
