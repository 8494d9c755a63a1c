"""Conflict probability: disc probability vs closed forms and Monte Carlo, limits, mixture."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.special import ndtr
from scipy.stats import ncx2

from airspace_sim.avoidance import conflict_probability, probability_inside_circle
from airspace_sim.geometry import rotate

R = 3000.0


@settings(max_examples=150, deadline=None)
@given(st.floats(-3.0, 3.0), st.floats(-3.0, 3.0), st.floats(-2.0, 4.5))
def test_isotropic_matches_noncentral_chi_square(mx, my, log_sigma):
    # |X|²/σ² ~ χ'²(2, |m|²/σ²) for X ~ N(m, σ² I)
    m = np.array([mx, my]) * R
    s = 10.0**log_sigma
    exact = ncx2.cdf(R**2 / s**2, 2, m @ m / s**2)
    tol = 1e-7
    if not np.isfinite(exact):
        # scipy's ncx2 gives NaN at huge noncentrality (σ ≪ R, mean near the circle); there
        # the circle is a straight line on the σ scale: P = Φ((R − |m|)/σ) to O(σ/R)
        exact, tol = ndtr((R - np.hypot(*m)) / s), 1e-5
    assert probability_inside_circle(m, s**2 * np.eye(2), R) == pytest.approx(exact, abs=tol)


def test_centred_isotropic_closed_form():
    s = np.array([100.0, 1000.0, 3000.0, 10000.0])
    got = probability_inside_circle(np.zeros((4, 2)), s[:, None, None] ** 2 * np.eye(2), R)
    assert got == pytest.approx(1 - np.exp(-(R**2) / (2 * s**2)), abs=1e-10)


@settings(max_examples=120, deadline=None)
@given(st.floats(-2.0, 2.0), st.floats(-2.0, 2.0), st.floats(-np.pi, np.pi), st.floats(0.0, 4.0))
def test_rank_one_covariance_closed_form(mx, my, angle, log_sigma):
    # X = m + σ z u: inside iff σ² z² + 2σ (m·u) z + |m|² − R² < 0, an interval in z
    m = np.array([mx, my]) * R
    u = np.array([np.cos(angle), np.sin(angle)])
    s = 10.0**log_sigma
    a, b, c = s**2, 2 * s * (m @ u), m @ m - R**2
    disc = b * b - 4 * a * c
    exact = 0.0
    if disc > 0:
        z1, z2 = (-b - np.sqrt(disc)) / (2 * a), (-b + np.sqrt(disc)) / (2 * a)
        exact = ndtr(z2) - ndtr(z1)
    got = probability_inside_circle(m, s**2 * np.outer(u, u), R)
    assert got == pytest.approx(exact, abs=1e-7)


CASES = [
    # mean (in units of R), covariance square-root L (m): Σ = L Lᵀ
    ((0.0, 1.0), [[100.0, 0.0], [0.0, 2.0]]),  # on the boundary, thin across it
    ((0.5, 0.5), [[800.0, 0.0], [600.0, 300.0]]),
    ((1.2, -0.3), [[1500.0, 0.0], [-1200.0, 500.0]]),
    ((0.0, 0.0), [[3000.0, 0.0], [0.0, 3.0]]),  # very elongated, centred
    ((0.99, 0.0), [[1.0, 0.0], [0.0, 2000.0]]),
    ((-2.0, 1.0), [[4000.0, 0.0], [3000.0, 2000.0]]),
]


@pytest.mark.parametrize("mean, chol", CASES)
def test_against_seeded_monte_carlo(mean, chol):
    rng = np.random.default_rng(12345)
    m = np.array(mean) * R
    L = np.array(chol)
    n = 400_000
    x = rng.standard_normal((n, 2)) @ L.T + m
    mc = np.mean(np.hypot(x[:, 0], x[:, 1]) < R)
    std = np.sqrt(max(mc * (1 - mc), 1.0 / n) / n)
    got = probability_inside_circle(m, L @ L.T, R)
    assert abs(got - mc) <= 5 * std + 1e-5


def test_zero_covariance_is_indicator():
    means = np.array([[0.0, 0.0], [2999.0, 0.0], [2000.0, 2000.0], [3001.0, 0.0], [0.0, -5000.0]])
    got = probability_inside_circle(means, np.zeros((5, 2, 2)), R)
    assert np.array_equal(got, [1.0, 1.0, 1.0, 0.0, 0.0])


def test_huge_covariance_gives_almost_zero():
    got = probability_inside_circle(np.array([1000.0, 0.0]), 1e14 * np.eye(2), R)
    assert 0.0 <= got < 1e-6
    assert got == pytest.approx(R**2 / (2 * 1e14), rel=1e-3)  # small-disc limit


def test_tiny_covariance_far_outside_and_inside():
    # 10σ from the boundary: the exact values differ from 0 and 1 by about 1e-23
    assert probability_inside_circle(np.array([3100.0, 0.0]), 100.0 * np.eye(2), R) < 1e-13
    assert probability_inside_circle(np.array([2900.0, 0.0]), 100.0 * np.eye(2), R) > 1 - 1e-13


@settings(max_examples=100, deadline=None)
@given(
    st.floats(-2.0, 2.0),
    st.floats(-2.0, 2.0),
    st.floats(1.0, 3.5),
    st.floats(0.0, 3.5),
    st.floats(-np.pi, np.pi),
    st.floats(-np.pi, np.pi),
)
def test_rotation_invariance(mx, my, la, lb, phi, alpha):
    m = np.array([mx, my]) * R
    u = np.array([np.cos(phi), np.sin(phi)])
    w = np.array([-u[1], u[0]])
    cov = 10 ** (2 * la) * np.outer(u, u) + 10 ** (2 * lb) * np.outer(w, w)
    c, s = np.cos(alpha), np.sin(alpha)
    rot = np.array([[c, -s], [s, c]])
    a = probability_inside_circle(m, cov, R)
    b = probability_inside_circle(rotate(m, alpha), rot @ cov @ rot.T, R)
    assert b == pytest.approx(a, abs=1e-9)


def test_mixture_aggregation_and_shapes():
    rng = np.random.default_rng(2)
    n, k, modes, steps = 3, 2, 3, 4
    xs = rng.uniform(-2 * R, 2 * R, (n, k, modes, steps, 2))
    L = rng.normal(0, 800, (n, k, modes, steps, 2, 2))
    ps = L @ np.swapaxes(L, -1, -2)
    mu = rng.dirichlet(np.ones(modes), (n, k))
    got = conflict_probability(xs, ps, mu, R)
    assert got.shape == (n, k)
    for i in range(n):
        for j in range(k):
            expect = sum(
                mu[i, j, q]
                * max(
                    probability_inside_circle(xs[i, j, q, s], ps[i, j, q, s], R)
                    for s in range(steps)
                )
                for q in range(modes)
            )
            assert got[i, j] == pytest.approx(expect, abs=1e-12)
    # one-hot mode probabilities pick that mode's worst step
    one_hot = np.zeros_like(mu)
    one_hot[..., 1] = 1.0
    per = probability_inside_circle(xs[..., 1, :, :], ps[..., 1, :, :, :], R).max(axis=-1)
    assert np.allclose(conflict_probability(xs, ps, one_hot, R), per, atol=1e-15)
    assert np.all((got >= 0) & (got <= 1))


def test_mixture_limits():
    # deterministic predictions: the mode probability mass of the modes that enter the circle
    xs = np.array(
        [
            [[5000.0, 0.0], [2000.0, 0.0]],
            [[5000.0, 0.0], [4000.0, 0.0]],
            [[0.0, 5000.0], [0.0, 2500.0]],
        ]
    )  # (M=3, S=2, 2)
    ps = np.zeros((3, 2, 2, 2))
    mu = np.array([0.2, 0.5, 0.3])
    assert conflict_probability(xs, ps, mu, R) == pytest.approx(0.5)
    assert conflict_probability(xs, ps + 1e14 * np.eye(2), mu, R) < 1e-6


def test_far_means_are_zero_without_quadrature_and_near_ones_unchanged():
    from airspace_sim.avoidance import probability as pr

    rng = np.random.default_rng(5)
    n = 400
    mean = rng.uniform(-60000, 60000, size=(n, 2))
    a = rng.normal(size=(n, 2, 2)) * rng.uniform(10, 3000, size=(n, 1, 1))
    cov = a @ np.swapaxes(a, -1, -2)
    R = 3000.0
    got = pr.probability_inside_circle(mean, cov, R)
    full = pr._inside(mean, cov, np.full(n, R))  # the quadrature everywhere
    d = np.hypot(*mean.T)
    u = mean / d[:, None]
    sig_n = np.sqrt(np.einsum("ri,rij,rj->r", u, cov, u))  # std along the mean's direction
    far = d - R > pr.WINDOW_SIGMAS * sig_n
    assert 0 < far.sum() < n
    assert np.all(got[far] == 0.0) and np.all(full[far] < 1e-13)
    np.testing.assert_array_equal(got[~far], full[~far])


def test_conflict_probability_bound_is_an_upper_bound_and_tight_far_out():
    from airspace_sim.avoidance.probability import conflict_probability_bound

    rng = np.random.default_rng(9)
    N, M, S = 300, 3, 4
    xs = rng.uniform(-15000, 15000, size=(N, M, S, 2))
    a = rng.normal(size=(N, M, S, 2, 2)) * rng.uniform(50, 4000, size=(N, M, S, 1, 1))
    Ps = a @ np.swapaxes(a, -1, -2)
    mu = rng.dirichlet(np.ones(M), size=N)
    exact = conflict_probability(xs, Ps, mu, 3000.0)
    bound = conflict_probability_bound(xs, Ps, mu, 3000.0)
    assert np.all(bound >= exact - 1e-12)
    assert np.all((bound >= 0) & (bound <= 1))
    # a point far out along x with small spread: both essentially 0; inside: bound 1
    x1 = np.array([[[[20000.0, 0.0]]]])
    P1 = np.array([[[np.diag([100.0**2, 5000.0**2])]]])
    assert conflict_probability_bound(x1, P1, [[1.0]], 3000.0)[0] < 1e-12
    assert conflict_probability_bound(x1 * 0.01, P1, [[1.0]], 3000.0)[0] == 1.0
    assert conflict_probability_bound(x1 * 0.0, P1, [[1.0]], 3000.0)[0] == 1.0  # at the origin
    assert np.isnan(conflict_probability_bound(x1 * np.nan, P1, [[1.0]], 3000.0)[0])


def test_probabilistic_bands_threats_unchanged_by_the_bound():
    # the resolver runs the quadrature only where the bound reaches the threshold: its
    # threats and advice equal those from the exact probability everywhere
    from airspace_sim.avoidance.resolvers import ProbabilisticBandsResolver

    rng = np.random.default_rng(2)
    N, K, M, S = 40, 6, 3, 5
    r = rng.uniform(-20000, 20000, size=(N, K, 2))
    v = rng.uniform(-400, 400, size=(N, K, 2))
    t = np.linspace(6.0, 30.0, S)
    turn = rng.normal(0, 30, size=(N, K, M, 1, 2)) * t[:, None] ** 1.5 / 10
    xs = r[:, :, None, None] + v[:, :, None, None] * t[:, None] + turn
    a = rng.normal(size=(N, K, M, S, 2, 2)) * (50 + 20 * t)[:, None, None]
    Ps = a @ np.swapaxes(a, -1, -2)
    mu = rng.dirichlet(np.ones(M), size=(N, K))
    valid = rng.random((N, K)) < 0.9
    vo = np.tile([230.0, 0.0], (N, 1))
    res = ProbabilisticBandsResolver(ProbabilisticBandsResolver.Params(threshold=0.05))
    out = res.resolve(
        vo, r, v - vo[:, None], valid, np.radians(90.0), mode_predictions=(xs, Ps, mu)
    )
    exact = np.where(valid, conflict_probability(xs, Ps, mu, 3000.0), 0.0)
    threat = valid & (exact >= 0.05)
    assert 0 < threat.sum() < valid.sum()
    np.testing.assert_array_equal(out.conflict, threat.any(axis=-1))
    np.testing.assert_array_equal(out.probability[threat], exact[threat])
    assert np.all(out.probability[valid & ~threat] < 0.05)
