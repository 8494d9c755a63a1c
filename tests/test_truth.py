"""Markov-switching truth generator: determinism, kinematics per mode, noise statistics."""

import math

import numpy as np
import pytest
from scipy import stats

from airspace_sim.dynamics import models, presets
from airspace_sim.dynamics.truth import Trajectories, noise_factor, simulate
from airspace_sim.errors import UserError


def _quiet(preset, Pi=None):
    """No process noise, and optionally a fixed mode chain."""
    changes = dict(process_noise=np.zeros((5, 5)))
    if Pi is not None:
        changes["transition_matrix"] = Pi
    return preset.with_(**changes)


@pytest.mark.parametrize("name", ["seed", "realistic"])
def test_seeded_determinism_bit_for_bit(name):
    p = presets.get(name)
    a = simulate(p, 50, 7, np.random.default_rng(42))
    b = simulate(p, 50, 7, np.random.default_rng(42))
    c = simulate(p, 50, 7, np.random.default_rng(43))
    assert isinstance(a, Trajectories) and a.dt == p.dt
    assert (
        a.states.shape == (50, 7, 5)
        and a.modes.shape == (50, 7)
        and a.measurements.shape == (50, 7, 2)
    )
    for f in ("states", "modes", "measurements"):
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f))
    assert not np.array_equal(a.measurements, c.measurements)


def test_measurement_noise_covariance():
    p = presets.get("realistic")
    n_t, B = 4, 25_000
    tr = simulate(p, n_t, B, np.random.default_rng(3))
    e = (tr.measurements - tr.states[..., [0, 2]]).reshape(-1, 2)
    n, s2 = e.shape[0], p.measurement_sigma**2
    C = np.cov(e.T, bias=True)
    # CLT: sd of a sample variance is σ²√(2/n), of a sample covariance σ²/√n
    assert abs(C[0, 0] - s2) < 5 * s2 * math.sqrt(2 / n)
    assert abs(C[1, 1] - s2) < 5 * s2 * math.sqrt(2 / n)
    assert abs(C[0, 1]) < 5 * s2 / math.sqrt(n)
    assert np.all(np.abs(e.mean(axis=0)) < 5 * p.measurement_sigma / math.sqrt(n))


def test_process_noise_increments_have_covariance_Q():
    """X(k) − A_q X(k−1) ~ N(0, Q) (position/velocity part; Ω is the mode's rate)."""
    p = presets.get("realistic").with_(transition_matrix=np.eye(3))
    B = 40_000
    tr = simulate(p, 2, B, np.random.default_rng(5), mode0=np.zeros(B, dtype=int))
    w = tr.states[1] - tr.states[0] @ models.constant_velocity(p.dt).T
    Q = np.array(p.process_noise)
    C = np.cov(w[:, :4].T, bias=True)
    sd = np.sqrt(np.outer(np.diag(Q), np.diag(Q))[:4, :4] * 2 / B)  # ≥ sd of each entry
    assert np.all(np.abs(C - Q[:4, :4]) < 5 * sd)
    np.testing.assert_array_equal(w[:, 4], 0.0)
    L = noise_factor(Q)
    np.testing.assert_allclose(L @ L.T, Q, atol=1e-15)


@pytest.mark.parametrize("name", ["seed", "realistic"])
def test_straight_mode_is_a_straight_line_when_Q_is_zero(name):
    p = _quiet(presets.get(name), np.eye(3))
    B, T = 20, 200
    tr = simulate(p, T, B, np.random.default_rng(1), mode0=np.zeros(B, dtype=int))
    t = p.dt * np.arange(T)[:, None]
    v0 = tr.states[0][:, [1, 3]]
    pos = tr.states[..., [0, 2]]
    np.testing.assert_allclose(
        pos, tr.states[0][None, :, [0, 2]] + t[..., None] * v0[None], rtol=1e-12, atol=1e-9
    )
    np.testing.assert_array_equal(tr.states[..., [1, 3]], np.broadcast_to(v0, (T, B, 2)))
    assert np.all(tr.modes == 0) and np.all(tr.states[..., 4] == 0.0)


@pytest.mark.parametrize("name", ["seed", "realistic"])
@pytest.mark.parametrize("mode", [1, 2])
def test_turn_mode_turns_at_its_rate(name, mode):
    p = _quiet(presets.get(name), np.eye(3))
    w = p.turn_rates[mode]
    assert (w > 0) == (mode == 1)  # mode 1 left (CCW), mode 2 right
    B, T = 10, 300
    tr = simulate(p, T, B, np.random.default_rng(2), mode0=np.full(B, mode))
    vx, vy = tr.states[..., 1], tr.states[..., 3]
    speed = np.hypot(vx, vy)
    np.testing.assert_allclose(speed, np.broadcast_to(speed[0], speed.shape), rtol=1e-10)
    dheading = np.angle(np.exp(1j * (np.diff(np.arctan2(vy, vx), axis=0))))
    np.testing.assert_allclose(dheading, w * p.dt, atol=1e-10)
    assert np.all(tr.states[..., 4] == w)
    # on a circle of radius v/|ω| around the centre to the left (ω>0) or right of the velocity
    x0 = tr.states[0]
    centre = np.stack([x0[:, 0] - x0[:, 3] / w, x0[:, 2] + x0[:, 1] / w], axis=-1)
    r = np.hypot(*(tr.states[..., [0, 2]] - centre).transpose(2, 0, 1))
    np.testing.assert_allclose(r, np.broadcast_to(speed[0] / abs(w), r.shape), rtol=1e-9)


@pytest.mark.parametrize("start", ["stationary", "straight"])
def test_mode_frequencies_match_stationary_law(start):
    """Across independent targets, the mode at a late step follows the stationary law
    (multinomial chi-square); from the stationary law it does at every step."""
    p = presets.get("realistic")
    B, T = 20_000, 150  # 150 s ≫ mixing time (~15 s)
    mode0 = None if start == "stationary" else np.zeros(B, dtype=int)
    tr = simulate(p, T, B, np.random.default_rng(11), mode0=mode0)
    mu = p.mu0()
    for k in [0, T // 2, T - 1] if start == "stationary" else [T - 1]:
        counts = np.bincount(tr.modes[k], minlength=3)
        assert stats.chisquare(counts, B * mu).pvalue > 1e-4, (k, counts / B, mu)
    # the time share over all steps too (correlated in time: a loose bound)
    share = np.bincount(tr.modes[T // 2 :].ravel(), minlength=3) / tr.modes[T // 2 :].size
    np.testing.assert_allclose(share, mu, atol=0.01)


def test_seed_preset_numbers():
    p = presets.get("seed")
    assert p.dt == 0.1 and p.turn_rates == (0.0, math.pi / 4, -math.pi / 4)
    np.testing.assert_array_equal(
        p.transition_matrix, [[0.8, 0.1, 0.1], [0.19, 0.8, 0.01], [0.19, 0.01, 0.8]]
    )
    np.testing.assert_array_equal(p.process_noise, models.paper_process_noise())
    np.testing.assert_array_equal(p.mu0(), [1.0, 0.0, 0.0])
    assert p.speed_range == (presets.V_CRUISE, 2 * presets.V_CRUISE)
    tr = simulate(p, 3, 1000, np.random.default_rng(0))
    speed = np.hypot(tr.states[0, :, 1], tr.states[0, :, 3])
    assert speed.min() >= presets.V_CRUISE and speed.max() <= 2 * presets.V_CRUISE


def test_preset_with_dt_rebuilds_continuous_time_numbers():
    r = presets.get("realistic")
    r2 = r.with_(dt=0.5)
    np.testing.assert_allclose(r2.process_noise, models.white_noise_acceleration(0.5, 0.5, 1e-4))
    np.testing.assert_allclose(
        r2.filter_process_noise, models.white_noise_acceleration(1.0, 0.5, 1e-4)
    )
    assert r2 == presets.get("realistic", dt=0.5) == presets.realistic(0.5)
    # an explicit per-step Q stays as given
    z = r.with_(process_noise=np.zeros((5, 5)))
    assert np.all(np.array(z.with_(dt=2.0).process_noise) == 0)


def test_imm_arguments_shapes_and_mode_pinning():
    for name in ("seed", "realistic"):
        p = presets.get(name)
        a = p.imm_arguments()
        M = p.n_modes
        assert a["transitions"].shape == (M, 5, 5) and a["process_noise"].shape == (M, 5, 5)
        assert a["measurement_matrix"].shape == (2, 5) and a["measurement_noise"].shape == (2, 2)
        assert a["offsets"].shape == (M, 5)
        for j in range(M):
            x = np.array([1.0, 2.0, 3.0, 4.0, 0.7])
            xp = a["transitions"][j] @ x + a["offsets"][j]
            assert xp[4] == p.turn_rates[j]
            np.testing.assert_allclose(xp[:4], (models.transition(p.turn_rates[j], p.dt) @ x)[:4])
    mu = presets.get("realistic").mu0()
    np.testing.assert_allclose(
        mu @ np.array(presets.get("realistic").transition_matrix), mu, atol=1e-12
    )


@pytest.mark.parametrize(
    "kwargs,match",
    [
        (dict(dt=0.0), "dt"),
        (dict(transition_matrix=[[0.5, 0.5], [0.5, 0.5]]), r"expected \(3, 3\)"),
        (dict(transition_matrix=[[0.5, 0.6, 0.0], [0, 1, 0], [0, 0, 1]]), "row 0 sums"),
        (dict(process_noise=-np.eye(5)), "positive semi-definite"),
        (dict(measurement_sigma=-1.0), "measurement_sigma"),
        (dict(initial_mode_probabilities=(0.5, 0.5)), "initial_mode_probabilities"),
    ],
)
def test_preset_validation(kwargs, match):
    with pytest.raises(UserError, match=match):
        presets.get("realistic").with_(**kwargs)


def test_unknown_preset_and_bad_simulate_inputs():
    with pytest.raises(
        UserError, match="known: dense-turns, imm-ct, imm-ct-airliner, realistic, seed, turn-rate"
    ):
        presets.get("nope")
    p = presets.get("realistic")
    with pytest.raises(UserError, match="x0"):
        simulate(p, 5, 2, x0=np.zeros((3, 5)))
    with pytest.raises(UserError, match="mode0"):
        simulate(p, 5, 2, mode0=[0, 3])
