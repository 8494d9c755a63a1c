"""IMM robustness: missing measurements, gating of outliers, long runs, extreme inputs.

filterpy's ``IMMEstimator`` has no predict-only step and no gating, so these behaviours are
checked against :class:`ReferenceIMM`, an independent, slow, obviously-correct pure-numpy
IMM written here from the textbook equations (Bar-Shalom, Li & Kirubarajan 2001, §11.6.6),
which also covers per-mode offsets.
"""

from __future__ import annotations

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.stats import chi2

from airspace_sim.dynamics import presets
from airspace_sim.tracking import IMM


class ReferenceIMM:
    """One tracker at a time, plain numpy, no tricks (except log-sum-exp and the gate)."""

    def __init__(self, transitions, process_noise, measurement_matrix, measurement_noise,
                 transition_matrix, x0, P0, mu0, offsets=None, gate_probability=1 - 1e-6):  # fmt: skip
        self.F, self.Q = np.asarray(transitions), np.asarray(process_noise)
        self.H, self.R = np.asarray(measurement_matrix), np.asarray(measurement_noise)
        self.Pi = np.asarray(transition_matrix)
        M, n, _ = self.F.shape
        self.U = np.zeros((M, n)) if offsets is None else np.asarray(offsets)
        self.gate = (
            np.inf if gate_probability == 1 else chi2.isf(1 - gate_probability, self.H.shape[0])
        )
        B = len(x0)
        self.xm = np.repeat(np.asarray(x0, float)[:, None], M, axis=1)
        self.Pm = np.repeat(np.broadcast_to(P0, (B, n, n))[:, None], M, axis=1).astype(float)
        self.mu = np.broadcast_to(mu0, (B, M)).astype(float)

    def step(self, z):
        F, Q, H, R, Pi, U = self.F, self.Q, self.H, self.R, self.Pi, self.U
        B, M, n = self.xm.shape
        m = H.shape[0]
        out = dict(x=[], P=[], mu=[], xm=[], Pm=[], nis=[], ll=[], gated=[])
        for b in range(B):
            mu = self.mu[b]
            cbar = Pi.T @ mu
            xs, Ps, lls, d2s, zhs, Ss = [], [], [], [], [], []
            for j in range(M):
                if cbar[j] > 0:
                    w = Pi[:, j] * mu / cbar[j]
                else:
                    w = np.eye(M)[j]
                x0 = w @ self.xm[b]
                P0 = sum(
                    w[i] * (self.Pm[b, i] + np.outer(self.xm[b, i] - x0, self.xm[b, i] - x0))
                    for i in range(M)
                )
                x = F[j] @ x0 + U[j]
                P = F[j] @ P0 @ F[j].T + Q[j]
                xs.append(x)
                Ps.append(P)
            have = bool(np.all(np.isfinite(z[b])))
            Ks, nus = [], []
            for j in range(M):
                S = H @ Ps[j] @ H.T + R
                zh = H @ xs[j]
                Ss.append(S)
                zhs.append(zh)
                if have:
                    nu = z[b] - zh
                    d2 = nu @ np.linalg.solve(S, nu)
                    lls.append(-0.5 * (d2 + np.linalg.slogdet(S)[1] + m * np.log(2 * np.pi)))
                    d2s.append(d2)
                    Ks.append(Ps[j] @ H.T @ np.linalg.inv(S))
                    nus.append(nu)
            gated = have and all(d2s[j] > self.gate for j in range(M) if cbar[j] > 0)
            if have:
                zbar = sum(cbar[j] * zhs[j] for j in range(M))
                Sbar = sum(
                    cbar[j] * (Ss[j] + np.outer(zhs[j] - zbar, zhs[j] - zbar)) for j in range(M)
                )
                nis = (z[b] - zbar) @ np.linalg.solve(Sbar, z[b] - zbar)
                ll = np.array(lls)
            else:
                nis = np.nan
                ll = np.full(M, np.nan)
            if have and not gated:
                for j in range(M):
                    A = np.eye(n) - Ks[j] @ H
                    xs[j] = xs[j] + Ks[j] @ nus[j]
                    Ps[j] = A @ Ps[j] @ A.T + Ks[j] @ R @ Ks[j].T
                    Ps[j] = 0.5 * (Ps[j] + Ps[j].T)
                with np.errstate(divide="ignore"):
                    lw = ll + np.log(cbar)
                mu_new = np.exp(lw - lw.max())
                mu_new /= mu_new.sum()
            else:
                mu_new = cbar
            x = sum(mu_new[j] * xs[j] for j in range(M))
            P = sum(mu_new[j] * (Ps[j] + np.outer(xs[j] - x, xs[j] - x)) for j in range(M))
            for key, val in zip(out, (x, P, mu_new, np.array(xs), np.array(Ps), nis, ll, gated)):
                out[key].append(val)
        out = {k: np.array(v) for k, v in out.items()}
        self.xm, self.Pm, self.mu = out["xm"], out["Pm"], out["mu"]
        return out


def assert_close_scaled(x, P, rx, rP, rtol=1e-9, atol=1e-12):
    """Compare x (..., n) and P (..., n, n) scaled by the reference's standard deviations."""
    s = np.sqrt(np.einsum("...ii->...i", rP))
    np.testing.assert_allclose(x / s, rx / s, rtol=rtol, atol=atol)
    ss = s[..., :, None] * s[..., None, :]
    np.testing.assert_allclose(P / ss, rP / ss, rtol=rtol, atol=atol)


def assert_symmetric(P, rtol=1e-12):
    """Each matrix of P (..., n, n) symmetric to rtol relative to its largest entry."""
    asym = np.abs(P - np.swapaxes(P, -1, -2)).max(axis=(-1, -2))
    assert np.all(asym <= rtol * np.abs(P).max(axis=(-1, -2)))


def seed_setup(B, rng):
    pre = presets.get("seed")
    args = pre.imm_arguments()
    x0 = np.zeros((B, 5))
    heading = rng.uniform(-np.pi, np.pi, B)
    speed = rng.uniform(285.0, 570.0, B)
    x0[:, 1], x0[:, 3] = speed * np.cos(heading), speed * np.sin(heading)
    P0 = np.diag([50.0**2, 30.0**2, 50.0**2, 30.0**2, 0.5**2])
    return pre, args, x0, P0


def propagate_truth(args, x, q, rng, Pi):
    """One step of the Markov-switching truth for the batch (x (B, 5), q (B,))."""
    F, U, Q = args["transitions"], args["offsets"], args["process_noise"][0]
    cdf = np.cumsum(Pi, axis=1)[q]
    q = np.minimum((rng.random(len(q))[:, None] > cdf).sum(axis=1), len(Pi) - 1)
    x = np.einsum("bij,bj->bi", F[q], x) + U[q] + rng.standard_normal(x.shape) * np.sqrt(np.diag(Q))
    return x, q


def test_missing_outliers_offsets_match_reference():
    """NaN / inf rows are predict-only, outliers are gated, offsets are applied: as the reference."""
    rng = np.random.default_rng(5)
    B, T = 12, 150
    _, args, x0, P0 = seed_setup(B, rng)
    mu0 = rng.dirichlet(np.ones(3), B)
    imm = IMM(x0=x0, P0=P0, mu0=mu0, **args)
    ref = ReferenceIMM(x0=x0, P0=P0, mu0=mu0, **args)
    x, q = x0.copy(), np.zeros(B, dtype=int)
    Pi = args["transition_matrix"]
    n_missing = n_gated = 0
    for _k in range(T):
        x, q = propagate_truth(args, x, q, rng, Pi)
        z = x[:, [0, 2]] + 50.0 * rng.standard_normal((B, 2))
        u = rng.random(B)
        z[u < 0.15] = np.nan
        z[(u >= 0.15) & (u < 0.18), 0] = np.nan  # one component missing: no measurement
        z[(u >= 0.18) & (u < 0.20), 1] = np.inf
        out = (u >= 0.20) & (u < 0.25)
        z[out] += 1e4  # 10 km outliers
        imm.step(z)
        r = ref.step(z)
        missing = u < 0.20
        n_missing += missing.sum()
        n_gated += imm.gated.sum()
        np.testing.assert_array_equal(imm.gated, r["gated"])
        assert np.all(imm.gated[out]) and not np.any(imm.gated[missing])
        assert np.all(np.isnan(imm.nis[missing])) and np.all(np.isnan(imm.log_likelihood[missing]))
        assert_close_scaled(imm.x, imm.P, r["x"], r["P"])
        assert_close_scaled(imm.x_modes, imm.P_modes, r["xm"], r["Pm"])
        np.testing.assert_allclose(imm.mu, r["mu"], rtol=1e-9, atol=1e-14)
        np.testing.assert_allclose(imm.nis, r["nis"], rtol=1e-9)
        np.testing.assert_allclose(imm.log_likelihood, r["ll"], rtol=1e-9)
    assert n_missing > 0.15 * B * T and n_gated >= 0.05 * B * T * 0.8


def test_gated_measurement_is_exactly_predict_only():
    """An outlier leaves the same bits as a missing measurement, except nis and the flag."""
    rng = np.random.default_rng(6)
    B = 50
    pre, args, x0, P0 = seed_setup(B, rng)
    a = IMM(x0=x0, P0=P0, mu0=pre.mu0(), **args)
    b = IMM(x0=x0, P0=P0, mu0=pre.mu0(), **args)
    for k in range(20):
        z = x0[:, [0, 2]] + (k + 1) * 0.1 * x0[:, [1, 3]] + 50 * rng.standard_normal((B, 2))
        a.step(z)
        b.step(z)
    zo = z + np.array([1e4, -1e4])
    a.step(zo)
    b.step(np.full((B, 2), np.nan))
    assert a.gated.all() and not b.gated.any()
    for name in ("x", "P", "mu", "x_modes", "P_modes"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    assert np.all(np.isfinite(a.nis)) and np.all(a.nis > a.gate_threshold)
    assert np.all(np.isnan(b.nis))
    # the evidence gathered so far is kept: μ = c̄ (the predicted mode probabilities), not reset
    assert not np.allclose(a.mu, pre.mu0())


def test_outliers_and_missing_10k_trackers_500_steps():
    """10⁴ trackers × 500 steps, 1 % outliers 10 km off, 2 % missing: finite, symmetric, PD."""
    rng = np.random.default_rng(7)
    B, T = 10_000, 500
    pre, args, x0, P0 = seed_setup(B, rng)
    Pi = args["transition_matrix"]
    imm = IMM(x0=x0, P0=P0, mu0=pre.mu0(), **args)
    x, q = x0.copy(), np.zeros(B, dtype=int)
    wrongly_gated = 0
    for k in range(T):
        x, q = propagate_truth(args, x, q, rng, Pi)
        z = x[:, [0, 2]] + 50.0 * rng.standard_normal((B, 2))
        u = rng.random(B)
        out = u < 0.01
        ang = rng.uniform(0, 2 * np.pi, out.sum())
        z[out] += 1e4 * np.column_stack([np.cos(ang), np.sin(ang)])
        z[(u >= 0.01) & (u < 0.03)] = np.nan
        imm.step(z)
        assert np.all(imm.gated[out])
        wrongly_gated += imm.gated[~out].sum()
        for arr in (imm.x, imm.P, imm.mu):
            assert np.all(np.isfinite(arr))
        P = imm.P
        assert_symmetric(P)
        mu_sum = imm.mu.sum(axis=1)
        assert np.abs(mu_sum - 1.0).max() <= 1e-12 and imm.mu.min() >= 0
        if k % 5 == 0 or k == T - 1:
            np.linalg.cholesky(P)  # raises unless positive definite
        if k % 25 == 0 or k == T - 1:
            Pm = imm.P_modes
            assert np.all(np.isfinite(Pm)) and np.all(np.isfinite(imm.x_modes))
            assert_symmetric(Pm)
            np.linalg.cholesky(Pm)
    # in-model measurements are practically never gated, and the tracks are still on target
    assert wrongly_gated < 1e-4 * B * T
    err = np.hypot(imm.x[:, 0] - x[:, 0], imm.x[:, 2] - x[:, 2])
    assert np.sqrt(np.mean(err**2)) < 100.0


def test_no_gate_outlier_stays_finite():
    """With gating disabled a 10 km outlier is used: log-sum-exp keeps μ finite and normalised."""
    rng = np.random.default_rng(8)
    B = 20
    pre, args, x0, P0 = seed_setup(B, rng)
    imm = IMM(x0=x0, P0=P0, mu0=pre.mu0(), gate_probability=1.0, **args)
    for k in range(5):
        imm.step(x0[:, [0, 2]] + (k + 1) * 0.1 * x0[:, [1, 3]])
    imm.step(x0[:, [0, 2]] + 1e6)
    assert not imm.gated.any()
    assert np.all(np.isfinite(imm.x)) and np.all(np.isfinite(imm.P))
    np.testing.assert_allclose(imm.mu.sum(axis=1), 1.0, atol=1e-12)
    assert np.all(np.isfinite(imm.log_likelihood)) and np.all(imm.log_likelihood < -1e3)


def test_overflowing_measurement_is_gated_even_without_gate():
    """z = 1e200 overflows d² to inf: no mode explains it, so it is gated, never NaN."""
    rng = np.random.default_rng(10)
    B = 5
    pre, args, x0, P0 = seed_setup(B, rng)
    imm = IMM(x0=x0, P0=P0, mu0=pre.mu0(), gate_probability=1.0, **args)
    imm.step(x0[:, [0, 2]] + 0.1 * x0[:, [1, 3]])
    mu = np.array(imm.mu)
    imm.step(np.full((B, 2), 1e200))
    assert imm.gated.all()
    assert np.all(np.isfinite(imm.x)) and np.all(np.isfinite(imm.P)) and np.all(np.isfinite(imm.mu))
    np.testing.assert_allclose(imm.mu, mu @ args["transition_matrix"], rtol=1e-12)


def test_unreachable_mode_stays_at_zero():
    """A mode with c̄_j = 0 (μ0 = 0 and no way in) keeps μ_j = 0, without NaN (filterpy: 0/0)."""
    rng = np.random.default_rng(9)
    _, args, x0, P0 = seed_setup(4, rng)
    args["transition_matrix"] = np.array([[0.9, 0.1, 0.0], [0.2, 0.8, 0.0], [0.3, 0.3, 0.4]])
    imm = IMM(x0=x0, P0=P0, mu0=[0.5, 0.5, 0.0], **args)
    for k in range(30):
        imm.step(x0[:, [0, 2]] + (k + 1) * 0.1 * x0[:, [1, 3]] + 50 * rng.standard_normal((4, 2)))
        assert np.all(imm.mu[:, 2] == 0.0)
        assert np.all(np.isfinite(imm.x)) and np.all(np.isfinite(imm.P_modes))
        np.linalg.cholesky(imm.P)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    pos_scale=st.floats(1.0, 1e7),
    p_scale=st.floats(1e-3, 1e8),
    z_offset=st.floats(-1e8, 1e8),
    missing=st.floats(0.0, 1.0),
    seed=st.integers(0, 2**31),
)
def test_extreme_inputs_stay_finite_and_pd(pos_scale, p_scale, z_offset, missing, seed):
    """Any scale of state, covariance and measurement: finite, normalised μ, PD covariances."""
    rng = np.random.default_rng(seed)
    pre = presets.get("seed")
    args = pre.imm_arguments()
    B = 8
    x0 = rng.standard_normal((B, 5)) * [pos_scale, 300, pos_scale, 300, 0.5]
    P0 = np.diag([p_scale, p_scale / 100, p_scale, p_scale / 100, 0.1])
    imm = IMM(x0=x0, P0=P0, mu0=rng.dirichlet(np.ones(3), B), **args)
    for _k in range(30):
        z = x0[:, [0, 2]] + z_offset * rng.standard_normal((B, 2))
        z[rng.random(B) < missing] = np.nan
        imm.step(z)
        assert np.all(np.isfinite(imm.x)) and np.all(np.isfinite(imm.P))
        assert np.all(np.isfinite(imm.P_modes)) and np.all(np.isfinite(imm.mu))
        np.testing.assert_allclose(imm.mu.sum(axis=1), 1.0, atol=1e-12)
        assert np.linalg.eigvalsh(imm.P_modes).min() > 0
        assert np.linalg.eigvalsh(imm.P).min() > 0
