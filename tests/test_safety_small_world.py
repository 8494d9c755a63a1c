"""Safety metrics of small worlds (all pairs of up to 32 active aircraft tested at once,
no grid; world/metrics.py) against brute-force scalar re-computations."""

import numpy as np
import pytest
from test_safety_metrics import safety_and_brute_force


@pytest.mark.parametrize("n, active_share", [(2, 1.0), (12, 0.8), (32, 0.9), (33, 1.0)])
def test_small_world_flags_match_brute_force(n, active_share):
    rng = np.random.default_rng(n)
    r_safe, look = 3000.0, 120.0
    pos = rng.uniform(-12000, 12000, (n, 2))
    vel = rng.uniform(-250, 250, (n, 2))
    following = rng.random(n) < 0.2
    active = rng.random(n) < active_share
    active[:2] = True
    m, wcv, pred = safety_and_brute_force(pos, vel, active, following, r_safe, look)
    if n >= 12:
        assert wcv and pred
    assert m.wcv_events == m.wcv_pair_steps == len(wcv)
    assert set(m._wcv_prev.tolist()) == wcv
    assert len(m._predicted) == len(pred)
    if pred:
        assert (m._predicted.get(np.array(sorted(pred))) >= 0).all()
