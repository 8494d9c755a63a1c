"""The pairwise avoidability oracle of docs/benchmarks/loss_trace.py (one_turn_avoids)."""

import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "docs", "benchmarks"))
from loss_trace import one_turn_avoids  # noqa: E402

V, W, R_SAFE = 230.0, np.radians(3.0), 3000.0
T = np.arange(0, 301)[:, None]  # s


def test_a_pair_already_inside_r_safe_cannot_be_saved():
    other = np.array([1000.0, 0.0]) + T * [V, 0.0]  # in formation 1 km ahead
    assert not one_turn_avoids(np.zeros(2), 0.0, V, W, other, 1.0, R_SAFE)


def test_straight_fails_but_a_turn_avoids_a_head_on_with_a_2_km_offset():
    other = np.array([20000.0, 2000.0]) + T * [-V, 0.0]
    # tau = 0 (straight) misses by 2 km: a loss; turning right away from the offset works
    d_straight = np.hypot(*(other - T * [V, 0.0]).T).min()
    assert d_straight < R_SAFE
    assert one_turn_avoids(np.zeros(2), 0.0, V, W, other, 1.0, R_SAFE)
    assert not one_turn_avoids(np.zeros(2), 0.0, V, W, other, 1.0, R_SAFE, max_tau_s=0.0)


def test_too_late_to_turn_a_head_on_closing_at_460_m_s_from_4_km():
    # closed form for the best case: even a 90-degree heading change is not reached in time;
    # over 8.7 s to the crossing, a 3 deg/s turn displaces the ownship by about
    # V*w*t^2/2 ~ 460 m sideways, far from the 3 km needed
    other = np.array([4000.0, 0.0]) + T * [-V, 0.0]
    assert not one_turn_avoids(np.zeros(2), 0.0, V, W, other, 1.0, R_SAFE)
