"""Monte Carlo consistency of the IMM on the realistic preset (Bar-Shalom et al. 2001, §5.4),
and its accuracy against the best-tuned constant-velocity Kalman filter.

200 targets (one batched IMM with B = 200), 300 steps of 1 s, seeded. Filters start at step
1 from the first two measurements (two-point differencing: no truth is used, as for a real
tracker); the first 30 filter steps are burn-in. Run ``pytest -s`` to see the figures, or
``python -m airspace_sim.tracking.consistency``.
"""

import numpy as np
import pytest
from scipy import stats

from airspace_sim.dynamics import models, presets
from airspace_sim.tracking import IMM
from airspace_sim.tracking.consistency import (
    chi2_band,
    monte_carlo,
    nees,
    nis,
)
from airspace_sim.tracking.initialisation import two_point_initialisation

N_RUNS, N_STEPS, BURN_IN, SEED = 200, 300, 30, 2026


@pytest.fixture(scope="module")
def mc():
    r = monte_carlo("realistic", N_RUNS, N_STEPS, BURN_IN, SEED, imm_class=IMM)
    print("\n" + r.summary())
    return r


# --- the helpers --------------------------------------------------------------------------


def test_chi2_band_textbook_values():
    # Bar-Shalom et al. 2001 §5.4: N = 50 runs, m = 2: 95% band for the average NIS is
    # [1.5, 2.5] (χ²(100) quantiles 74.2 and 129.6 divided by 50).
    lo, hi = chi2_band(2, 50, 0.95)
    assert lo == pytest.approx(74.222 / 50, rel=1e-4) and hi == pytest.approx(
        129.561 / 50, rel=1e-4
    )
    # one run: plain χ² quantiles
    assert chi2_band(4, 1, 0.95) == pytest.approx((0.4844, 11.1433), rel=1e-3)
    # wider for higher probability, narrower for more runs, always around dof
    assert chi2_band(4, 200, 0.99)[1] > chi2_band(4, 200, 0.95)[1] > 4 > chi2_band(4, 200, 0.95)[0]
    assert (
        chi2_band(2, 1000)[1] - chi2_band(2, 1000)[0] < chi2_band(2, 100)[1] - chi2_band(2, 100)[0]
    )
    with pytest.raises(ValueError):
        chi2_band(0, 10)


def test_nees_nis_are_chi2_for_consistent_errors():
    rng = np.random.default_rng(0)
    n, N = 4, 20_000
    A = rng.standard_normal((N, n, n))
    P = A @ np.swapaxes(A, 1, 2) + 0.1 * np.eye(n)
    err = np.einsum("bij,bj->bi", np.linalg.cholesky(P), rng.standard_normal((N, n)))
    e = nees(err, P)
    assert e.shape == (N,)
    assert stats.kstest(e, stats.chi2(n).cdf).pvalue > 1e-3
    # hand-written value
    assert nis(np.array([3.0, 4.0]), np.diag([9.0, 4.0])) == pytest.approx(1.0 + 4.0)
    # and an inflated covariance gives a too-small average
    assert nees(err, 4 * P).mean() == pytest.approx(e.mean() / 4)


def test_two_point_initialisation_covariance_is_the_error_covariance():
    """Empirical covariance of the two-point initial error ≈ the P0 it claims (CV truth)."""
    rng = np.random.default_rng(1)
    dt, s, B = 2.0, 50.0, 100_000
    R = models.measurement_noise(s)
    p0 = rng.uniform(-1e4, 1e4, (B, 2))
    v = rng.uniform(-250, 250, (B, 2))
    z0 = p0 + s * rng.standard_normal((B, 2))
    z1 = p0 + v * dt + s * rng.standard_normal((B, 2))
    x0, P0 = two_point_initialisation(z0, z1, dt, R, omega=0.01, omega_var=0.4 * 0.05**2)
    err = x0[:, :4] - np.stack(
        [p0[:, 0] + v[:, 0] * dt, v[:, 0], p0[:, 1] + v[:, 1] * dt, v[:, 1]], 1
    )
    C = np.cov(err.T)
    P = P0[0, :4, :4]
    sd = np.sqrt(np.outer(np.diag(P), np.diag(P)) * 2 / B)  # ≥ sd of each sample (co)variance
    assert np.all(np.abs(C - P) < 5 * sd), (C, P)
    assert P0[0, 4, 4] == 0.4 * 0.05**2 and x0[0, 4] == 0.01
    assert np.all(np.linalg.eigvalsh(P0[0]) > 0)


def test_two_point_initialisation_per_track_dt_and_manoeuvre_allowance():
    """Per-track Δt and the velocity allowance, against the closed form written out."""
    z0 = np.array([[0.0, 0.0], [100.0, -50.0]])
    z1 = np.array([[230.0, 10.0], [100.0, 410.0]])
    dt = np.array([1.0, 2.0])
    R = np.array([[2500.0, 100.0], [100.0, 1600.0]])
    x0, P0 = two_point_initialisation(z0, z1, dt, R, omega_var=1e-4, extra_velocity_var=100.0)
    for b in range(2):
        d = dt[b]
        assert x0[b].tolist() == [
            z1[b, 0], (z1[b, 0] - z0[b, 0]) / d, z1[b, 1], (z1[b, 1] - z0[b, 1]) / d, 0.0
        ]  # fmt: skip
        pos, vel = [0, 2], [1, 3]
        np.testing.assert_array_equal(P0[b][np.ix_(pos, pos)], R)
        np.testing.assert_array_equal(P0[b][np.ix_(pos, vel)], R / d)
        np.testing.assert_array_equal(P0[b][np.ix_(vel, vel)], 2 * R / d**2 + 100.0 * np.eye(2))
        assert P0[b, 4, 4] == 1e-4 and not P0[b, 4, :4].any()


# --- the Monte Carlo ----------------------------------------------------------------------


@pytest.mark.slow
def test_imm_average_nis_inside_chi2_band(mc):
    """Time average (after burn-in) of the per-step N-run average NIS lies inside the 95%
    band of an N-run average of χ²(2) (Bar-Shalom §5.4: N·avgNIS ~ χ²(N·m))."""
    lo, hi = chi2_band(2, N_RUNS, 0.95)
    assert lo <= mc.nis_time_avg <= hi, mc.summary()
    assert np.all(np.isfinite(mc.nis_per_step))


@pytest.mark.slow
def test_imm_nees_never_above_upper_bound(mc):
    """Per-step N-run average 4-d position/velocity NEES never above the upper end of the 99%
    two-sided band (χ²(4N) 0.995 quantile / N). 99% rather than 95% because it is checked at
    every one of ~270 steps: a consistent filter would cross a 97.5% quantile at ~7 of them
    by chance (the 99% bound is still stricter than a Bonferroni 5% family-wise bound).
    Ω is left out: it is the mode's deterministic rate, its posterior a discrete mixture.
    The lower sanity bound catches a grossly inflated P (the filters' Q is 4× the truth's,
    so some conservatism, NEES ≈ 3.2 < 4, is expected and documented in the preset)."""
    bound = chi2_band(4, N_RUNS, 0.99)[1]
    assert mc.nees_bound == bound
    assert mc.nees_max <= bound, mc.summary()
    assert mc.nees_time_avg > 2.5, mc.summary()


@pytest.mark.slow
def test_imm_beats_best_tuned_cv_and_raw_measurements(mc):
    """IMM position RMSE ≤ 0.85 × the best CV Kalman filter over a σ_a grid 0.5…20 m/s²
    (tuned on the same data: the honest baseline), and well below the raw measurement error."""
    assert min(mc.cv_grid) <= 0.5 and max(mc.cv_grid) >= 20.0
    assert min(mc.cv_grid) < mc.cv_sigma < max(mc.cv_grid), "best σ_a on the grid edge: widen it"
    assert mc.rmse_pos_imm <= 0.85 * mc.rmse_pos_cv, mc.summary()
    assert mc.rmse_pos_imm < 0.7 * mc.rmse_raw, mc.summary()
    assert mc.rmse_raw == pytest.approx(50.0 * np.sqrt(2), rel=0.02)  # σ√2 for 2-d error
    assert mc.rmse_vel_imm < mc.rmse_vel_cv_best, mc.summary()


@pytest.mark.slow
def test_checks_can_fail_with_a_mistuned_imm():
    """Negative control: an IMM that believes σ = 25 m (R/4) is overconfident, so the same
    checks must reject it (the NIS average far above its band, NEES above its bound)."""

    def wrong_R(**kw):
        kw["measurement_noise"] = kw["measurement_noise"] / 4
        return IMM(**kw)

    r = monte_carlo("realistic", 100, 120, BURN_IN, SEED + 1, cv_sigmas=(10.0,), imm_class=wrong_R)
    assert r.nis_time_avg > chi2_band(2, 100, 0.95)[1]
    assert r.nees_max > chi2_band(4, 100, 0.99)[1]


def test_preset_used_is_the_realistic_one(mc):
    p = presets.get("realistic")
    assert mc.preset == p.name and p.measurement_sigma == 50.0
    assert mc.n_runs >= 100 and mc.n_eval_steps == N_STEPS - 2 - BURN_IN
