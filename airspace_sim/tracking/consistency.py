"""Filter consistency statistics (NEES, NIS, chi-square bands) and the IMM-vs-CV Monte Carlo.

Bar-Shalom, Li & Kirubarajan, *Estimation with Applications to Tracking and Navigation*
(Wiley 2001), §5.4: a consistent filter's state errors are zero-mean with covariance P, so

- NEES ``ε = x̃ᵀ P⁻¹ x̃`` is χ²(n) for an n-dimensional state error x̃ (§5.4.2);
- NIS ``ε_ν = νᵀ S⁻¹ ν`` is χ²(m) for an m-dimensional innovation ν (§5.4.2);
- averaged over N independent Monte Carlo runs at one time step, ``N ε̄ ~ χ²(N n)``,
  so ε̄ should lie in the two-sided ``prob`` band :func:`chi2_band` (§5.4.2, eq. 5.4.2-6).

:func:`monte_carlo` runs the project's standard check: B targets of a preset's jump-Markov
model tracked by the matched IMM and by constant-velocity Kalman filters over a grid of
σ_a; ``python -m airspace_sim.tracking.consistency`` prints its figures.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from airspace_sim.dynamics import models, presets
from airspace_sim.dynamics.truth import simulate
from airspace_sim.tracking.initialisation import two_point_initialisation
from airspace_sim.tracking.kalman import KalmanFilter

#: CV Kalman filter σ_a grid (m/s²) searched for the best-tuned baseline.
CV_SIGMA_GRID = (0.5, 0.75, 1.0, 1.5, 2.0, 2.5, 3.0, 4.0, 5.0, 6.0, 8.0, 10.0, 12.0, 15.0, 20.0)


def _quadratic_form(v: np.ndarray, C: np.ndarray) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    C = np.asarray(C, dtype=float)
    return np.einsum("...i,...i->...", v, np.linalg.solve(C, v[..., None])[..., 0])


def nees(err, P) -> np.ndarray:
    """Normalised estimation error squared ``x̃ᵀ P⁻¹ x̃`` (Bar-Shalom et al. 2001, §5.4.2).

    ``err`` (..., n) is estimate minus truth, ``P`` (..., n, n) the filter's covariance;
    returns (...). χ²(n)-distributed for a consistent filter.
    """
    return _quadratic_form(err, P)


def nis(innovation, S) -> np.ndarray:
    """Normalised innovation squared ``νᵀ S⁻¹ ν`` (Bar-Shalom et al. 2001, §5.4.2).

    ``innovation`` (..., m) is ``z − ẑ``, ``S`` (..., m, m) its predicted covariance;
    returns (...). χ²(m)-distributed for a consistent filter.
    """
    return _quadratic_form(innovation, S)


def chi2_band(dof: int, n_runs: int = 1, prob: float = 0.95) -> tuple[float, float]:
    """Two-sided ``prob`` acceptance band for the average of ``n_runs`` independent χ²(dof)
    statistics (NEES with dof = n, NIS with dof = m).

    ``n_runs · average ~ χ²(n_runs · dof)`` (Bar-Shalom et al. 2001, §5.4.2), so the band
    is ``[F⁻¹((1 − prob)/2), F⁻¹((1 + prob)/2)] / n_runs`` with F the χ²(n_runs · dof) CDF.
    E.g. ``chi2_band(2, 50, 0.95)`` = (1.59, 2.45), the textbook NIS example.
    """
    if dof < 1 or n_runs < 1 or not 0 < prob < 1:
        raise ValueError(
            f"chi2_band: need dof >= 1, n_runs >= 1, 0 < prob < 1; got {dof}, {n_runs}, {prob}"
        )
    k = dof * n_runs
    lo, hi = stats.chi2.ppf([(1 - prob) / 2, (1 + prob) / 2], k)
    return float(lo / n_runs), float(hi / n_runs)


@dataclass
class MonteCarloResult:
    """Figures of one IMM-vs-CV Monte Carlo experiment (RMSEs in m and m/s, over runs and
    the steps after burn-in; NEES over the 4-d position-velocity error)."""

    preset: str
    n_runs: int
    n_steps: int
    burn_in: int
    rmse_pos_imm: float
    rmse_vel_imm: float
    rmse_pos_cv: float  # best-tuned CV (by position RMSE)
    rmse_vel_cv: float  # that same filter's velocity RMSE
    cv_sigma: float  # its σ_a, m/s²
    rmse_vel_cv_best: float  # best CV velocity RMSE over the grid (tuned for velocity)
    cv_sigma_vel: float
    rmse_raw: float  # measurement position error
    nis_time_avg: float
    nis_band: tuple  # 95 % band for the N-run average of χ²(2)
    nis_band_time: tuple  # 95 % band for the N·K-sample time average (much tighter)
    nees_time_avg: float
    nees_max: float
    nees_bound: float  # 99 % two-sided (upper 0.995) bound for the N-run average of χ²(4)
    nees_band95: tuple
    nees_steps_above_95: int
    n_eval_steps: int
    gated: int
    nees5_time_avg: float = float("nan")  # full 5-d NEES incl. Ω: shown only to say why not
    nees5_max: float = float("nan")
    cv_grid: dict = field(default_factory=dict)  # σ_a -> (pos RMSE, vel RMSE)
    nees_per_step: np.ndarray = field(default=None, repr=False)
    nis_per_step: np.ndarray = field(default=None, repr=False)

    @property
    def ratio_pos(self) -> float:
        return self.rmse_pos_imm / self.rmse_pos_cv

    @property
    def ratio_vel(self) -> float:
        return self.rmse_vel_imm / self.rmse_vel_cv

    def summary(self) -> str:
        lo, hi = self.nis_band
        tl, th = self.nis_band_time
        el, eh = self.nees_band95
        return "\n".join(
            [
                f"preset={self.preset} runs={self.n_runs} steps={self.n_steps} burn_in={self.burn_in} "
                f"evaluated_steps={self.n_eval_steps}",
                f"position RMSE: IMM {self.rmse_pos_imm:.2f} m, best CV {self.rmse_pos_cv:.2f} m "
                f"(sigma_a={self.cv_sigma:g} m/s^2), ratio {self.ratio_pos:.3f}; raw measurement "
                f"{self.rmse_raw:.2f} m (IMM/raw {self.rmse_pos_imm / self.rmse_raw:.3f})",
                f"velocity RMSE: IMM {self.rmse_vel_imm:.2f} m/s, that CV {self.rmse_vel_cv:.2f} m/s, "
                f"ratio {self.ratio_vel:.3f}; best CV for velocity {self.rmse_vel_cv_best:.2f} m/s "
                f"(sigma_a={self.cv_sigma_vel:g}), ratio {self.rmse_vel_imm / self.rmse_vel_cv_best:.3f}",
                f"NIS (m=2): time-averaged {self.nis_time_avg:.3f}, 95% band for {self.n_runs}-run "
                f"average [{lo:.3f}, {hi:.3f}] (time-average band [{tl:.3f}, {th:.3f}])",
                f"NEES (4-d pos/vel): time-averaged {self.nees_time_avg:.3f}, max over steps "
                f"{self.nees_max:.3f}, upper bound (99% two-sided) {self.nees_bound:.3f}; 95% band "
                f"[{el:.3f}, {eh:.3f}], steps above it {self.nees_steps_above_95}/{self.n_eval_steps}",
                f"5-d NEES incl. Omega (not chi-square: Omega is the mode's rate): time-averaged "
                f"{self.nees5_time_avg:.3g}, max {self.nees5_max:.3g}",
                f"gated measurements: {self.gated}",
            ]
        )


def _rmse(err: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum(err**2, axis=-1))))


def monte_carlo(
    preset="realistic",
    n_runs: int = 200,
    n_steps: int = 300,
    burn_in: int = 30,
    seed: int = 2026,
    cv_sigmas=CV_SIGMA_GRID,
    imm_class=None,
) -> MonteCarloResult:
    """Track ``n_runs`` simulated targets of ``preset`` with its matched IMM and CV filters.

    Truth and measurements come from :func:`~airspace_sim.dynamics.truth.simulate` (seeded
    with ``numpy.random.default_rng(seed)``). Every filter starts at step 1 from the first
    two measurements (:func:`two_point_initialisation`: uses no truth, so the comparison is
    the one a real tracker faces) and then processes steps 2 … n_steps−1. Statistics use the
    steps after ``burn_in`` filter steps.

    NEES uses the 4-d position/velocity error: Ω is not a random state here but the mode's
    deterministic rate, so its IMM posterior is a discrete mixture (a near-zero variance
    per mode plus the spread term), not a Gaussian, and a χ² test on it is meaningless.
    """
    if imm_class is None:
        from airspace_sim.tracking import IMM as imm_class
    p = presets.get(preset) if isinstance(preset, str) else preset
    rng = np.random.default_rng(seed)
    tr = simulate(p, n_steps, n_runs, rng)
    Z, X = tr.measurements, tr.states
    R = models.measurement_noise(p.measurement_sigma)
    mu0 = p.mu0()
    # Ω starts at the mode-weighted rate Σ μ_j ω_j with the spread of the rates as its
    # variance (floored at (10⁻³ rad/s)² to keep P0 definite)
    rates = np.asarray(p.turn_rates, dtype=float)
    omega = float(mu0 @ rates)
    omega_var = max(float(mu0 @ (rates - omega) ** 2), 1e-6)
    x0, P0 = two_point_initialisation(Z[0], Z[1], p.dt, R, omega, omega_var)
    steps = np.arange(2, n_steps)
    ev = steps >= 2 + burn_in  # evaluated steps
    pv = [0, 1, 2, 3]

    imm = imm_class(**p.imm_arguments(), x0=x0, P0=P0, mu0=mu0)
    err = np.empty((steps.size, n_runs, 5))
    nees_k = np.empty((steps.size, n_runs))
    nis_k = np.empty((steps.size, n_runs))
    nees5_k = np.empty((steps.size, n_runs))
    gated = 0
    for i, k in enumerate(steps):
        imm.step(Z[k])
        err[i] = imm.x - X[k]
        nees_k[i] = nees(err[i][:, pv], imm.P[:, pv][:, :, pv])
        nees5_k[i] = nees(err[i], imm.P)
        nis_k[i] = imm.nis
        gated += int(np.count_nonzero(getattr(imm, "gated", np.zeros(1, bool))))
    e = err[ev]
    rmse_pos_imm, rmse_vel_imm = _rmse(e[..., [0, 2]]), _rmse(e[..., [1, 3]])

    H4 = models.position_measurement_matrix()[:, :4]
    F4 = models.constant_velocity(p.dt)[:4, :4]
    grid = {}
    for s in cv_sigmas:
        kf = KalmanFilter(
            F4, models.white_noise_acceleration(s, p.dt)[:4, :4], H4, R, x0[:, :4], P0[:, :4, :4]
        )
        ecv = np.empty((steps.size, n_runs, 4))
        for i, k in enumerate(steps):
            kf.step(Z[k])
            ecv[i] = kf.x - X[k, :, :4]
        ecv = ecv[ev]
        grid[float(s)] = (_rmse(ecv[..., [0, 2]]), _rmse(ecv[..., [1, 3]]))
    best = min(grid, key=lambda s: grid[s][0])
    best_v = min(grid, key=lambda s: grid[s][1])

    raw = _rmse((Z[steps] - X[steps][..., [0, 2]])[ev])
    nis_t = np.nanmean(nis_k[ev], axis=1)
    nees_t = nees_k[ev].mean(axis=1)
    n_eval = int(ev.sum())
    band95 = chi2_band(4, n_runs, 0.95)
    return MonteCarloResult(
        preset=p.name,
        n_runs=n_runs,
        n_steps=n_steps,
        burn_in=burn_in,
        rmse_pos_imm=rmse_pos_imm,
        rmse_vel_imm=rmse_vel_imm,
        rmse_pos_cv=grid[best][0],
        rmse_vel_cv=grid[best][1],
        cv_sigma=best,
        rmse_vel_cv_best=grid[best_v][1],
        cv_sigma_vel=best_v,
        rmse_raw=raw,
        nis_time_avg=float(nis_t.mean()),
        nis_band=chi2_band(2, n_runs, 0.95),
        nis_band_time=chi2_band(2, n_runs * n_eval, 0.95),
        nees_time_avg=float(nees_t.mean()),
        nees_max=float(nees_t.max()),
        nees_bound=chi2_band(4, n_runs, 0.99)[1],
        nees_band95=band95,
        nees_steps_above_95=int(np.count_nonzero(nees_t > band95[1])),
        n_eval_steps=n_eval,
        gated=gated,
        nees5_time_avg=float(nees5_k[ev].mean(axis=1).mean()),
        nees5_max=float(nees5_k[ev].mean(axis=1).max()),
        cv_grid=grid,
        nees_per_step=nees_t,
        nis_per_step=nis_t,
    )


def main(argv=None) -> int:
    import argparse

    ap = argparse.ArgumentParser(description="IMM vs best-tuned CV Monte Carlo consistency check")
    ap.add_argument("--preset", default="realistic")
    ap.add_argument("--runs", type=int, default=200)
    ap.add_argument("--steps", type=int, default=300)
    ap.add_argument("--burn-in", type=int, default=30)
    ap.add_argument("--seed", type=int, default=2026)
    a = ap.parse_args(argv)
    r = monte_carlo(a.preset, a.runs, a.steps, a.burn_in, a.seed)
    print(r.summary())
    grid = ", ".join(f"{s:g}: {v[0]:.1f}, {v[1]:.1f}" for s, v in r.cv_grid.items())
    print(f"CV grid (sigma_a: pos RMSE, vel RMSE): {grid}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
