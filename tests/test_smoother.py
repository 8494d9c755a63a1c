"""The fixed-interval IMM smoother (tracking.smoother) against independent references.

- One linear mode: filterpy's ``KalmanFilter.rts_smoother``, states and covariances.
- One estimated-rate mode: an extended RTS smoother written here over a filterpy
  ``ExtendedKalmanFilter`` with the test's own coordinated turn and complex-step Jacobian.
- Identical modes: whatever the mode probabilities, the RTS smoother.
- Several modes: the exact smoother, a mixture over every mode sequence (a Kalman filter
  and RTS smoother per sequence, weighted by its posterior), on short records.
- Records of different lengths in one batch smooth as each alone.
- Fixed lag L: step k is the fixed-interval smoother's over the record up to k + L.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

filterpy = pytest.importorskip("filterpy")
from filterpy.kalman import ExtendedKalmanFilter, KalmanFilter  # noqa: E402
from test_imm_ct import f_ct  # noqa: E402  (the test's own coordinated turn)
from test_imm_ct import jac_complex_step as jac  # noqa: E402

from airspace_sim.dynamics import models, presets  # noqa: E402
from airspace_sim.errors import UserError  # noqa: E402
from airspace_sim.tracking import IMM, smooth  # noqa: E402

SIGMA = 100.0


def record(model, Z, x0, P0, mu0):
    """Run the IMM of ``model`` over Z (K, B, 2); its (mu, x_modes, P_modes) after each step."""
    imm = IMM(**model, x0=x0, P0=P0, mu0=mu0, gate_probability=1.0)
    mus, xs, Ps = [], [], []
    for z in Z:
        imm.step(z)
        mus.append(imm.mu.copy())
        xs.append(imm.x_modes.copy())
        Ps.append(imm.P_modes.copy())
    return np.array(mus), np.array(xs), np.array(Ps)


def straight_then_turn(rng, K, T, rate_deg=3.0, B=1, with_path=False):
    """Measurements (K, B, 2) of an aircraft at 150 m/s that turns at ``rate_deg`` halfway
    (and, ``with_path``, its positions (K, 2))."""
    x = np.array([0.0, 150.0, 0.0, 40.0, 0.0])
    zs, path = [], []
    for k in range(K):
        w = math.radians(rate_deg) if k >= K // 2 else 0.0
        h, v = math.atan2(x[3], x[1]) + w * T, math.hypot(x[1], x[3])
        x = x + [T * x[1], 0.0, T * x[3], 0.0, 0.0]
        x[1], x[3] = v * math.cos(h), v * math.sin(h)
        zs.append(x[[0, 2]] + rng.normal(0.0, SIGMA, (B, 2)))
        path.append(x[[0, 2]])
    return (np.array(zs), np.array(path)) if with_path else np.array(zs)


def start(B, omega_var=1e-4):
    """x0 (B, 5), P0 (B, 5, 5): trackers started at :func:`straight_then_turn`'s aircraft,
    100 m and 10 m/s sd, Ω = 0 with variance ``omega_var``."""
    x0 = np.tile([0.0, 150.0, 0.0, 40.0, 0.0], (B, 1))
    return x0, np.tile(np.diag([1e4, 100.0, 1e4, 100.0, omega_var]), (B, 1, 1))


def cv_model(sigma_a, T):
    """A one-mode constant-velocity model's IMM arguments."""
    F, Q = models.constant_velocity(T), models.white_noise_acceleration(sigma_a, T, 1e-3)
    return dict(transitions=F[None], process_noise=Q[None],
                measurement_matrix=models.position_measurement_matrix(),
                measurement_noise=models.measurement_noise(SIGMA), transition_matrix=[[1.0]])  # fmt: skip


def test_one_linear_mode_is_the_rts_smoother():
    rng = np.random.default_rng(1)
    T, K = 4.0, 40
    model = cv_model(2.0, T)
    F, Q = model["transitions"][0], model["process_noise"][0]
    H, R = model["measurement_matrix"], model["measurement_noise"]
    Z = straight_then_turn(rng, K, T)
    x0, P0 = np.array([0.0, 150.0, 0.0, 40.0, 0.0]), np.diag([1e4, 100.0, 1e4, 100.0, 1e-4])
    sm = smooth(*record(model, Z, x0[None], P0[None], [1.0]), model)
    kf = KalmanFilter(dim_x=5, dim_z=2)
    kf.x, kf.P, kf.F, kf.Q, kf.H, kf.R = x0.copy(), P0.copy(), F, Q, H, R
    xf, Pf, _, _ = kf.batch_filter(Z[:, 0])
    xs, Ps, _, _ = kf.rts_smoother(xf, Pf)
    np.testing.assert_allclose(sm.x[:, 0], xs, rtol=1e-9, atol=1e-7)
    np.testing.assert_allclose(sm.P_modes[:, 0, 0], Ps, rtol=1e-9, atol=1e-7)
    np.testing.assert_array_equal(sm.mu, 1.0)


def test_one_estimated_rate_mode_is_the_extended_rts_smoother():
    rng = np.random.default_rng(2)
    T, K = 4.0, 40
    p = presets.turn_rate(T).with_(measurement_sigma=SIGMA)
    a = p.imm_arguments()
    keep = [1]  # the estimated-rate mode alone
    model = dict(a, transitions=a["transitions"][keep], process_noise=a["process_noise"][keep],
                 transition_matrix=[[1.0]], offsets=a["offsets"][keep],
                 estimated_turn_rate=a["estimated_turn_rate"][keep])  # fmt: skip
    Q, H, R = model["process_noise"][0], model["measurement_matrix"], model["measurement_noise"]
    Z = straight_then_turn(rng, K, T, rate_deg=2.0)
    x0 = np.array([0.0, 150.0, 0.0, 40.0, 0.01])
    P0 = np.diag([1e4, 100.0, 1e4, 100.0, 1e-4])
    sm = smooth(*record(model, Z, x0[None], P0[None], [1.0]), model)

    ekf = ExtendedKalmanFilter(dim_x=5, dim_z=2)
    ekf.x, ekf.P, ekf.Q, ekf.R = x0[:, None].copy(), P0.copy(), Q.copy(), R.copy()
    xf, Pf = [], []
    for z in Z[:, 0]:
        ekf.F = jac(ekf.x[:, 0], T)
        ekf.x = f_ct(ekf.x[:, 0], T)[:, None]
        ekf.P = ekf.F @ ekf.P @ ekf.F.T + ekf.Q
        ekf.update(z[:, None], lambda x: H, lambda x: H @ x)
        xf.append(ekf.x[:, 0].copy())
        Pf.append(ekf.P.copy())
    xs, Ps = [xf[-1]], [Pf[-1]]
    for k in range(K - 2, -1, -1):  # the extended RTS smoother, Jacobian at the filtered state
        J = jac(xf[k], T)
        Pp = J @ Pf[k] @ J.T + Q
        G = Pf[k] @ J.T @ np.linalg.inv(Pp)
        xs.insert(0, xf[k] + G @ (xs[0] - f_ct(xf[k], T)))
        Ps.insert(0, Pf[k] + G @ (Ps[0] - Pp) @ G.T)
    np.testing.assert_allclose(sm.x[:, 0], np.array(xs), rtol=1e-7, atol=1e-6)
    np.testing.assert_allclose(sm.P_modes[:, 0, 0], np.array(Ps), rtol=1e-6, atol=1e-9)


def test_identical_modes_give_the_rts_smoother_whatever_their_probabilities():
    rng = np.random.default_rng(3)
    T, K = 4.0, 30
    one = cv_model(1.5, T)
    three = dict(one, transitions=np.repeat(one["transitions"], 3, 0),
                 process_noise=np.repeat(one["process_noise"], 3, 0),
                 transition_matrix=[[0.8, 0.15, 0.05], [0.1, 0.7, 0.2], [0.3, 0.3, 0.4]])  # fmt: skip
    Z = straight_then_turn(rng, K, T, B=2)
    x0, P0 = start(2)
    ref = smooth(*record(one, Z, x0, P0, [1.0]), one)
    sm = smooth(*record(three, Z, x0, P0, [0.2, 0.5, 0.3]), three)
    for j in range(3):
        np.testing.assert_allclose(sm.x_modes[:, :, j], ref.x_modes[:, :, 0], rtol=1e-9, atol=1e-6)
        np.testing.assert_allclose(sm.P_modes[:, :, j], ref.P_modes[:, :, 0], rtol=1e-9, atol=1e-6)
    np.testing.assert_allclose(sm.mu.sum(axis=2), 1.0, rtol=1e-12)


def exact_smoother(model, Z, x0, P0, mu0):
    """The exact smoothed mode probabilities (K, M) and mean states (K, n) of a jump-Markov
    linear model on one record Z (K, 2): every mode sequence's Kalman filter and RTS
    smoother (offsets u included), weighted by the sequence's posterior probability."""
    F, Q = np.asarray(model["transitions"]), np.asarray(model["process_noise"])
    U, Pi = np.asarray(model["offsets"]), np.asarray(model["transition_matrix"])
    H, R = model["measurement_matrix"], model["measurement_noise"]
    K, M = Z.shape[0], Pi.shape[0]
    logw, means = [], []
    for seq in itertools.product(range(M), repeat=K):
        prior = np.asarray(mu0) @ Pi
        lw = math.log(prior[seq[0]]) + sum(math.log(Pi[a, b]) for a, b in zip(seq, seq[1:]))
        x, P = x0.copy(), P0.copy()
        xf, Pf, xp, Pp = [], [], [], []
        for k, s in enumerate(seq):
            x, P = F[s] @ x + U[s], F[s] @ P @ F[s].T + Q[s]
            xp.append(x)
            Pp.append(P)
            S = H @ P @ H.T + R
            nu = Z[k] - H @ x
            lw += -0.5 * (nu @ np.linalg.solve(S, nu) + math.log(np.linalg.det(2 * math.pi * S)))
            Kg = P @ H.T @ np.linalg.inv(S)
            x, P = x + Kg @ nu, P - Kg @ S @ Kg.T
            xf.append(x)
            Pf.append(P)
        xs = [xf[-1]]
        for k in range(K - 2, -1, -1):
            G = Pf[k] @ F[seq[k + 1]].T @ np.linalg.pinv(Pp[k + 1])
            xs.insert(0, xf[k] + G @ (xs[0] - xp[k + 1]))
        logw.append(lw)
        means.append(np.array(xs))
    w = np.exp(np.array(logw) - max(logw))
    w /= w.sum()
    seqs = np.array(list(itertools.product(range(M), repeat=K)))
    mu = np.stack([np.bincount(seqs[:, k], weights=w, minlength=M) for k in range(K)])
    return mu, np.einsum("s,skn->kn", w, np.array(means))


@pytest.mark.parametrize("seed", [4, 5, 6])
def test_several_modes_approach_the_exact_smoother(seed):
    """Straight flight then a 3 °/s turn, the `realistic` model's three known-rate modes at
    4 s: the smoothed mode probabilities and states are, on average over the record, close
    to the exact ones and much closer than the filter's. (Not at every step: at the last
    one the smoother is the filter, whose IMM merging is itself an approximation.)"""
    d_mu_s, d_mu_f, d_x_s, d_x_f = exact_comparison(
        seed, lambda model, Z, x0, P0, mu0, T, rec: smooth(*rec, model)
    )
    assert d_mu_s < 0.2 and d_mu_s < 0.5 * d_mu_f
    assert d_x_s < 30.0 and d_x_s < 0.5 * d_x_f


def exact_comparison(seed, smoother):
    """Straight flight then a 3 °/s turn, 8 steps of 4 s, the `realistic` model: the mean
    over the steps of the summed |Δμ| and of the position distance to the exact smoother,
    of a smoother and of the filter (d_mu_s, d_mu_f, d_x_s, d_x_f). ``smoother(model, Z,
    x0, P0, mu0, T, record)`` returns a Smoothed; ``record`` is the filter's."""
    rng = np.random.default_rng(seed)
    T, K = 4.0, 8
    p = presets.realistic(T).with_(measurement_sigma=SIGMA)
    model = p.imm_arguments()
    Z = straight_then_turn(rng, K, T, rate_deg=3.0)
    x0, P0 = np.array([0.0, 150.0, 0.0, 40.0, 0.0]), np.diag([1e4, 25.0, 1e4, 25.0, 0.0])
    mu0 = p.mu0()
    P0_pd = P0[None] + 1e-12 * np.eye(5)
    rec = record(model, Z, x0[None], P0_pd, mu0)
    sm = smoother(model, Z, x0[None], P0_pd, mu0, T, rec)
    mu_exact, x_exact = exact_smoother(model, Z[:, 0], x0, P0, mu0)
    mu_f, x_f = rec[0], rec[1]
    filtered = np.einsum("km,kmn->kn", mu_f[:, 0], x_f[:, 0])
    return (
        np.abs(sm.mu[:, 0] - mu_exact).sum(axis=1).mean(),
        np.abs(mu_f[:, 0] - mu_exact).sum(axis=1).mean(),
        np.hypot(*(sm.x[:, 0] - x_exact)[:, [0, 2]].T).mean(),
        np.hypot(*(filtered - x_exact)[:, [0, 2]].T).mean(),
    )


@pytest.mark.parametrize("name", ["seed", "realistic", "dense-turns"])
def test_on_traffic_of_its_own_model_smoothing_beats_filtering(name):
    """Tracks of aircraft flying the preset's own jump-Markov model (the world's Markov
    autopilot): the smoothed positions are well inside the filter's error. (Barber's form at
    the smoothed mean, N(x_s; x⁻, P⁻), fails this with `realistic` and `dense-turns`: some
    tracks' smoothed estimates run hundreds of metres off.)"""
    from airspace_sim.dynamics import get_preset, simulate
    from airspace_sim.tracking import two_point_initialisation

    preset = get_preset(name)
    truth = simulate(preset, n_steps=300, n_targets=40, rng=np.random.default_rng(11))
    z = truth.measurements
    R = preset.measurement_sigma**2 * np.eye(2)
    x0, P0 = two_point_initialisation(z[0], z[1], preset.dt, R)
    imm = IMM.from_preset(preset, x0, P0)
    rec = []
    for zk in z[2:]:
        imm.step(zk)
        rec.append((np.array(imm.mu), imm.x_modes, imm.P_modes))
    mu, xm, Pm = (np.array(a) for a in zip(*rec))
    sm = smooth(mu, xm, Pm, preset.filter_model().imm_arguments())
    true_xy = truth.states[2:, :, [0, 2]]
    filtered = np.einsum("kbm,kbmn->kbn", mu, xm)
    err_f = np.sqrt(np.mean(np.sum((filtered[..., [0, 2]] - true_xy) ** 2, axis=-1)))
    err_s = np.sqrt(np.mean(np.sum((sm.x[..., [0, 2]] - true_xy) ** 2, axis=-1)))
    assert err_s < 0.8 * err_f


def test_records_of_different_lengths_smooth_as_each_alone():
    rng = np.random.default_rng(7)
    T, K = 4.0, 30
    p = presets.imm_ct(T).with_(measurement_sigma=SIGMA)
    model = p.imm_arguments()
    Z = straight_then_turn(rng, K, T, rate_deg=2.0, B=2)
    Z[20:, 1] = np.nan  # the second record ends after 20 steps
    x0, P0 = start(2)
    both = smooth(*record(model, Z, x0, P0, p.mu0()), model, n_steps=np.array([K, 20]))
    alone = smooth(*record(model, Z[:20, 1:], x0[1:], P0[1:], p.mu0()), model)
    np.testing.assert_allclose(both.x_modes[:20, 1], alone.x_modes[:, 0], rtol=1e-9, atol=1e-6)
    np.testing.assert_allclose(both.mu[:20, 1], alone.mu[:, 0], rtol=1e-9, atol=1e-12)
    first = smooth(*record(model, Z[:, :1], x0[:1], P0[:1], p.mu0()), model)
    np.testing.assert_allclose(both.x_modes[:, 0], first.x_modes[:, 0], rtol=1e-9, atol=1e-6)


def test_fixed_lag_is_the_fixed_interval_smoother_of_the_record_so_far(monkeypatch):
    """Step k with lag L is step k of the fixed-interval smoother over the steps up to k + L;
    lag 0 is the filter, a lag past the end the fixed-interval smoother; windows run in
    chunks as one."""
    from airspace_sim.tracking import smoother

    monkeypatch.setattr(smoother, "LAG_WINDOWS", 7)
    rng = np.random.default_rng(8)
    T, K, L = 4.0, 24, 3
    p = presets.imm_ct(T).with_(measurement_sigma=SIGMA)
    model = p.imm_arguments()
    Z = straight_then_turn(rng, K, T, rate_deg=2.0, B=2)
    Z[18:, 1] = np.nan
    x0, P0 = start(2)
    rec = record(model, Z, x0, P0, p.mu0())
    n = np.array([K, 18])
    lagged = smooth(*rec, model, n_steps=n, lag=L)
    for b in range(2):
        for k in range(n[b]):
            upto = min(k + L, n[b] - 1) + 1
            ref = smooth(*(a[:upto, b : b + 1] for a in rec), model)
            np.testing.assert_allclose(
                lagged.x_modes[k, b], ref.x_modes[k, 0], rtol=1e-9, atol=1e-6
            )
            np.testing.assert_allclose(lagged.mu[k, b], ref.mu[k, 0], rtol=1e-9, atol=1e-12)
    filt = smooth(*rec, model, n_steps=n, lag=0)
    for got, want in zip(filt, rec):
        np.testing.assert_array_equal(got, want)
    whole = smooth(*rec, model, n_steps=n)
    far = smooth(*rec, model, n_steps=n, lag=K)
    np.testing.assert_allclose(far.x_modes, whole.x_modes, rtol=1e-9, atol=1e-6)


def test_missed_detections_smooth_through():
    """Steps without a measurement (NaN rows: the filter only predicts) smooth like any other:
    finite, probabilities that sum to one, and closer to the path than the filter."""
    rng = np.random.default_rng(9)
    T, K, B = 4.0, 60, 8
    p = presets.imm_ct(T).with_(measurement_sigma=SIGMA)
    model = p.imm_arguments()
    Z, path = straight_then_turn(rng, K, T, rate_deg=2.0, B=B, with_path=True)
    Z[rng.random((K, B)) < 0.2] = np.nan
    x0, P0 = start(B)
    rec = record(model, Z, x0, P0, p.mu0())
    sm = smooth(*rec, model)
    assert np.all(np.isfinite(sm.x)) and np.allclose(sm.mu.sum(axis=2), 1.0)
    filtered = np.einsum("kbm,kbmn->kbn", rec[0], rec[1])
    err_f = np.sqrt(np.mean(np.sum((filtered[5:, :, [0, 2]] - path[5:, None]) ** 2, axis=-1)))
    err_s = np.sqrt(np.mean(np.sum((sm.x[5:, :, [0, 2]] - path[5:, None]) ** 2, axis=-1)))
    assert err_s < 0.8 * err_f


def test_bad_arguments_are_user_errors():
    p = presets.imm_ct(4.0)
    model = p.imm_arguments()
    mu, x, P = np.full((3, 1, 3), 1 / 3), np.zeros((3, 1, 3, 5)), np.zeros((3, 1, 3, 4, 4))
    with pytest.raises(UserError, match="do not match"):
        smooth(mu, x, P, model)
    with pytest.raises(UserError, match="n_steps"):
        smooth(mu, x, np.zeros((3, 1, 3, 5, 5)), model, n_steps=[3, 3])
    with pytest.raises(UserError, match="lag"):
        smooth(mu, x, np.zeros((3, 1, 3, 5, 5)), model, lag=-1)
    with pytest.raises(UserError, match="along-track"):
        smooth(mu, x, P, presets.imm_cta(4.0).imm_arguments())
