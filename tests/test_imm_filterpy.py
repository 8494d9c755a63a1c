"""The batched IMM equals filterpy's ``IMMEstimator`` on the posterior x, P, μ.

Oracle: ``filterpy.kalman.IMMEstimator(filters, mu, M)`` with one ``KalmanFilter`` per mode
built with the same F, Q, H, R, x0, P0 (and ``B = u_j`` with a unit control for the offsets),
stepped with ``predict(u)`` then ``update(z)``. filterpy's ``x_prior`` is weighted with the
old μ rather than with c̄, so only posteriors are compared.

Tolerance: every entry to 1e-9 relative (``rtol=1e-9``). Entries that are near zero only
through cancellation (an x–y cross-covariance, a turn rate Σ μ_j ω_j, a velocity component
along an axis) cannot be compared relatively, so each quantity is first divided by its
natural scale from filterpy's covariance — x_i by σ_i, P_ij by σ_i σ_j (a fixed positive
factor, which leaves relative errors unchanged) — and ``atol=1e-12`` then means "to 10⁻¹² of
a standard deviation", far below anything that matters and far above rounding (≈10⁻¹⁵).
μ gets ``atol=1e-14``: probabilities below that are immaterial, and it absorbs filterpy's
likelihood floor (``sys.float_info.min`` where ``exp`` underflows).

filterpy runs about 10³ tracker-updates/s (less on a loaded machine), so the B = 1000 case
runs all 1000 trackers in the IMM for 500 steps and checks a random subset of 10 against
their own filterpy runs at every one of the 500 steps, plus all 1000 against theirs for the
first 2 steps (the whole batch's first two steps are where the different x0, P0, μ0 differ
most).
"""

from __future__ import annotations

import numpy as np
import pytest

filterpy = pytest.importorskip("filterpy")
from filterpy.kalman import IMMEstimator, KalmanFilter  # noqa: E402

from airspace_sim.dynamics import presets, truth  # noqa: E402
from airspace_sim.tracking import IMM  # noqa: E402

ONE = np.ones((1, 1))


def filterpy_imm(args: dict, x0: np.ndarray, P0: np.ndarray, mu0: np.ndarray) -> IMMEstimator:
    """filterpy's IMM for one tracker: one KalmanFilter per mode, offsets as B u with u = 1."""
    F, Q = args["transitions"], args["process_noise"]
    H, R = args["measurement_matrix"], args["measurement_noise"]
    U = args.get("offsets")
    M, n, _ = F.shape
    filters = []
    for j in range(M):
        kf = KalmanFilter(dim_x=n, dim_z=H.shape[0], dim_u=1)
        kf.F, kf.Q, kf.H, kf.R = F[j].copy(), Q[j].copy(), H.copy(), R.copy()
        kf.B = (np.zeros((n, 1)) if U is None else U[j][:, None]).copy()
        kf.x = x0[:, None].copy()
        kf.P = P0.copy()
        filters.append(kf)
    return IMMEstimator(filters, mu0.copy(), args["transition_matrix"].copy())


def filterpy_step(f: IMMEstimator, z: np.ndarray) -> None:
    f.predict(u=ONE)
    f.update(z)


def assert_posterior_close(x, P, mu, rx, rP, rmu):
    """x (B, n), P (B, n, n), mu (B, M) against the reference, as explained in the module doc."""
    s = np.sqrt(np.einsum("bii->bi", rP))
    np.testing.assert_allclose(x / s, rx / s, rtol=1e-9, atol=1e-12)
    ss = s[:, :, None] * s[:, None, :]
    np.testing.assert_allclose(P / ss, rP / ss, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(mu, rmu, rtol=1e-9, atol=1e-14)


def random_initial(rng, x_true: np.ndarray, M: int, sigmas: np.ndarray):
    """Per-tracker x0 (B, n) near the truth, random SPD P0 (B, n, n), random μ0 (B, M)."""
    B, n = x_true.shape
    scale = sigmas * rng.uniform(0.5, 2.0, (B, n))
    C = rng.uniform(-0.3, 0.3, (B, n, n))
    C = np.eye(n) + 0.5 * (C + np.swapaxes(C, 1, 2)) * (1 - np.eye(n))
    C = C @ np.swapaxes(C, 1, 2)  # SPD correlation-like matrix
    d = np.sqrt(np.einsum("bii->bi", C))
    C = C / (d[:, :, None] * d[:, None, :])
    P0 = C * (scale[:, :, None] * scale[:, None, :])
    L = np.linalg.cholesky(P0)
    x0 = x_true + np.einsum("bij,bj->bi", L, rng.standard_normal((B, n)))
    mu0 = rng.dirichlet(np.ones(M), B)
    return x0, P0, mu0


def run_case(args, z, x0, P0, mu0, check_rows, full_steps=0):
    """Run our IMM over all of z (T, B, m); compare rows ``check_rows`` at every step and
    all rows for the first ``full_steps`` steps against filterpy."""
    T, B, _ = z.shape
    imm = IMM(x0=x0, P0=P0, mu0=mu0, **args)
    fp_all = [filterpy_imm(args, x0[b], P0[b], mu0[b]) for b in range(B)] if full_steps else []
    fp = {
        b: (fp_all[b] if fp_all else filterpy_imm(args, x0[b], P0[b], mu0[b])) for b in check_rows
    }
    rows = np.asarray(check_rows)
    for k in range(T):
        imm.step(z[k])
        assert not imm.gated.any(), "test measurements must stay inside the gate"
        if k < full_steps:
            for f, zb in zip(fp_all, z[k]):
                filterpy_step(f, zb)
            assert_posterior_close(
                imm.x, imm.P, imm.mu,
                np.array([f.x[:, 0] for f in fp_all]),
                np.array([f.P for f in fp_all]),
                np.array([f.mu for f in fp_all]),
            )  # fmt: skip
        else:
            for b in rows:
                filterpy_step(fp[b], z[k, b])
        assert_posterior_close(
            imm.x[rows], imm.P[rows], imm.mu[rows],
            np.array([fp[b].x[:, 0] for b in rows]),
            np.array([fp[b].P for b in rows]),
            np.array([fp[b].mu for b in rows]),
        )  # fmt: skip
    return imm


SIGMAS_5 = np.array([50.0, 20.0, 50.0, 20.0, 0.3])


@pytest.mark.parametrize("preset", ["seed", "realistic"])
def test_single_tracker_500_steps(preset):
    pre = presets.get(preset)
    args = pre.imm_arguments()
    rng = np.random.default_rng(11)
    tr = truth.simulate(pre, 501, 1, rng)
    x0, P0, mu0 = random_initial(rng, tr.states[0], pre.n_modes, SIGMAS_5)
    run_case(args, tr.measurements[1:], x0, P0, mu0, check_rows=[0])


def test_1000_trackers_500_steps():
    pre = presets.get("seed")
    args = pre.imm_arguments()
    rng = np.random.default_rng(12)
    B = 1000
    tr = truth.simulate(pre, 501, B, rng)
    x0, P0, mu0 = random_initial(rng, tr.states[0], pre.n_modes, SIGMAS_5)
    rows = np.sort(rng.choice(B, 10, replace=False))
    imm = run_case(args, tr.measurements[1:], x0, P0, mu0, check_rows=rows, full_steps=2)
    assert imm.B == B


def random_model(rng, M: int, n: int, m: int):
    """A random stable jump-linear model with offsets, dense F and H, correlated Q and R."""
    F = []
    for _ in range(M):
        A = rng.standard_normal((n, n))
        Qo, _ = np.linalg.qr(A)
        F.append(0.97 * Qo + 0.02 * rng.standard_normal((n, n)))
    F = np.array(F)
    G = rng.standard_normal((M, n, n)) * 0.3
    Q = G @ np.swapaxes(G, 1, 2) + 0.05 * np.eye(n)
    H = rng.standard_normal((m, n))
    Gr = rng.standard_normal((m, m))
    R = Gr @ Gr.T + 0.5 * np.eye(m)
    Pi = rng.dirichlet(np.ones(M), M) * 0.3 + 0.7 * np.eye(M)
    U = rng.standard_normal((M, n)) * 0.5
    return dict(
        transitions=F, process_noise=Q, measurement_matrix=H, measurement_noise=R,
        transition_matrix=Pi, offsets=U,
    )  # fmt: skip


def simulate_model(rng, args, T: int, x0: np.ndarray) -> np.ndarray:
    """Measurements (T, B, m) of a Markov-switching truth of the given model."""
    F, Q, H, R = (
        args[k] for k in ("transitions", "process_noise", "measurement_matrix", "measurement_noise")
    )
    Pi, U = args["transition_matrix"], args["offsets"]
    B, n = x0.shape
    M = F.shape[0]
    q = rng.integers(0, M, B)
    x = x0.copy()
    zs = []
    LQ = np.linalg.cholesky(Q)
    LR = np.linalg.cholesky(R)
    for _ in range(T):
        q = np.array([rng.choice(M, p=Pi[i]) for i in q])
        x = (
            np.einsum("bij,bj->bi", F[q], x)
            + U[q]
            + np.einsum("bij,bj->bi", LQ[q], rng.standard_normal((B, n)))
        )
        zs.append(x @ H.T + rng.standard_normal((B, H.shape[0])) @ LR.T)
    return np.array(zs)


@pytest.mark.parametrize("M,n,m", [(4, 4, 3), (2, 3, 1), (3, 6, 2)])
def test_random_models_general_m(M, n, m):
    """Dense F and H, general measurement dimension (Cholesky path for m = 3)."""
    rng = np.random.default_rng(100 + 10 * M + n + m)
    args = random_model(rng, M, n, m)
    B = 2
    x_true = rng.standard_normal((B, n))
    z = simulate_model(rng, args, 200, x_true)
    x0, P0, mu0 = random_initial(rng, x_true, M, np.ones(n))
    run_case(args, z, x0, P0, mu0, check_rows=list(range(B)))


def test_filterpy_kf_update_is_joseph_form():
    """The oracle's covariance update is the Joseph form P = (I−KH)P(I−KH)ᵀ + KRKᵀ."""
    rng = np.random.default_rng(3)
    kf = KalmanFilter(dim_x=3, dim_z=1)
    kf.H = np.array([[1.0, 0.0, 0.0]])
    kf.R = np.array([[2.0]])
    G = rng.standard_normal((3, 3))
    kf.P = G @ G.T + np.eye(3)
    P, H, R = kf.P.copy(), kf.H, kf.R
    kf.update(np.array([[1.0]]))
    S = H @ P @ H.T + R
    K = P @ H.T @ np.linalg.inv(S)
    A = np.eye(3) - K @ H
    np.testing.assert_allclose(kf.P, A @ P @ A.T + K @ R @ K.T, rtol=1e-14)
