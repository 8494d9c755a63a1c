"""The two-filter IMM smoother (tracking.two_filter) against independent references.

- One linear mode: filterpy's ``KalmanFilter.rts_smoother`` (equal to 1 cm but near the
  record's end, where the backward filter starts from two points).
- Several modes: the exact smoother by enumeration of every mode sequence
  (``test_smoother.exact_comparison``), on short records.
- Traffic flying the model itself: the smoothed positions beat the filter's and the
  expectation-correction smoother's, fixed-interval and with a 10-step lag (whose
  fixed-interval positions are worse than its 10-step lag's on this traffic).
- A record reflected (y → −y) smooths to the reflection, left and right modes swapped.
- The time-reversed model: its chain has the forward one's stationary distribution and
  reversed twice is the forward chain.
- Fixed lag L: step k is the fixed-interval smoother's over the record up to its window's
  end; on traffic of the model itself the positions improve with every step of lag.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

filterpy = pytest.importorskip("filterpy")
from filterpy.kalman import KalmanFilter  # noqa: E402
from test_smoother import SIGMA, cv_model, exact_comparison, record, start, straight_then_turn  # noqa: E402

from airspace_sim.dynamics import presets  # noqa: E402
from airspace_sim.dynamics.markov import stationary_law  # noqa: E402
from airspace_sim.errors import UserError  # noqa: E402
from airspace_sim.tracking import smooth, smooth_two_filter  # noqa: E402
from airspace_sim.tracking.two_filter import MIRROR, mirror_modes, reversed_model  # noqa: E402


def test_one_linear_mode_is_the_rts_smoother():
    rng = np.random.default_rng(1)
    T, K = 4.0, 40
    model = cv_model(2.0, T)
    Z = straight_then_turn(rng, K, T)
    x0, P0 = np.array([0.0, 150.0, 0.0, 40.0, 0.0]), np.diag([1e4, 100.0, 1e4, 100.0, 1e-4])
    kf = KalmanFilter(dim_x=5, dim_z=2)
    kf.x, kf.P = x0.copy(), P0.copy()
    kf.F, kf.Q = model["transitions"][0], model["process_noise"][0]
    kf.H, kf.R = model["measurement_matrix"], model["measurement_noise"]
    xf, Pf, _, _ = kf.batch_filter(Z[:, 0])
    xs, Ps, _, _ = kf.rts_smoother(xf, Pf)
    sm = smooth_two_filter(Z, model, x0[None], P0[None], [1.0], T)
    dist = np.hypot(*(sm.x[:, 0] - xs)[:, [0, 2]].T)
    # the backward filter starts from the last two points, leaving out Q between them: the
    # difference that makes dies out going back
    assert dist[: K // 2].max() < 1e-4 * SIGMA and dist.max() < 0.05 * SIGMA
    np.testing.assert_allclose(
        sm.P_modes[: K // 2, 0, 0, :4, :4], Ps[: K // 2, :4, :4], rtol=1e-5, atol=1e-3
    )
    np.testing.assert_allclose(sm.x[-1, 0], xf[-1], rtol=1e-12)  # the last step is the filter's


@pytest.mark.parametrize("seed", [4, 5, 6])
def test_several_modes_approach_the_exact_smoother(seed):
    """`realistic`'s three known-rate modes, straight flight then a 3 °/s turn at 4 s: the
    smoothed mode probabilities and positions are, over the record, much closer to the
    exact ones than the filter's."""
    d_mu_s, d_mu_f, d_x_s, d_x_f = exact_comparison(
        seed, lambda model, Z, x0, P0, mu0, T, rec: smooth_two_filter(Z, model, x0, P0, mu0, T)
    )
    assert d_mu_s < 0.2 and d_mu_s < 0.5 * d_mu_f
    assert d_x_s < 30.0 and d_x_s < 0.5 * d_x_f


@pytest.mark.parametrize("name", ["seed", "realistic", "dense-turns"])
def test_on_traffic_of_its_own_model_beats_expectation_correction(name):
    """Aircraft flying the preset's own jump-Markov model. The expectation-correction
    smoother over the whole record is worse than with 10 steps of lag (its per-mode
    estimates run off, ``docs/tracking.md``); two filters are better than both."""
    from airspace_sim.dynamics import get_preset, simulate
    from airspace_sim.tracking import two_point_initialisation

    preset = get_preset(name)
    truth = simulate(preset, n_steps=300, n_targets=40, rng=np.random.default_rng(11))
    z = truth.measurements
    R = preset.measurement_sigma**2 * np.eye(2)
    x0, P0 = two_point_initialisation(z[0], z[1], preset.dt, R)
    model = preset.filter_model().imm_arguments()
    mu0 = preset.filter_model().mu0()
    rec = record(model, z[2:], x0, P0, mu0)
    true_xy = truth.states[2:, :, [0, 2]]

    def rmse(x):
        return np.sqrt(np.mean(np.sum((x[..., [0, 2]] - true_xy) ** 2, axis=-1)))

    err_f = rmse(np.einsum("kbm,kbmn->kbn", rec[0], rec[1]))
    err_ec = rmse(smooth(*rec, model).x)
    err_lag = rmse(smooth(*rec, model, lag=10).x)
    err_2f = rmse(smooth_two_filter(z[2:], model, x0, P0, mu0, preset.dt).x)
    assert err_2f < min(err_ec, err_lag) and err_2f < 0.7 * err_f


def test_a_reflected_record_smooths_to_the_reflection():
    rng = np.random.default_rng(3)
    T, K = 4.0, 30
    p = presets.realistic(T).with_(measurement_sigma=SIGMA)
    model = p.imm_arguments()
    Z = straight_then_turn(rng, K, T, rate_deg=3.0, B=2)
    x0, P0 = start(2, omega_var=1e-6)
    sm = smooth_two_filter(Z, model, x0, P0, p.mu0(), T)
    ref = smooth_two_filter(Z * [1, -1], model, x0 * MIRROR, P0, p.mu0(), T)
    perm = mirror_modes(model)
    np.testing.assert_array_equal(perm, [0, 2, 1])
    np.testing.assert_allclose(ref.x * MIRROR, sm.x, rtol=1e-9, atol=1e-6)
    np.testing.assert_allclose(ref.mu[..., perm], sm.mu, rtol=1e-9, atol=1e-12)
    assert sm.mu[-10:, :, 1].mean() > 0.9  # the left-turn mode flies the turn


@pytest.mark.parametrize("name", ["realistic", "dense-turns", "imm-ct"])
def test_the_reversed_chain(name):
    model = presets.get(name).filter_model().imm_arguments()
    Pi = np.asarray(model["transition_matrix"])
    rev, perm, p = reversed_model(model)
    Pr = np.asarray(rev["transition_matrix"])[np.ix_(perm, perm)]  # back to forward labels
    np.testing.assert_allclose(p @ Pi, p, atol=1e-12)
    np.testing.assert_allclose(p @ Pr, p, atol=1e-12)
    np.testing.assert_allclose(p[:, None] * Pr, (p[:, None] * Pi).T, atol=1e-12)  # Pr(i→j) flows
    again = dict(model, transition_matrix=Pr)
    np.testing.assert_allclose(reversed_model(again)[0]["transition_matrix"][np.ix_(perm, perm)],
                               Pi, atol=1e-12)  # fmt: skip
    w, v = np.linalg.eig(Pi.T)  # the stationary law as the eigenvector of eigenvalue 1
    eig = np.abs(np.real(v[:, np.argmin(np.abs(w - 1.0))]))
    np.testing.assert_allclose(stationary_law(Pi), eig / eig.sum(), atol=1e-12)


def test_records_of_different_lengths_and_missed_detections():
    rng = np.random.default_rng(7)
    T, K = 4.0, 30
    p = presets.imm_ct(T).with_(measurement_sigma=SIGMA)
    model = p.imm_arguments()
    Z, path = straight_then_turn(rng, K, T, rate_deg=2.0, B=2, with_path=True)
    Z[[5, 9, 14], 0] = np.nan  # missed detections
    Z[20:, 1] = np.nan  # the second record ends after 20 steps
    x0, P0 = start(2)
    both = smooth_two_filter(Z, model, x0, P0, p.mu0(), T, n_steps=np.array([K, 20]))
    alone = smooth_two_filter(Z[:20, 1:], model, x0[1:], P0[1:], p.mu0(), T)
    np.testing.assert_allclose(both.x_modes[:20, 1], alone.x_modes[:, 0], rtol=1e-9, atol=1e-6)
    np.testing.assert_allclose(both.mu[:20, 1], alone.mu[:, 0], rtol=1e-9, atol=1e-12)
    assert np.all(np.isfinite(both.x[:, 0])) and np.allclose(both.mu[:, 0].sum(axis=1), 1.0)
    mu_f, x_f, _ = record(model, Z[:, :1], x0[:1], P0[:1], p.mu0())
    filtered = np.einsum("km,kmn->kn", mu_f[:, 0], x_f[:, 0])[:, [0, 2]]
    err_f = np.hypot(*(filtered - path)[5:].T)
    err_s = np.hypot(*(both.x[:, 0, [0, 2]] - path)[5:].T)
    assert math.sqrt(np.mean(err_s**2)) < 0.8 * math.sqrt(np.mean(err_f**2))


def test_bad_input_is_a_user_error():
    T = 4.0
    p = presets.imm_ct(T)
    model = p.imm_arguments()
    Z = straight_then_turn(np.random.default_rng(0), 10, T)
    x0, P0 = np.zeros((1, 5)), np.eye(5)[None]
    Z_end = Z.copy()
    Z_end[-1] = np.nan
    with pytest.raises(UserError, match="record 0 has no measurement"):
        smooth_two_filter(Z_end, model, x0, P0, p.mu0(), T)
    with pytest.raises(UserError, match="x0"):
        smooth_two_filter(Z, model, x0[:, :4], P0, p.mu0(), T)
    with pytest.raises(UserError, match="n_steps"):
        smooth_two_filter(Z, model, x0, P0, p.mu0(), T, n_steps=[11])
    one_sided = dict(presets.realistic(T).imm_arguments())
    one_sided["offsets"] = np.asarray(one_sided["offsets"]).copy()
    one_sided["offsets"][2, 4] = 0.0  # the right-turn mode no longer mirrors the left one
    with pytest.raises(UserError, match="mirror"):
        smooth_two_filter(Z, one_sided, x0, P0, presets.realistic(T).mu0(), T)
    with pytest.raises(UserError, match="along-track"):
        smooth_two_filter(Z, presets.imm_cta(T).imm_arguments(), x0, P0, [0.6, 0.3, 0.1], T)


def test_fixed_lag_is_the_fixed_interval_smoother_of_the_window(monkeypatch):
    """Step k with lag L is step k of the fixed-interval smoother over the record up to
    k + L, or up to the last step before it whose measurement and the one before it are
    there (a missed detection moves the window's start back); lag 0 is the filter, a lag
    past the end the fixed-interval smoother; windows run in chunks as one."""
    from airspace_sim.tracking import two_filter

    monkeypatch.setattr(two_filter, "LAG_WINDOWS", 7)
    rng = np.random.default_rng(8)
    T, K, L = 4.0, 24, 3
    p = presets.imm_ct(T).with_(measurement_sigma=SIGMA)
    model = p.imm_arguments()
    Z = straight_then_turn(rng, K, T, rate_deg=2.0, B=2)
    Z[18:, 1] = np.nan  # the second record ends after 18 steps
    Z[10, 0] = np.nan  # a missed detection
    n = np.array([K, 18])
    x0, P0 = start(2)
    args = (model, x0, P0, p.mu0(), T)
    lagged = smooth_two_filter(Z, *args, n_steps=n, lag=L)
    for b in range(2):
        for k in range(n[b] - 1):
            end = min(k + L, n[b] - 1)
            while np.isnan(Z[end, b, 0]) or np.isnan(Z[end - 1, b, 0]):
                end -= 1
            if end - 1 < k:
                np.testing.assert_allclose(lagged.mu[k, b], record(model, Z[: k + 1, b : b + 1],
                                           x0[b : b + 1], P0[b : b + 1], p.mu0())[0][k, 0])  # fmt: skip
                continue
            ref = smooth_two_filter(Z[: end + 1, b : b + 1], model, x0[b : b + 1], P0[b : b + 1],
                                    p.mu0(), T)  # fmt: skip
            np.testing.assert_allclose(
                lagged.x_modes[k, b], ref.x_modes[k, 0], rtol=1e-9, atol=1e-6
            )
            np.testing.assert_allclose(lagged.mu[k, b], ref.mu[k, 0], rtol=1e-9, atol=1e-12)
    filt = smooth_two_filter(Z, *args, n_steps=n, lag=0)
    rec = record(model, Z, x0, P0, p.mu0())
    np.testing.assert_array_equal(filt.x_modes, rec[1])
    whole = smooth_two_filter(Z, *args, n_steps=n)
    far = smooth_two_filter(Z, *args, n_steps=n, lag=K)
    np.testing.assert_allclose(far.x_modes, whole.x_modes, rtol=1e-12, atol=1e-9)
    with pytest.raises(UserError, match="lag"):
        smooth_two_filter(Z, *args, n_steps=n, lag=-1)


def test_more_look_ahead_smooths_better_on_traffic_of_its_own_model():
    """`realistic`'s own traffic: the fixed-lag smoother's positions improve with the lag up
    to the fixed-interval ones (expectation correction's get worse from 10 steps on)."""
    from airspace_sim.dynamics import get_preset, simulate
    from airspace_sim.tracking import two_point_initialisation

    preset = get_preset("realistic")
    truth = simulate(preset, n_steps=200, n_targets=40, rng=np.random.default_rng(12))
    z = truth.measurements
    x0, P0 = two_point_initialisation(
        z[0], z[1], preset.dt, preset.measurement_sigma**2 * np.eye(2)
    )
    model, mu0 = preset.filter_model().imm_arguments(), preset.filter_model().mu0()
    true_xy = truth.states[2:, :, [0, 2]]
    errs = [
        np.sqrt(np.mean(np.sum((sm.x[..., [0, 2]] - true_xy) ** 2, axis=-1)))
        for sm in [
            smooth_two_filter(z[2:], model, x0, P0, mu0, preset.dt, lag=L) for L in (0, 3, 10, 20)
        ]
        + [smooth_two_filter(z[2:], model, x0, P0, mu0, preset.dt)]
    ]
    assert all(a > b for a, b in zip(errs, errs[1:])), errs
