"""Observation encoding and action decoding, on hand-made arrays (no world)."""

import math

import numpy as np
import pytest

from airspace_sim.env import spaces as sp
from airspace_sim.errors import UserError

LAYOUT = sp.ObservationLayout(
    n_intruders=3, n_modes=3, sensor_range=40000.0, r_safe=3000.0, lookahead=120.0
)


def test_layout_names_bounds_and_space():
    lay = LAYOUT
    assert lay.size == 14 + 3 * 14 == len(lay.names())
    low, high = lay.bounds()
    assert low.dtype == np.float32 and np.all(low < high) and np.all(np.isfinite(high))
    assert lay.names()[14] == "intruder0.mask" and lay.names()[-1] == "intruder2.mu2"
    assert lay.space().shape == (lay.size,)


def test_batch_matches_a_direct_computation():
    rng = np.random.default_rng(0)
    T = 14
    x = rng.normal(0, 10000, (T, 5))
    x[:, [1, 3]] = rng.normal(0, 200, (T, 2))
    A = rng.normal(size=(T, 5, 5))
    P = A @ A.transpose(0, 2, 1) * 1e4
    mu = rng.dirichlet([1, 1, 1], T)
    slot = rng.integers(0, 2, T)
    own_pos = rng.normal(0, 1000, (2, 2))
    own_vel = rng.normal(0, 200, (2, 2))
    hd = np.array([0.3, -2.0])
    b = sp.encode_intruders_batch(LAYOUT, slot, own_pos, own_vel, hd, x, P, mu)
    assert b.shape == (2, 3, 14)
    for a in range(2):
        r = x[slot == a]
        rp = np.stack([r[:, 0] - own_pos[a, 0], r[:, 2] - own_pos[a, 1]], 1)
        rv = np.stack([r[:, 1] - own_vel[a, 0], r[:, 3] - own_vel[a, 1]], 1)
        o = np.argsort(np.hypot(*rp.T))[:3]
        c, s = math.cos(hd[a]), math.sin(hd[a])
        R = np.array([[c, s], [-s, c]])  # world -> body (x forward, y left)
        assert np.all(b[a, :, 0] == 1)
        assert np.allclose(b[a, :, 1:3], (rp[o] @ R.T) / 40000)
        assert np.allclose(b[a, :, 3:5], (rv[o] @ R.T) / 600)
        cov = R @ P[slot == a][o][:, [0, 2]][:, :, [0, 2]] @ R.T
        assert np.allclose(b[a, :, 6], np.sqrt(cov[:, 0, 0]) / 3000)
        assert np.allclose(b[a, :, 8], cov[:, 0, 1] / np.sqrt(cov[:, 0, 0] * cov[:, 1, 1]))
        assert np.allclose(b[a, :, 11:], mu[slot == a][o])
        # single-ownship form agrees
        one = sp.encode_intruders(
            LAYOUT, own_pos[a], own_vel[a], hd[a], r, P[slot == a], mu[slot == a]
        )
        assert np.allclose(one, b[a])


def test_geometry_of_a_head_on_intruder():
    # ownship at the origin heading north at 200 m/s; intruder 10 km north heading south
    x = np.array([[0.0, 0.0, 10000.0, -200.0, 0.0]])
    P = np.diag([100.0**2, 1, 50.0**2, 1, 1e-6])[None]
    rows = sp.encode_intruders(
        LAYOUT, np.zeros(2), np.array([0.0, 200.0]), math.pi / 2, x, P, np.array([[1.0, 0, 0]])
    )
    r = rows[0]
    assert np.allclose(r[1:3], [10000 / 40000, 0], atol=1e-12)  # dead ahead
    assert np.allclose(r[3:5], [-400 / 600, 0], atol=1e-12)  # closing
    # body frame: the east error (σ 100 m) is across track (y), the north one along (x)
    assert np.allclose(r[6:8], [50 / 3000, 100 / 3000])
    assert np.isclose(r[9], 25 / 120) and np.isclose(r[10], 0)  # tcpa 25 s, miss 0
    assert np.all(rows[1:] == 0)


def test_padding_non_finite_tracks_and_clipping():
    x = np.array([[np.nan, 0, 0, 0, 0], [1e9, 0, 0, 0, 0]])
    P = np.tile(np.eye(5), (2, 1, 1))
    rows = sp.encode_intruders(LAYOUT, np.zeros(2), np.zeros(2), 0.0, x, P, np.ones((2, 3)) / 3)
    assert rows[0, 0] == 1 and np.all(rows[1:] == 0)  # the NaN track is skipped
    obs = sp.finish(LAYOUT, np.full(14, 5.0), rows)
    assert obs.dtype == np.float32 and LAYOUT.space().contains(obs)
    assert obs[15] == 1.0  # 1e9 m ahead clipped to 1


def test_decode_action():
    # normalised: a fraction of the turn-rate limit, clipped to [-1, 1]
    assert sp.decode_action("a", np.array([0.2], np.float32), False) == pytest.approx(0.2)
    assert sp.decode_action("a", [3.0], False) == 1.0
    assert sp.decode_action("a", -7, False) == -1.0
    assert sp.decode_action("a", 0, True) == 1.0  # hard left = CCW
    assert sp.decode_action("a", 4, True) == -1.0
    assert sp.decode_action("a", np.int64(2), True) == 0.0
    assert sp.decode_action("a", np.array(1), True) == 0.5
    # the built-in pilot: None, or the discrete BUILTIN_ACTION
    assert math.isnan(sp.decode_action("a", None, False))
    assert math.isnan(sp.decode_action("a", sp.BUILTIN_ACTION, True))
    for bad in ([np.nan], [np.inf], np.array([-np.inf], np.float32)):
        with pytest.raises(UserError, match="agent 'a'"):
            sp.decode_action("a", bad, False)
    with pytest.raises(UserError, match="one number"):
        sp.decode_action("a", [0.0, 0.0], False)
    with pytest.raises(UserError, match="0..5"):
        sp.decode_action("a", 6, True)
    with pytest.raises(UserError, match="0..5"):
        sp.decode_action("a", 1.5, True)
