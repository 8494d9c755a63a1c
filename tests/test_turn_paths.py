"""turned_path_min_ratio (avoidance/turn_paths.py) against a fine numerical integration of the
turning intruder and a closed-form full circle."""

import numpy as np
import pytest

from airspace_sim.avoidance.turn_paths import turned_path_min_ratio, turned_path_min_ratio_numpy


def _integrated_min(vo, r, vi, psi, radius, T, w, turn_s, step):
    """(3,) min distance / radius on the grid t = 0, step, ..., T for straight, left, right,
    the intruder's heading integrated with 1 ms steps (midpoint rule), not the arc formula."""
    h = 1e-3
    n = int(round(T / h))
    tt = np.arange(n) * h + h / 2  # midpoints
    c, s = np.cos(psi), np.sin(psi)
    own = np.array([c * vo[0] - s * vo[1], s * vo[0] + c * vo[1]])
    grid = np.rint(np.unique(np.append(np.arange(0.0, T, step), T)) / h).astype(int)
    out = []
    for sign in (0.0, 1.0, -1.0):
        a = sign * w * np.minimum(tt, turn_s)
        vx = np.cos(a) * vi[0] - np.sin(a) * vi[1]
        vy = np.sin(a) * vi[0] + np.cos(a) * vi[1]
        px = np.concatenate([[0.0], np.cumsum(vx * h)])
        py = np.concatenate([[0.0], np.cumsum(vy * h)])
        t = grid * h
        dx = r[0] + px[grid] - own[0] * t
        dy = r[1] + py[grid] - own[1] * t
        out.append(np.hypot(dx, dy).min() / radius)
    return np.array(out)


def test_against_integration_of_random_encounters():
    rng = np.random.default_rng(3)
    n, k = 6, 2
    vo = rng.uniform(-250, 250, (n, 2))
    r = rng.uniform(-15000, 15000, (n, k, 2))
    v = rng.uniform(-400, 400, (n, k, 2))
    valid = np.ones((n, k), bool)
    valid[0, 1] = False
    psi = rng.uniform(-0.05, 0.05, (n, 3))
    radius = rng.uniform(3000, 8000, n)
    w = np.radians(rng.uniform(1.0, 4.0, n))
    got = turned_path_min_ratio(vo, r, v, valid, psi, radius, 100.0, w, 30.0, step_s=2.0)
    assert got.shape == (n, k, 3, 3)
    assert np.isinf(got[0, 1]).all()
    for i in range(n):
        for j in range(k):
            if not valid[i, j]:
                continue
            for c in range(3):
                want = _integrated_min(
                    vo[i], r[i, j], v[i, j] + vo[i], psi[i, c], radius[i], 100.0, w[i], 30.0, 2.0
                )
                np.testing.assert_allclose(got[i, j, :, c], want, atol=1e-3 / radius[i] * 1e3)
    # the hypotheses differ: turning is not straight
    assert (np.abs(got[valid][:, 1] - got[valid][:, 0]) > 0.01).any()


@pytest.mark.parametrize("sign", [1, 2])
def test_a_full_circle_around_a_still_ownship_is_closed_form(sign):
    # Ownship still at the origin; the intruder at r with velocity v turns for ever (turn_s
    # beyond the look-ahead, which covers a whole circle): its path is the circle of radius
    # |v|/w centred at r + J v / w (left; right: r - J v / w), whose nearest point to the
    # origin is | |centre| - |v|/w | away.
    w = np.radians(3.0)
    r = np.array([9000.0, -2000.0])
    v = np.array([150.0, 170.0])
    jv = np.array([-v[1], v[0]])
    centre = r + jv / w if sign == 1 else r - jv / w
    want = abs(np.hypot(*centre) - np.hypot(*v) / w)
    T = 2 * np.pi / w + 1.0
    got = turned_path_min_ratio(
        np.zeros((1, 2)),
        r[None, None],
        v[None, None],
        np.ones((1, 1), bool),
        np.zeros((1, 1)),
        1.0,
        T,
        w,
        10 * T,
        step_s=0.05,
    )[0, 0, sign, 0]
    assert got == pytest.approx(want, abs=0.5)  # m: sampling a 3 km circle every 0.05 s
    assert want < np.hypot(*r) - 300  # the circle comes closer than the start


def test_zero_turn_time_is_the_straight_path():
    rng = np.random.default_rng(8)
    vo = rng.uniform(-250, 250, (4, 2))
    r = rng.uniform(-9000, 9000, (4, 3, 2))
    v = rng.uniform(-400, 400, (4, 3, 2))
    got = turned_path_min_ratio(
        vo, r, v, np.ones((4, 3), bool), np.zeros((4, 2)), 3300.0, 120.0, 0.05, 0.0
    )
    np.testing.assert_array_equal(got[:, :, 1], got[:, :, 0])
    np.testing.assert_array_equal(got[:, :, 2], got[:, :, 0])


def test_the_kernel_matches_the_numpy_reference():
    rng = np.random.default_rng(13)
    n, k = 40, 7
    vo = rng.uniform(-250, 250, (n, 2))
    r = rng.uniform(-30000, 30000, (n, k, 2))
    v = rng.uniform(-450, 450, (n, k, 2))
    valid = rng.random((n, k)) < 0.7
    psi = rng.uniform(-0.1, 0.1, (n, 4))
    radius = rng.uniform(3000, 8000, n)
    w = np.radians(rng.uniform(0.0, 4.0, n))  # 0 included: the straight limit
    w[0] = 0.0
    args = (vo, r, v, valid, psi, radius, 120.0, w, 30.0)
    got, want = turned_path_min_ratio(*args), turned_path_min_ratio_numpy(*args)
    assert np.isinf(got[~valid]).all() and np.isinf(want[~valid]).all()
    np.testing.assert_allclose(got[valid], want[valid], rtol=1e-12)
