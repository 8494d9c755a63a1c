"""Motion models against closed forms written out here, independently of the code."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from airspace_sim.dynamics import models
from airspace_sim.dynamics.models import (
    constant_velocity,
    measurement_noise,
    paper_process_noise,
    position_measurement_matrix,
    transition,
    white_noise_acceleration,
)


def ct_closed_form(w: float, T: float) -> np.ndarray:
    """Bar-Shalom, Li & Kirubarajan (2001) §11.7 CT matrix for [x, vx, y, vy, Ω], ω ≠ 0."""
    s, c = math.sin(w * T), math.cos(w * T)
    return np.array(
        [
            [1, s / w, 0, -(1 - c) / w, 0],
            [0, c, 0, -s, 0],
            [0, (1 - c) / w, 1, s / w, 0],
            [0, s, 0, c, 0],
            [0, 0, 0, 0, 1],
        ]
    )


def cv_closed_form(T: float) -> np.ndarray:
    """The paper's A1."""
    return np.array(
        [[1, T, 0, 0, 0], [0, 1, 0, 0, 0], [0, 0, 1, T, 0], [0, 0, 0, 1, 0], [0, 0, 0, 0, 1]],
        dtype=float,
    )


def paper_literal_A2(w: float, T: float) -> np.ndarray:
    """The paper's A2 exactly as printed (with β = 0, so its 'β + π/4' is ω), sign error kept.

    The paper writes cos(ω)ΔT where cos(ωΔT) is meant; we read the arguments as ωΔT.
    Its third row has ``−(1 − cos ωT)/ω`` in the vx column.
    """
    s, c = math.sin(w * T), math.cos(w * T)
    return np.array(
        [
            [1, s / w, 0, -(1 - c) / w, 0],
            [0, c, 0, -s, 0],
            [0, -(1 - c) / w, 1, s / w, 0],
            [0, s, 0, c, 0],
            [0, 0, 0, 0, 1],
        ]
    )


OMEGAS = [math.pi / 4, -math.pi / 4, math.radians(3), -math.radians(1.1), 2.5, -7.0, 1e-3]


@pytest.mark.parametrize("w", OMEGAS)
@pytest.mark.parametrize("T", [0.1, 1.0, 4.5, 12.0])
def test_ct_matches_closed_form(w, T):
    np.testing.assert_allclose(
        transition(w, T), ct_closed_form(w, T), rtol=1e-12, atol=1e-12 * max(T, 1)
    )


def test_cv_is_paper_A1():
    for T in (0.1, 1.0, 5.0):
        np.testing.assert_array_equal(constant_velocity(T), cv_closed_form(T))
        np.testing.assert_array_equal(transition(0.0, T), cv_closed_form(T))


def test_vectorised_over_turn_rates():
    rng = np.random.default_rng(1)
    w = rng.uniform(-1, 1, size=(4, 3, 2))
    w[0, 0, 0] = 0.0
    F = transition(w, 0.7)
    assert F.shape == (4, 3, 2, 5, 5)
    for idx in np.ndindex(w.shape):
        expect = cv_closed_form(0.7) if w[idx] == 0 else ct_closed_form(w[idx], 0.7)
        np.testing.assert_allclose(F[idx], expect, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("w", OMEGAS + [0.0])
def test_velocity_rows_are_derivative_of_position_rows(w):
    """d/dT (position row) = velocity row: position integrates the velocity it carries."""
    T, h = 1.3, 1e-5
    dF = (transition(w, T + h) - transition(w, T - h)) / (2 * h)
    F = transition(w, T)
    np.testing.assert_allclose(dF[0], F[1], atol=1e-8)
    np.testing.assert_allclose(dF[2], F[3], atol=1e-8)


@settings(max_examples=200, deadline=None)
@given(
    w=st.floats(-3, 3, allow_nan=False),
    T1=st.floats(0, 20, allow_nan=False),
    T2=st.floats(0, 20, allow_nan=False),
)
def test_composition_is_semigroup(w, T1, T2):
    lhs = transition(w, T1) @ transition(w, T2)
    np.testing.assert_allclose(lhs, transition(w, T1 + T2), rtol=1e-9, atol=1e-9 * (1 + T1 + T2))


@pytest.mark.parametrize("w", [0.0, -0.0, 1e-12, -1e-12, 1e-300, -1e-300, 5e-324, 1e-8])
def test_small_turn_rate_tends_to_cv_without_nan(w):
    for T in (0.1, 1.0, 10.0):
        F = transition(w, T)
        assert np.all(np.isfinite(F))
        # Entries differ from CV by at most |ω|·max(T, T²/2) (sin ωT ≈ ωT, (1−cos ωT)/ω ≈ ωT²/2).
        np.testing.assert_allclose(
            F, cv_closed_form(T), rtol=0, atol=abs(w) * max(T, T * T) + 1e-15
        )
        # And the first-order term is right: (1 − cos ωT)/ω ≈ ωT²/2.
        np.testing.assert_allclose(F[2, 1], w * T * T / 2, rtol=1e-6, atol=1e-320)
        np.testing.assert_allclose(F[0, 3], -w * T * T / 2, rtol=1e-6, atol=1e-320)


def test_ct_converges_to_cv_continuously():
    T = 2.0
    ws = np.logspace(-1, -9, 9)
    err = np.abs(transition(ws, T) - cv_closed_form(T)).max(axis=(-1, -2))
    assert np.all(np.diff(err) < 0)  # monotone in ω
    np.testing.assert_allclose(
        err / ws, max(T, T * T / 2), rtol=0.2
    )  # sin ωT ≈ ωT, (1−cos)/ω ≈ ωT²/2


@pytest.mark.parametrize("w", [math.radians(3), -math.radians(3), math.pi / 4, -0.5])
@pytest.mark.parametrize("v", [120.0, 285.841])
def test_ct_trajectory_closes_circle_of_radius_v_over_w(w, v):
    """Flying ω for 2π/|ω| s in N steps returns to the start along a circle of radius v/|ω|."""
    N = 360
    dt = 2 * math.pi / abs(w) / N
    F = transition(w, dt)
    X = np.array([0.0, v, 0.0, 0.0, w])
    R = v / abs(w)
    centre = np.array([0.0, v / w])  # left of the velocity for ω > 0, right for ω < 0
    pts = []
    for _ in range(N):
        X = F @ X
        pts.append([X[0], X[2]])
        assert math.hypot(X[1], X[3]) == pytest.approx(v, rel=1e-12)
    pts = np.array(pts)
    np.testing.assert_allclose(np.hypot(*(pts - centre).T), R, rtol=1e-10)
    np.testing.assert_allclose(pts[-1], [0.0, 0.0], atol=1e-8 * R)
    np.testing.assert_allclose(X[[1, 3]], [v, 0.0], atol=1e-9 * v)
    # heading after a quarter of the steps is ±90°
    Fq = np.linalg.matrix_power(F, N // 4)
    Xq = Fq @ np.array([0.0, v, 0.0, 0.0, w])
    assert math.atan2(Xq[3], Xq[1]) == pytest.approx(math.copysign(math.pi / 2, w), abs=1e-9)


def test_paper_literal_A2_is_not_self_consistent_and_ours_is():
    """The paper's printed A2 has a sign error in row 3 (docs/paper-notes.md §1)."""
    w, T, h = math.pi / 4, 0.1, 1e-6
    paper = lambda t: paper_literal_A2(w, t)  # noqa: E731
    ours = lambda t: transition(w, t)  # noqa: E731
    for A, consistent in ((paper, False), (ours, True)):
        dA = (A(T + h) - A(T - h)) / (2 * h)
        mismatch = np.abs(dA[2] - A(T)[3]).max()  # d(north position)/dT vs north velocity row
        comp = np.abs(A(T) @ A(T) - A(2 * T)).max()
        if consistent:
            assert mismatch < 1e-6 and comp < 1e-12
        else:
            # d/dT of −(1−cos ωT)/ω is −sin ωT, but the velocity row says +sin ωT.
            assert mismatch == pytest.approx(2 * math.sin(w * T), rel=1e-4)
            assert comp > 1e-4
    # And the paper's A2 does not fly a circle: its track leaves the turn circle.
    N, v = 80, 200.0
    dt = 2 * math.pi / w / N
    R, centre = v / w, np.array([0.0, v / w])
    X = np.array([0.0, v, 0.0, 0.0, w])
    Xp = X.copy()
    dev, devp = 0.0, 0.0
    for _ in range(N):
        X, Xp = transition(w, dt) @ X, paper_literal_A2(w, dt) @ Xp
        dev = max(dev, abs(np.hypot(X[0] - centre[0], X[2] - centre[1]) - R))
        devp = max(devp, abs(np.hypot(Xp[0] - centre[0], Xp[2] - centre[1]) - R))
    # The error is second order in ωT per step (2(1−cos ωT)/ω · vx), so it is small but real.
    assert dev < 1e-9 * R
    assert devp > 0.02 * R


def test_paper_process_noise_as_given():
    np.testing.assert_array_equal(paper_process_noise(), np.diag([200.0, 0.1, 200.0, 0.1, 0.001]))


@pytest.mark.parametrize("sigma,T,sw", [(1.0, 1.0, 0.0), (0.5, 0.1, 1e-4), (3.0, 4.5, 0.01)])
def test_white_noise_acceleration_closed_form_and_psd(sigma, T, sw):
    Q = white_noise_acceleration(sigma, T, sw)
    block = sigma**2 * np.array([[T**4 / 4, T**3 / 2], [T**3 / 2, T**2]])
    expect = np.zeros((5, 5))
    expect[0:2, 0:2] = block
    expect[2:4, 2:4] = block
    expect[4, 4] = sw**2
    np.testing.assert_allclose(Q, expect, rtol=1e-14, atol=0)
    np.testing.assert_array_equal(Q, Q.T)
    assert np.linalg.eigvalsh(Q).min() >= -1e-12 * np.abs(Q).max()
    # Q = Γ σ² Γᵀ with Γ = [T²/2, T]: rank one per axis
    G = np.array([T**2 / 2, T])
    np.testing.assert_allclose(Q[0:2, 0:2], sigma**2 * np.outer(G, G), rtol=1e-14)


def test_wna_position_variance_grows_like_cubic():
    """Propagating P ← F P Fᵀ + Q from 0 over N CV steps gives, for piecewise-constant
    acceleration, var(x) = σ² T⁴ (N³/3 − N/12) exactly and var(vx) = σ² T² N; in the
    continuous limit that is q t³/3 with q = σ² T (Bar-Shalom et al. 2001, §6.2–6.3)."""
    sigma, T = 0.7, 0.5
    F, Q = constant_velocity(T), white_noise_acceleration(sigma, T)
    P = np.zeros((5, 5))
    for N in range(1, 2001):
        P = F @ P @ F.T + Q
        if N in (1, 2, 10, 2000):
            assert P[0, 0] == pytest.approx(sigma**2 * T**4 * (N**3 / 3 - N / 12), rel=1e-10)
            assert P[1, 1] == pytest.approx(sigma**2 * T**2 * N, rel=1e-10)
            assert P[2, 2] == pytest.approx(P[0, 0], rel=1e-12)
    t = 2000 * T
    assert P[0, 0] / (sigma**2 * T * t**3 / 3) == pytest.approx(1.0, rel=1e-5)


def test_measurement_model():
    H = position_measurement_matrix()
    X = np.array([1.0, 2.0, 3.0, 4.0, 5.0])
    np.testing.assert_array_equal(H @ X, [1.0, 3.0])
    np.testing.assert_array_equal(measurement_noise(), 2500.0 * np.eye(2))
    np.testing.assert_array_equal(measurement_noise(10.0), 100.0 * np.eye(2))
    assert models.POSITION == (0, 2) and models.VELOCITY == (1, 3) and models.TURN_RATE == 4
