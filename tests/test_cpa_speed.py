"""Minimum distance with the ownship turning and changing speed (avoidance/cpa_speed.py)
against a brute-force oracle (the path's velocity integrated by the trapezoid rule every 5 ms),
the closed-form straight CPA, and the turning kernel at constant speed; the knots' spacing."""

import math

import numpy as np
import pytest

from airspace_sim.avoidance.cpa import cpa_min_ratio
from airspace_sim.avoidance.cpa_intruder_turning import cpa_min_ratio_intruder_turning
from airspace_sim.avoidance.cpa_speed import _knot_bound, _knots, _piece, cpa_min_ratio_speed

RATE = math.radians(3.0)
RADIUS = 3300.0


def _scene(seed, n=10, k=5, c=7, p=4):
    rng = np.random.default_rng(seed)
    vo = rng.normal(size=(n, 2))
    vo *= rng.uniform(180, 260, (n, 1)) / np.linalg.norm(vo, axis=1, keepdims=True)
    r = rng.uniform(-12000, 12000, (n, k, 2))
    vi = rng.normal(size=(n, k, 2))
    vi *= rng.uniform(180, 260, (n, k, 1)) / np.linalg.norm(vi, axis=-1, keepdims=True)
    valid = rng.random((n, k)) < 0.8
    cand = np.radians(rng.uniform(-90, 90, (n, c)))
    speeds = np.linalg.norm(vo, axis=1, keepdims=True) * rng.uniform(0.7, 1.3, (n, p))
    return vo, r, vi - vo[:, None], valid, cand, speeds


def _oracle(vo, r, v, valid, cand, speeds, accel, lookahead):
    t = np.linspace(0.0, lookahead, int(lookahead * 200) + 1)
    dt = t[1] - t[0]
    out = np.full(cand.shape + (speeds.shape[1],), np.inf)
    for i in range(cand.shape[0]):
        s0, h0 = np.hypot(*vo[i]), math.atan2(vo[i, 1], vo[i, 0])
        for j, psi in enumerate(cand[i]):
            h = h0 + math.copysign(1.0, psi) * np.minimum(RATE * t, abs(psi))
            for q, s1 in enumerate(speeds[i]):
                s = s0 + math.copysign(1.0, s1 - s0) * np.minimum(accel * t, abs(s1 - s0))
                vx, vy = s * np.cos(h), s * np.sin(h)
                ox = np.concatenate([[0.0], np.cumsum(0.5 * (vx[1:] + vx[:-1]) * dt)])
                oy = np.concatenate([[0.0], np.cumsum(0.5 * (vy[1:] + vy[:-1]) * dt)])
                for k in np.flatnonzero(valid[i]):
                    vi = v[i, k] + vo[i]
                    d = np.hypot(r[i, k, 0] + vi[0] * t - ox, r[i, k, 1] + vi[1] * t - oy)
                    out[i, j, q] = min(out[i, j, q], d.min() / RADIUS)
    return out


@pytest.mark.parametrize("seed, accel", [(0, 0.5), (1, 1.0), (2, 3.0)])
def test_matches_the_integrated_oracle(seed, accel):
    vo, r, v, valid, cand, speeds = _scene(seed)
    n = vo.shape[0]
    got = cpa_min_ratio_speed(
        vo, r, v, valid, cand, speeds, RADIUS, 60.0, np.full(n, RATE), np.full(n, accel)
    )
    want = _oracle(vo, r, v, valid, cand, speeds, accel, 60.0)
    # one-second chords of 3°/s arcs at up to 340 m/s depart from them by under 3 m
    np.testing.assert_allclose(got, want, atol=4.0 / RADIUS, rtol=0)


def test_piece_is_the_integral_through_small_turns():
    """The closed form and the midpoint branch agree on either side of the switch."""
    for w in (0.99e-4 / 10.0, 1.01e-4 / 10.0, 1e-3, RATE):
        x, y = _piece(230.0, 0.3, w, 0.8, 10.0)
        u = np.linspace(0.0, 10.0, 200001)
        s, h = 230.0 + 0.8 * u, 0.3 + w * u
        want = np.trapezoid(s * np.cos(h), u), np.trapezoid(s * np.sin(h), u)
        np.testing.assert_allclose((x, y), want, atol=1e-6)


def test_current_speed_is_the_turning_kernel():
    """Target speed = current speed: the ownship-only turning path (sampled every second
    there, at the chord tolerance here: both within 2 m of the arc)."""
    vo, r, v, valid, cand, _ = _scene(3)
    n, k = valid.shape
    here = np.linalg.norm(vo, axis=1, keepdims=True)
    rate = np.full(n, RATE)
    got = cpa_min_ratio_speed(vo, r, v, valid, cand, here, RADIUS, 90.0, rate, np.full(n, 0.5))
    want = cpa_min_ratio_intruder_turning(
        vo, r, v, valid, cand, RADIUS, 90.0, rate, np.zeros((n, k)), 0.0
    )
    np.testing.assert_allclose(got[:, :, 0], want, atol=4.0 / RADIUS, rtol=0)


@pytest.mark.parametrize("tolerance_m", [0.25, 8.0])
def test_the_chord_tolerance_bounds_the_error(tolerance_m):
    """Against the integrated oracle the error stays within the tolerance asked for (the
    minimum distance moves by at most the path's distance from its chords)."""
    vo, r, v, valid, cand, speeds = _scene(6)
    n = vo.shape[0]
    rate, acc = np.full(n, RATE), np.full(n, 1.0)
    got = cpa_min_ratio_speed(
        vo, r, v, valid, cand, speeds, RADIUS, 60.0, rate, acc, tolerance_m=tolerance_m
    )
    want = _oracle(vo, r, v, valid, cand, speeds, 1.0, 60.0)
    err = np.abs(got - want)[np.isfinite(want)] * RADIUS
    assert err.max() <= tolerance_m + 0.05


@pytest.mark.parametrize(
    "s0, s1, rate, tau_h, a, tau_s, lookahead",
    [
        (230.0, 260.0, RATE, 20.0, 0.5, 60.0, 120.0),  # turn ends first
        (207.7, 269.6, RATE, 23.4, 3.0, 20.6, 60.0),  # speed change ends first
        (230.0, 230.0, 0.0, 0.0, 0.0, 0.0, 120.0),  # straight: two knots
        (230.0, 200.0, -RATE, 50.0, -0.5, 60.0, 40.0),  # cut by the look-ahead
    ],
)
def test_knots_end_each_phase_and_keep_to_the_tolerance(s0, s1, rate, tau_h, a, tau_s, lookahead):
    tol = 2.0
    buf = np.empty(4096)
    m = _knots(s0, s1, rate, tau_h, a, tau_s, lookahead, tol, buf)
    t = buf[:m]
    assert t[0] == 0.0 and t[-1] == lookahead and np.all(np.diff(t) > 0.0)
    for end in (tau_h, tau_s):
        if 0.0 < end < lookahead:
            assert np.any(np.abs(t - end) < 1e-12)
    # within the manoeuvre each gap keeps g·Δt²/8 ≤ tol, g the phase's largest acceleration
    mid = 0.5 * (t[1:] + t[:-1])
    g = np.hypot(np.where(mid < tau_h, max(s0, s1) * rate, 0.0), np.where(mid < tau_s, a, 0.0))
    manoeuvre = mid < min(max(tau_h, tau_s), lookahead)
    assert np.all(g[manoeuvre] * np.diff(t)[manoeuvre] ** 2 / 8.0 <= tol * (1 + 1e-9))
    assert np.count_nonzero(~manoeuvre) <= 1  # one straight piece to the look-ahead
    # the kernel's buffer, sized once per call, holds them
    one = np.ones(1)
    assert m <= _knot_bound(
        np.array([[s0, 0.0]]), s1 * one, abs(rate) * one, abs(a) * one, lookahead, tol
    )


def test_at_once_is_the_closed_form_cpa():
    """Heading and speed taken at once: a straight relative track, the closed-form CPA of the
    new velocity."""
    vo, r, v, valid, cand, speeds = _scene(4)
    n = vo.shape[0]
    got = cpa_min_ratio_speed(
        vo, r, v, valid, cand, speeds, RADIUS, 120.0, np.full(n, np.inf), np.full(n, np.inf)
    )
    for q in range(speeds.shape[1]):
        scale = speeds[:, q] / np.linalg.norm(vo, axis=1)
        vn = vo * scale[:, None]
        vi = v + vo[:, None]
        want = cpa_min_ratio(vn, r, vi - vn[:, None], valid, cand, RADIUS, 120.0)
        np.testing.assert_allclose(got[:, :, q], want, atol=1e-9)


def test_nan_candidates_and_no_intruders():
    vo, r, v, valid, cand, speeds = _scene(5)
    n = vo.shape[0]
    cand[:, 0] = np.nan
    got = cpa_min_ratio_speed(vo, r, v, valid, cand, speeds, RADIUS, 30.0, RATE, 0.5)
    assert np.isnan(got[valid.any(axis=1), 0]).all()
    none = cpa_min_ratio_speed(
        vo, r[:, :0], v[:, :0], valid[:, :0], cand[:, 1:], speeds, RADIUS, 30.0, RATE, 0.5
    )
    assert none.shape == (n, cand.shape[1] - 1, speeds.shape[1]) and np.isinf(none).all()
    with pytest.raises(ValueError, match="tolerance_m"):
        cpa_min_ratio_speed(vo, r, v, valid, cand, speeds, RADIUS, 30.0, RATE, 0.5, tolerance_m=0)
