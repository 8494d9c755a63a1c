"""Mode chain: Π validation, Π(ΔT) = expm(ΛΔT) from sojourn times, and sampling."""

import math

import numpy as np
import pytest
from scipy import stats

from airspace_sim.dynamics import presets
from airspace_sim.dynamics.markov import (
    generator_from_sojourn,
    transition_matrix_from_sojourn,
    validate_transition_matrix,
)
from airspace_sim.dynamics.truth import sample_modes
from airspace_sim.errors import UserError

PAPER_PI = [[0.8, 0.1, 0.1], [0.19, 0.8, 0.01], [0.19, 0.01, 0.8]]
SWITCH = [[0, 0.5, 0.5], [1, 0, 0], [1, 0, 0]]


def test_paper_pi_is_valid():
    P = validate_transition_matrix(PAPER_PI)
    assert P.dtype == float and P.shape == (3, 3)
    np.testing.assert_array_equal(P, PAPER_PI)


@pytest.mark.parametrize(
    "Pi,match",
    [
        ([[0.5, 0.5, 0.0], [0.2, 0.8, 0.0]], r"square.*\(2, 3\)"),
        ([0.5, 0.5], r"square"),
        ([], r"square"),
        ([[1.2, -0.2], [0.5, 0.5]], r"\[0, 1\] = -0.2 is negative"),
        ([[0.5, 0.4], [0.5, 0.5]], r"row 0 sums to 0.9"),
        (np.array(PAPER_PI).T, r"row 0 sums to 1.18"),  # the paper's 'sum over i' reading
        ([[np.nan, 1.0], [0.5, 0.5]], r"non-finite"),
        ([[np.inf, 0.0], [0.5, 0.5]], r"non-finite"),
        ([[0.5, 0.5], [0.5]], r"square"),
        ([["a", "b"], ["c", "d"]], r"numbers"),
    ],
)
def test_validate_rejects_with_clear_message(Pi, match):
    with pytest.raises(UserError, match=match) as e:
        validate_transition_matrix(Pi, name="scenario.toml: model.transition_matrix")
    msg = str(e.value)
    assert msg.startswith("scenario.toml: model.transition_matrix: ") and "\n" not in msg


@pytest.mark.parametrize("dt", [0.01, 0.1, 1.0, 4.5, 12.0, 100.0])
def test_sojourn_matrix_is_row_stochastic(dt):
    Pi = transition_matrix_from_sojourn([60.0, 20.0, 20.0], dt, SWITCH)
    assert np.all(Pi >= 0)
    np.testing.assert_allclose(Pi.sum(axis=1), 1.0, atol=1e-12)
    # Staying at least as likely as never having left: Π_ii ≥ exp(−ΔT/τ_i), equal to first order.
    tau = np.array([60.0, 20.0, 20.0])
    stay = np.exp(-dt / tau)
    assert np.all(np.diag(Pi) >= stay - 1e-12)
    if dt <= 1.0:
        np.testing.assert_allclose(np.diag(Pi), stay, atol=(dt / tau.min()) ** 2)


def test_two_state_chain_closed_form():
    """For two modes with rates a = 1/τ0, b = 1/τ1: Π00(t) = (b + a e^{−(a+b)t})/(a+b)."""
    t0, t1 = 30.0, 7.0
    a, b = 1 / t0, 1 / t1
    for dt in (0.1, 1.0, 10.0, 300.0):
        e = math.exp(-(a + b) * dt)
        expect = np.array(
            [
                [(b + a * e) / (a + b), a * (1 - e) / (a + b)],
                [b * (1 - e) / (a + b), (a + b * e) / (a + b)],
            ]
        )
        np.testing.assert_allclose(transition_matrix_from_sojourn([t0, t1], dt), expect, rtol=1e-12)


def test_generator_matrix():
    G = generator_from_sojourn([60.0, 20.0, 20.0], SWITCH)
    np.testing.assert_allclose(
        G, [[-1 / 60, 1 / 120, 1 / 120], [1 / 20, -1 / 20, 0], [1 / 20, 0, -1 / 20]], rtol=1e-15
    )
    np.testing.assert_allclose(G.sum(axis=1), 0.0, atol=1e-15)
    # default: uniform over the other modes
    np.testing.assert_allclose(generator_from_sojourn([10.0, 10.0, 10.0])[0], [-0.1, 0.05, 0.05])


@pytest.mark.parametrize("bad", [[0.0, 1.0], [-1.0, 2.0], [np.nan, 1.0], []])
def test_sojourn_rejects_bad_times(bad):
    with pytest.raises(UserError, match="sojourn_s"):
        transition_matrix_from_sojourn(bad, 1.0)


@pytest.mark.parametrize("dt", [0.0, -1.0, float("nan"), "1"])
def test_sojourn_rejects_bad_dt(dt):
    with pytest.raises(UserError, match="dt"):
        transition_matrix_from_sojourn([10.0, 10.0], dt)


@pytest.mark.parametrize("t1,t2", [(0.1, 0.1), (1.0, 2.5), (4.5, 12.0), (0.3, 60.0)])
def test_semigroup(t1, t2):
    P = lambda t: transition_matrix_from_sojourn([60.0, 20.0, 20.0], t, SWITCH)  # noqa: E731
    np.testing.assert_allclose(P(t1) @ P(t2), P(t1 + t2), atol=1e-12)
    # ten steps of 0.1 s are one step of 1 s
    np.testing.assert_allclose(np.linalg.matrix_power(P(0.1), 10), P(1.0), atol=1e-12)


def test_changing_dt_keeps_sojourn_in_seconds():
    """Mean run length in seconds, ΔT/(1 − Π_ii(ΔT)), stays τ_i for any ΔT, up to the short
    excursions a sampled chain cannot see: expanding expm gives
    ΔT/(1 − Π_ii) = τ_i + ΔT · τ_i² (Λ²)_ii / 2 + O(ΔT²). The stationary law does not depend
    on ΔT. A fixed per-step Π would scale the seconds with ΔT instead."""
    tau = np.array([60.0, 20.0, 20.0])
    G = generator_from_sojourn(tau, SWITCH)
    c = tau**2 * np.diag(G @ G) / 2  # (2, 7/12, 7/12) s per s of ΔT
    np.testing.assert_allclose(c, [2.0, 7 / 12, 7 / 12], rtol=1e-12)
    base = presets.get("realistic")
    mu_ref = base.mu0()
    # stationary law of the continuous chain: time share ∝ τ_i × visit rate
    np.testing.assert_allclose(mu_ref, [0.75, 0.125, 0.125], rtol=1e-9)
    for dt in (0.01, 0.05, 0.5, 1.0, 2.0):
        for p in (
            transition_matrix_from_sojourn(tau, dt, SWITCH),
            np.array(base.with_(dt=dt).transition_matrix),
        ):
            mean_s = dt / (1 - np.diag(p))
            np.testing.assert_allclose(mean_s - tau, c * dt, rtol=0.05)
            assert np.all(np.abs(mean_s / tau - 1) < 0.07)
        np.testing.assert_allclose(presets.get("realistic", dt=dt).mu0(), mu_ref, rtol=1e-9)
    # The paper's Π is per step: the seed preset keeps it per step (its sojourn in seconds
    # then scales with ΔT, which is why scenarios can give sojourn times instead).
    seed = presets.get("seed")
    assert seed.with_(dt=1.0).transition_matrix == seed.transition_matrix


def _run_lengths(modes: np.ndarray):
    """Completed run lengths per mode from (T, B) mode sequences (first and last runs dropped,
    as they are censored)."""
    runs = {}
    for col in modes.T:
        change = np.flatnonzero(col[1:] != col[:-1]) + 1
        if change.size < 2:
            continue
        lengths = np.diff(change)
        for m, n in zip(col[change[:-1]], lengths):
            runs.setdefault(int(m), []).append(int(n))
    return {m: np.array(v) for m, v in runs.items()}


def test_empirical_sojourn_from_sample_modes():
    """Run lengths of the sampled chain are geometric with mean 1/(1 − Π_ii): checked with a
    CLT bound on the mean and a chi-square goodness of fit, and in seconds against τ."""
    dt = 1.0
    tau = np.array([60.0, 20.0, 20.0])
    Pi = transition_matrix_from_sojourn(tau, dt, SWITCH)
    rng = np.random.default_rng(12345)
    B, T = 400, 3000
    q = rng.choice(3, size=B, p=[0.75, 0.125, 0.125])
    modes = np.empty((T, B), dtype=np.int64)
    for k in range(T):
        q = sample_modes(Pi, q, rng)
        modes[k] = q
    runs = _run_lengths(modes)
    for i in range(3):
        r = runs[i]
        p_leave = 1 - Pi[i, i]
        mean, sd = 1 / p_leave, math.sqrt(1 - p_leave) / p_leave
        assert r.size > 3000
        assert abs(r.mean() - mean) < 4.0 * sd / math.sqrt(r.size), (i, r.mean(), mean)
        assert abs(r.mean() * dt / tau[i] - 1) < 0.05  # seconds, see the test above
        # chi-square goodness of fit of the geometric law on quantile bins
        edges = np.unique(np.ceil(stats.geom.ppf(np.linspace(0, 1, 11)[1:-1], p_leave)).astype(int))
        edges = np.concatenate([[0], edges, [np.inf]])
        observed = np.histogram(r, bins=edges + 0.5)[0]  # bin (a, b] of integers
        expected = r.size * np.diff(stats.geom.cdf(edges, p_leave))
        chi2 = ((observed - expected) ** 2 / expected).sum()
        assert stats.chi2.sf(chi2, len(observed) - 1) > 1e-4, (i, observed, expected)
    # transitions out of each mode go where the switch probabilities say (chi-square)
    prev, nxt = modes[:-1].ravel(), modes[1:].ravel()
    for i in range(3):
        counts = np.bincount(nxt[prev == i], minlength=3)
        expected = counts.sum() * Pi[i]
        ok = expected > 0
        assert np.all(counts[~ok] == 0)
        chi2 = ((counts[ok] - expected[ok]) ** 2 / expected[ok]).sum()
        assert stats.chi2.sf(chi2, ok.sum() - 1) > 1e-4, (i, counts, expected)


class _FixedUniforms:
    """A stand-in generator whose `random` returns given numbers (to hit CDF edges)."""

    def __init__(self, u):
        self.u = np.asarray(u, dtype=float)

    def random(self, shape):
        return np.broadcast_to(self.u, shape).copy()


def test_sample_modes_never_draws_zero_probability_modes():
    # cumsum of this row is 0.9999999999999999 < 1: a u above it must not pick mode 3
    Pi = np.array(
        [[0.7, 0.2, 0.1, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0, 0, 0, 1.0]]
    )
    assert np.cumsum(Pi[0])[-2] < 1.0
    u = [0.0, 0.71, 0.9, 0.9999999999999999, np.nextafter(1.0, 0.0)]
    got = sample_modes(Pi, np.zeros(5, dtype=int), _FixedUniforms(u))
    np.testing.assert_array_equal(got, [0, 1, 2, 2, 2])
    # a leading zero-probability mode is never drawn, even for u = 0
    got = sample_modes(
        Pi, np.ones(3, dtype=int), _FixedUniforms([0.0, 0.5, np.nextafter(1.0, 0.0)])
    )
    np.testing.assert_array_equal(got, [1, 1, 1])


def test_sample_modes_frequencies():
    rng = np.random.default_rng(7)
    Pi = np.array(PAPER_PI)
    n = 200_000
    for i in range(3):
        got = sample_modes(Pi, np.full(n, i), rng)
        counts = np.bincount(got, minlength=3)
        assert stats.chisquare(counts, n * Pi[i]).pvalue > 1e-4
