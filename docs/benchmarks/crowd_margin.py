"""``resolver_candidates.py`` with one more resolver kind, ``bands-flown-crowd`` (an
experiment, not a shipped resolver): ``bands-flown`` whose clear radius grows to
``r_safe·(1 + crowd_margin)`` for an ownship with at least ``crowd_count`` tracks within
``crowd_range_m`` (``per_intruder = true``: only for those near tracks), through the
resolver's ``clear_radius`` hook. The world's prefilter is off (it tests the scenario's
radius). Measured on dense_random in docs/resolvers.md (twelfth part)::

    python docs/benchmarks/crowd_margin.py dense:0-63 --set resolver.margin=0.1 \\
        --kinds bands-flown-crowd:K1[:per_intruder=true]

Arguments as ``resolver_candidates.py``'s.
"""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass

import numpy as np

from airspace_sim import registry
from airspace_sim.avoidance.flown_bands import FlownBandsResolver
from airspace_sim.parts import param

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import resolver_candidates  # noqa: E402


@registry.register("resolver", "bands-flown-crowd")
class CrowdFlownBandsResolver(FlownBandsResolver):
    """``bands-flown`` with a larger clear radius in a crowd (module docstring)."""

    @dataclass(frozen=True)
    class Params(FlownBandsResolver.Params):
        crowd_range_m: float = param(12000.0, unit="m", doc="a crowd's range", gt=0.0)
        crowd_count: int = param(2, doc="tracks within crowd_range_m that make a crowd", ge=1)
        crowd_margin: float = param(0.2, doc="the margin in a crowd", ge=0.0)
        per_intruder: bool = param(False, doc="the crowd margin only for the near tracks")

    prefilter = False

    def clear_radius(self, vo, r, v, valid):
        """(N, K) m: ``r_safe·(1 + crowd_margin)`` in a crowd, ``r_safe·(1 + margin)`` else."""
        p = self.params
        near = valid & (np.hypot(r[..., 0], r[..., 1]) < p.crowd_range_m)
        crowded = (near.sum(axis=1) >= p.crowd_count)[:, None]
        crowded = crowded & near if p.per_intruder else np.broadcast_to(crowded, valid.shape)
        return p.r_safe * (1.0 + np.where(crowded, p.crowd_margin, p.margin))


if __name__ == "__main__":
    sys.exit(resolver_candidates.main())
