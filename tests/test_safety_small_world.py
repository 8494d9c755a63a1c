"""Safety metrics of small worlds (all pairs of up to 32 active aircraft tested at once,
no grid; world/metrics.py) against brute-force scalar re-computations."""

import numpy as np
import pytest
from test_safety_metrics import _predicted_scalar, _wcv_scalar

from airspace_sim.world.bodies import LOS, NMAC, RANGE
from airspace_sim.world.metrics import WorldMetrics


@pytest.mark.parametrize("n, active_share", [(2, 1.0), (12, 0.8), (32, 0.9), (33, 1.0)])
def test_small_world_flags_match_brute_force(n, active_share):
    rng = np.random.default_rng(n)
    r_safe, look = 3000.0, 120.0
    pos = rng.uniform(-12000, 12000, (n, 2))
    vel = rng.uniform(-250, 250, (n, 2))
    following = rng.random(n) < 0.2
    active = rng.random(n) < active_share
    active[:2] = True
    m = WorldMetrics(n, r_safe, 152.4, 1.0)
    none = {t: np.zeros(0, np.int64) for t in (LOS, NMAC, RANGE)}
    began = {t: np.zeros((0, 2), np.int64) for t in (LOS, NMAC, RANGE)}
    m.contacts(pos, none, began)
    m.conflicts(np.zeros(n, bool))
    m.safety(0.0, pos, vel, active, following, look)
    wcv, pred = set(), set()
    for i in range(n):
        for j in range(i + 1, n):
            if not (active[i] and active[j]):
                continue
            s, v = pos[j] - pos[i], vel[j] - vel[i]
            if _wcv_scalar(s, v):
                wcv.add(i * n + j)
            if not following[i] and not following[j] and _predicted_scalar(s, v, r_safe, look):
                pred.add(i * n + j)
    if n >= 12:
        assert wcv and pred
    assert m.wcv_events == m.wcv_pair_steps == len(wcv)
    assert set(m._wcv_prev.tolist()) == wcv
    assert len(m._predicted) == len(pred)
    if pred:
        assert (m._predicted.get(np.array(sorted(pred))) >= 0).all()
