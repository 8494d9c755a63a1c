"""Batched Kalman filter against filterpy 2.0.0's KalmanFilter, tracker by tracker."""

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter as FPKalmanFilter
from scipy.linalg import solve_discrete_are

from airspace_sim.dynamics import models, presets, simulate
from airspace_sim.errors import UserError
from airspace_sim.tracking.kalman import KalmanFilter


def _random_model(rng, n, m):
    F = np.eye(n) + 0.3 * rng.standard_normal((n, n))
    A = rng.standard_normal((n, n))
    Q = A @ A.T * 0.1 + 0.01 * np.eye(n)
    H = rng.standard_normal((m, n))
    C = rng.standard_normal((m, m))
    R = C @ C.T + np.eye(m)
    return F, Q, H, R


def _filterpy(F, Q, H, R, x0, P0):
    kf = FPKalmanFilter(dim_x=F.shape[0], dim_z=H.shape[0])
    kf.F, kf.Q, kf.H, kf.R = F.copy(), Q.copy(), H.copy(), R.copy()
    kf.x, kf.P = x0.reshape(-1, 1).copy(), P0.copy()
    return kf


def _assert_close(a, b, rtol=1e-9):
    scale = np.maximum(np.abs(b), np.abs(b).max() * 1e-6)
    assert np.all(np.abs(a - b) <= rtol * scale), np.max(np.abs(a - b) / scale)


@pytest.mark.parametrize("n,m", [(5, 2), (4, 2), (3, 1), (6, 3)])
def test_matches_filterpy_random_models(n, m):
    rng = np.random.default_rng(n * 10 + m)
    F, Q, H, R = _random_model(rng, n, m)
    F /= max(1.0, np.abs(np.linalg.eigvals(F)).max())  # keep it stable over 60 steps
    B, T = 7, 60
    x0 = rng.standard_normal((B, n))
    A = rng.standard_normal((B, n, n))
    P0 = A @ np.swapaxes(A, 1, 2) + np.eye(n)
    kf = KalmanFilter(F, Q, H, R, x0, P0)
    refs = [_filterpy(F, Q, H, R, x0[b], P0[b]) for b in range(B)]
    for _k in range(T):
        z = rng.standard_normal((B, m)) * 3
        z[rng.random(B) < 0.2] = np.nan  # missed detections: predict only
        kf.step(z)
        for b, ref in enumerate(refs):
            ref.predict()
            if np.isnan(z[b]).any():
                assert np.isnan(kf.nis[b])
            else:
                ref.update(z[b])
                assert kf.nis[b] == pytest.approx(ref.mahalanobis**2, rel=1e-9)
            _assert_close(kf.x[b], ref.x[:, 0])
            _assert_close(kf.P[b], ref.P)


def test_matches_filterpy_on_cv_tracking_of_realistic_truth():
    p = presets.get("realistic")
    B, T = 5, 200
    tr = simulate(p, T, B, np.random.default_rng(9))
    F = models.constant_velocity(p.dt)[:4, :4]
    Q = models.white_noise_acceleration(3.0, p.dt)[:4, :4]
    H = models.position_measurement_matrix()[:, :4]
    R = models.measurement_noise(p.measurement_sigma)
    x0 = tr.states[0, :, :4] + np.array([30.0, 5.0, -30.0, -5.0])
    P0 = np.diag([2500.0, 400.0, 2500.0, 400.0])
    kf = KalmanFilter(F, Q, H, R, x0, P0)
    refs = [_filterpy(F, Q, H, R, x0[b], P0) for b in range(B)]
    for k in range(1, T):
        kf.step(tr.measurements[k])
        for b, ref in enumerate(refs):
            ref.predict()
            ref.update(tr.measurements[k, b])
    for b, ref in enumerate(refs):
        _assert_close(kf.x[b], ref.x[:, 0])
        _assert_close(kf.P[b], ref.P)


def test_steady_state_covariance_is_the_riccati_solution():
    """The prior covariance converges to the discrete algebraic Riccati equation's solution."""
    dt, sa, s = 1.0, 2.0, 50.0
    F = models.constant_velocity(dt)[:4, :4]
    Q = models.white_noise_acceleration(sa, dt)[:4, :4] + 1e-9 * np.eye(4)
    H = models.position_measurement_matrix()[:, :4]
    R = models.measurement_noise(s)
    kf = KalmanFilter(F, Q, H, R, np.zeros((2, 4)), np.eye(4) * 1e6)
    for _ in range(500):
        kf.step(np.zeros((2, 2)))
    prior = F @ kf.P[0] @ F.T + Q
    expect = solve_discrete_are(F.T, H.T, Q, R)
    np.testing.assert_allclose(prior, expect, rtol=1e-6, atol=1e-9 * np.abs(expect).max())


def test_nan_rows_predict_only_and_all_nan():
    F, Q = models.constant_velocity(1.0), models.white_noise_acceleration(1.0, 1.0, 0.01)
    H, R = models.position_measurement_matrix(), models.measurement_noise()
    x0 = np.array([[0.0, 100.0, 0.0, 0.0, 0.0]] * 3)
    kf = KalmanFilter(F, Q, H, R, x0, np.eye(5) * 100.0)
    kf.step(np.full((3, 2), np.nan))
    np.testing.assert_allclose(kf.x, x0 @ F.T)
    np.testing.assert_allclose(kf.P, np.broadcast_to(F @ (np.eye(5) * 100) @ F.T + Q, (3, 5, 5)))
    assert np.all(np.isnan(kf.nis))
    kf.step(np.array([[100.0, 0.0], [np.nan, 0.0], [200.0, np.inf]]))
    assert np.isnan(kf.nis[1]) and np.isnan(kf.nis[2]) and np.isfinite(kf.nis[0])
    assert kf.P[1, 0, 0] > kf.P[0, 0, 0]


def test_append_remove_keep_rows_independent():
    rng = np.random.default_rng(4)
    F, Q, H, R = _random_model(rng, 4, 2)
    F /= max(1.0, np.abs(np.linalg.eigvals(F)).max())
    x0 = rng.standard_normal((5, 4))
    P0 = np.eye(4)
    a = KalmanFilter(F, Q, H, R, x0, P0)
    b = KalmanFilter(F, Q, H, R, x0[[0, 2, 4]], P0)
    zs = rng.standard_normal((10, 5, 2))
    for z in zs[:5]:
        a.step(z)
        b.step(z[[0, 2, 4]])
    a.remove([1, 3])
    np.testing.assert_array_equal(a.x, b.x)
    new = a.append(x0[:2], np.broadcast_to(P0, (2, 4, 4)))
    np.testing.assert_array_equal(new, [3, 4])
    assert a.B == 5 and a.P.shape == (5, 4, 4) and a.nis.shape == (5,)
    c = KalmanFilter(F, Q, H, R, x0[:2], P0)
    for z in zs[5:]:
        a.step(z)
        b.step(z[:3])
        c.step(z[3:])
    np.testing.assert_allclose(a.x[:3], b.x, rtol=1e-12)
    np.testing.assert_allclose(a.x[3:], c.x, rtol=1e-12)


def test_shape_errors():
    F = np.eye(4)
    with pytest.raises(UserError, match="shapes"):
        KalmanFilter(F, np.eye(5), np.ones((2, 4)), np.eye(2), np.zeros((1, 4)), np.eye(4))
    with pytest.raises(UserError, match="x0"):
        KalmanFilter(F, np.eye(4), np.ones((2, 4)), np.eye(2), np.zeros((1, 5)), np.eye(4))
    with pytest.raises(UserError, match="P0"):
        KalmanFilter(F, np.eye(4), np.ones((2, 4)), np.eye(2), np.zeros((1, 4)), np.eye(3))
    with pytest.raises(UserError, match="finite"):
        KalmanFilter(F, np.eye(4), np.ones((2, 4)), np.eye(2), np.full((1, 4), np.nan), np.eye(4))
