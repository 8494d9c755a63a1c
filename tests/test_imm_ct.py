"""The estimated-rate coordinated-turn mode (EKF) against independent references.

- Its Jacobian (``coordinated_turn.transition``) against complex-step derivatives of the
  closed-form turn written here (exact to rounding, no step-size error).
- A one-mode IMM with that mode against filterpy's ``ExtendedKalmanFilter`` step by step,
  and a two-mode IMM (pinned straight + estimated turn) against filterpy's ``IMMEstimator``
  over an EKF and a ``KalmanFilter``: the EKF's F is set to the complex-step Jacobian of the
  test's own f at each predict.
- Irregular sampling: ``step(z, dt)`` equals an IMM built at that dt, bit for bit.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

filterpy = pytest.importorskip("filterpy")
from filterpy.kalman import ExtendedKalmanFilter, IMMEstimator, KalmanFilter  # noqa: E402

from airspace_sim.dynamics import presets  # noqa: E402
from airspace_sim.tracking import IMM, coordinated_turn  # noqa: E402


def f_ct(x, T):
    """Coordinated turn at the state's own rate (works on complex x for complex steps)."""
    px, vx, py, vy, w = x
    s, c = np.sin(w * T) / w, (1 - np.cos(w * T)) / w
    return np.array(
        [px + s * vx - c * vy, np.cos(w * T) * vx - np.sin(w * T) * vy, py + c * vx + s * vy,
         np.sin(w * T) * vx + np.cos(w * T) * vy, w]
    )  # fmt: skip


def jac_complex_step(x, T, h=1e-30):
    """Complex-step Jacobian of :func:`f_ct`, in extended precision (so the closed form's
    cancellation at tiny rates stays below the tolerance)."""
    J = np.empty((5, 5))
    for k in range(5):
        e = np.array(x, dtype=np.clongdouble)
        e[k] += 1j * h
        J[:, k] = (f_ct(e, np.longdouble(T)).imag / np.longdouble(h)).astype(float)
    return J


# 3e-4 rad/s over 4 s is just above the series threshold |ΩT| < 1e-3, -1e-4 below it
@pytest.mark.parametrize("omega", [0.05, -0.02, 3e-4, -1e-4])
def test_jacobian_matches_complex_step(omega):
    x = np.array([100.0, 180.0, -50.0, 120.0, omega])
    fx, J = coordinated_turn.transition(x[None], 4.0)
    ref = f_ct(np.asarray(x, dtype=np.longdouble), np.longdouble(4.0)).astype(float)
    np.testing.assert_allclose(fx[0], ref, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(J[0], jac_complex_step(x, 4.0), rtol=1e-9, atol=1e-9)


class CTEKF(ExtendedKalmanFilter):
    """filterpy EKF with the test's coordinated turn; ``update(z)`` with a linear H."""

    def __init__(self, T, Q, H, R, x0, P0):
        super().__init__(dim_x=5, dim_z=2)
        self.T, self.Q, self.R, self.Hm = T, Q.copy(), R.copy(), H.copy()
        self.x, self.P = x0[:, None].copy(), P0.copy()

    def predict_x(self, u=0):
        self.x = f_ct(self.x[:, 0], self.T)[:, None]

    def predict(self, u=0):
        self.F = jac_complex_step(self.x[:, 0], self.T)
        super().predict(u)

    def update(self, z):
        super().update(z, lambda x: self.Hm, lambda x: self.Hm @ x)


def turning_measurements(rng, K, T, sigma):
    x = np.array([0.0, 150.0, 0.0, 60.0, math.radians(2.0)])
    zs = []
    for k in range(K):
        if k == K // 2:
            x[4] = -math.radians(1.0)
        x = f_ct(x, T)
        zs.append(x[[0, 2]] + sigma * rng.standard_normal(2))
    return np.array(zs)


def linear_kf(a, j, x0, P0):
    """filterpy's KalmanFilter for the linear mode ``j`` of IMM arguments ``a``."""
    kf = KalmanFilter(dim_x=5, dim_z=2, dim_u=1)
    kf.F, kf.Q = a["transitions"][j].copy(), a["process_noise"][j].copy()
    kf.H, kf.R = a["measurement_matrix"].copy(), a["measurement_noise"].copy()
    kf.B = a["offsets"][j][:, None].copy()
    kf.x, kf.P = x0[:, None].copy(), P0.copy()
    return kf


def imm_equals_filterpy(imm, ref, zs):
    """Step ``imm`` and filterpy's IMMEstimator ``ref`` on ``zs`` (K, 2), equal at each step."""
    for z in zs:
        imm.step(z[None])
        ref.predict(u=np.ones((1, 1)))
        ref.update(z[:, None])
        scaled_close(imm.x[0], imm.P[0], ref.x[:, 0], ref.P)
        np.testing.assert_allclose(imm.mu[0], ref.mu, rtol=1e-7, atol=1e-12)


def scaled_close(x, P, rx, rP):
    s = np.sqrt(np.diag(rP))
    np.testing.assert_allclose(x / s, rx / s, rtol=1e-7, atol=1e-9)
    np.testing.assert_allclose(P / np.outer(s, s), rP / np.outer(s, s), rtol=1e-7, atol=1e-9)


def test_one_mode_equals_filterpy_ekf():
    rng = np.random.default_rng(3)
    T, sigma = 2.0, 40.0
    p = presets.get("turn-rate", dt=T).with_(measurement_sigma=sigma)
    a = p.imm_arguments()
    j = 1  # the estimated-rate mode alone
    args = dict(
        transitions=a["transitions"][j : j + 1], process_noise=a["process_noise"][j : j + 1],
        measurement_matrix=a["measurement_matrix"], measurement_noise=a["measurement_noise"],
        transition_matrix=[[1.0]], estimated_turn_rate=[True], dt=T, gate_probability=1.0,
    )  # fmt: skip
    x0 = np.array([0.0, 140.0, 10.0, 70.0, 0.01])
    P0 = np.diag([50.0**2, 20.0**2, 50.0**2, 20.0**2, 0.02**2])
    imm = IMM(**args, x0=x0[None], P0=P0, mu0=[1.0])
    ref = CTEKF(T, a["process_noise"][j], a["measurement_matrix"], a["measurement_noise"], x0, P0)
    for z in turning_measurements(rng, 60, T, sigma):
        imm.step(z[None])
        ref.predict()
        ref.update(z[:, None])
        scaled_close(imm.x[0], imm.P[0], ref.x[:, 0], ref.P)


def test_straight_and_estimated_turn_equal_filterpy_imm():
    rng = np.random.default_rng(4)
    T, sigma = 1.0, 50.0
    p = presets.get("turn-rate", dt=T)
    a = p.imm_arguments()
    x0 = np.array([0.0, 150.0, 0.0, 60.0, 0.005])
    P0 = np.diag([50.0**2, 30.0**2, 50.0**2, 30.0**2, 0.01**2])
    mu0 = np.array([0.6, 0.4])
    imm = IMM(**a, x0=x0[None], P0=P0, mu0=mu0, gate_probability=1.0)
    assert imm.kernel == "loops"
    assert IMM.from_preset(p, x0[None], P0).mode_names == ("straight", "turn")
    kf = linear_kf(a, 0, x0, P0)
    ekf = CTEKF(T, a["process_noise"][1], a["measurement_matrix"], a["measurement_noise"], x0, P0)
    ref = IMMEstimator([kf, ekf], mu0.copy(), a["transition_matrix"].copy())
    imm_equals_filterpy(imm, ref, turning_measurements(rng, 120, T, sigma))
    # the turn mode's own rate estimate follows the second half's -1 deg/s
    assert abs(math.degrees(imm.x_modes[0, 1, 4]) + 1.0) < 0.3


@pytest.mark.parametrize("name", ["imm-ct", "imm-ct-airliner"])
def test_imm_ct_three_modes_with_their_own_noise_equal_filterpy_imm(name):
    """The imm-ct presets (quiet CV, estimated-rate CT, manoeuvring CV, each with its own
    σ_a) against filterpy's IMMEstimator over a KalmanFilter, an EKF and a KalmanFilter
    whose Q are the closed-form white-noise-acceleration matrices written here."""
    rng = np.random.default_rng(6)
    T, sigma = 4.0, 100.0
    p = presets.get(name, dt=T).with_(measurement_sigma=sigma)
    a = p.imm_arguments()
    assert a["estimated_turn_rate"].tolist() == [False, True, False]
    for j, sa in enumerate(p.filter_mode_sigma_accel):
        q = sa**2 * np.array([[T**4 / 4, T**3 / 2], [T**3 / 2, T**2]])
        np.testing.assert_allclose(a["process_noise"][j][np.ix_([0, 1], [0, 1])], q)
        np.testing.assert_allclose(a["process_noise"][j][np.ix_([2, 3], [2, 3])], q)
    assert a["process_noise"][1, 4, 4] == pytest.approx(p.ct_sigma_turn_rate**2 * T)
    x0 = np.array([0.0, 150.0, 0.0, 60.0, 0.005])
    P0 = np.diag([100.0**2, 30.0**2, 100.0**2, 30.0**2, 0.01**2])
    mu0 = p.mu0()
    imm = IMM(**a, x0=x0[None], P0=P0, mu0=mu0, gate_probability=1.0)
    ekf = CTEKF(T, a["process_noise"][1], a["measurement_matrix"], a["measurement_noise"], x0, P0)
    filters = [linear_kf(a, 0, x0, P0), ekf, linear_kf(a, 2, x0, P0)]
    ref = IMMEstimator(filters, mu0.copy(), a["transition_matrix"].copy())
    imm_equals_filterpy(imm, ref, turning_measurements(rng, 80, T, sigma))


def test_imm_ct_airliner_mode_chain_has_its_mean_sojourns():
    """The airliner preset's Π is the continuous-time chain of its mean sojourns (900, 60,
    10 s) and imm-ct's switch probabilities: the generator recovered by the matrix logarithm
    of Π over dt has -1/Λ_jj = sojourn_j and off-diagonal shares equal to the switches."""
    from scipy.linalg import logm

    for dt in (1.0, 4.0):
        p = presets.get("imm-ct-airliner", dt=dt)
        L = np.real(logm(np.asarray(p.transition_matrix))) / dt
        np.testing.assert_allclose(-1.0 / np.diag(L), [900.0, 60.0, 10.0], rtol=1e-9)
        shares = L / -np.diag(L)[:, None]
        np.fill_diagonal(shares, 0.0)
        np.testing.assert_allclose(shares, presets.get("imm-ct").switch_probabilities, atol=1e-9)
        assert p.filter_mode_sigma_accel == (0.1, 1.0, 4.0)


@pytest.mark.parametrize("name", ["realistic", "turn-rate", "imm-ct", "imm-ct-airliner"])
def test_step_with_dt_equals_model_built_at_dt(name):
    rng = np.random.default_rng(5)
    p = presets.get(name)
    x0 = np.array([[0.0, 150.0, 0.0, 60.0, 0.0]] * 3)
    P0 = np.diag([50.0**2, 30.0**2, 50.0**2, 30.0**2, 1e-4])
    dts = rng.uniform(0.5, 6.0, 8)
    irregular = IMM.from_preset(p, x0, P0)
    zs = rng.normal(0, 50, (dts.size, 3, 2)) + 150.0 * np.cumsum(dts)[:, None, None]
    for dt, z in zip(dts, zs):
        irregular.step(z, dt=dt)
    # step by step against IMMs built for each dt from the same posteriors: equal bits
    ref = IMM.from_preset(p, x0, P0, kernel=irregular.kernel)
    s = ref.slots
    for dt, z in zip(dts, zs):
        a = p.with_(dt=dt).imm_arguments()
        other = IMM(**a, x0=x0, P0=P0, mu0=p.mu0(), kernel=irregular.kernel)
        other.slots._xs[...] = s._xs
        other.slots._Ps[...] = s._Ps
        other.slots._mus[...] = s._mus
        other.step(z)
        ref.step(z, dt=dt)
        np.testing.assert_array_equal(ref.x, other.x)
        np.testing.assert_array_equal(ref.P, other.P)
    np.testing.assert_array_equal(ref.x, irregular.x)


def test_dt_needs_a_preset():
    from airspace_sim.errors import UserError

    p = presets.get("realistic")
    imm = IMM(**p.imm_arguments(), x0=np.zeros((1, 5)), P0=np.eye(5), mu0=p.mu0())
    with pytest.raises(UserError, match="from_preset"):
        imm.step(np.zeros((1, 2)), dt=2.0)


def test_predict_modes_at_uses_the_ekf_for_the_turn_mode():
    p = presets.get("turn-rate")
    x0 = np.array([[0.0, 150.0, 0.0, 60.0, 0.02]])
    P0 = np.diag([50.0**2, 30.0**2, 50.0**2, 30.0**2, 1e-4])
    imm = IMM.from_preset(p, x0, P0)
    xs, Ps = imm.predict_modes_at(np.array([3, 10]))
    a = p.imm_arguments()
    ekf = CTEKF(p.dt, a["process_noise"][1], a["measurement_matrix"], a["measurement_noise"],
                x0[0], P0)  # fmt: skip
    for k in range(1, 11):
        ekf.predict()
        if k in (3, 10):
            i = (3, 10).index(k)
            scaled_close(xs[0, 1, i], Ps[0, 1, i], ekf.x[:, 0], ekf.P)
    xs2, Ps2 = imm.predict_modes(10)
    np.testing.assert_allclose(xs2[0, 1, 9], xs[0, 1, 1], rtol=1e-12)


def test_turn_presets_names_and_noise():
    d = presets.get("dense-turns")
    assert d.mode_names() == ("straight", "left 1°/s", "right 1°/s", "left 2°/s", "right 2°/s",
                              "left 3°/s", "right 3°/s")  # fmt: skip
    assert d.turning_modes().tolist() == [False] + [True] * 6
    np.testing.assert_allclose(np.asarray(d.transition_matrix).sum(axis=1), 1.0)
    assert "estimated_turn_rate" not in d.imm_arguments()  # linear: filterpy-compatible args
    ct = presets.get("turn-rate", dt=4.0)
    a = ct.imm_arguments()
    assert a["estimated_turn_rate"].tolist() == [False, True] and a["dt"] == 4.0
    assert a["process_noise"][1, 4, 4] == pytest.approx(ct.ct_sigma_turn_rate**2 * 4.0)
    assert a["offsets"][1, 4] == 0.0 and a["transitions"][1, 4, 4] == 1.0
    assert ct.turning_modes().tolist() == [False, True]
    assert presets.get("seed").mode_names() == ("straight", "left 45°/s", "right 45°/s")


def test_a_start_far_from_the_measurements_warns_once():
    p = presets.get("realistic")
    imm = IMM.from_preset(p, np.zeros((2, 5)), np.eye(5) * 1e4)
    z = np.array([[50e3, 20e3], [0.0, 0.0]])
    with pytest.warns(UserWarning, match="two_point_initialisation"):
        for k in range(6):
            imm.step(z + [[200.0 * k, 0.0], [0.0, 0.0]])
    assert imm.gated[0] and not imm.gated[1]
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        imm.step(z)  # once only


def test_the_start_check_resumes_for_trackers_appended_later():
    """Once every tracker has accepted a measurement the check stops; a tracker appended
    after that, started far from its measurements, still gets the warning, as does one
    in an IMM pickled before the check could stop (no such flag in its state)."""
    import pickle

    p = presets.get("realistic")
    imm = IMM.from_preset(p, np.zeros((1, 5)), np.eye(5) * 1e4)
    for _ in range(3):
        imm.step(np.zeros((1, 2)))
    imm.append(np.zeros((1, 5)), np.eye(5) * 1e4, p.mu0())
    z = np.array([[0.0, 0.0], [50e3, 20e3]])
    with pytest.warns(UserWarning, match=r"1 tracker\(s\) \(first: row 1\)"):
        for _ in range(6):
            imm.step(z)

    old = IMM.from_preset(p, np.zeros((1, 5)), np.eye(5) * 1e4)
    state = old.__getstate__()
    state.pop("_starting", None)  # a fresh IMM holds none yet: the class default
    old = pickle.loads(pickle.dumps(old))
    old.__dict__.clear()
    old.__dict__.update(state)
    with pytest.warns(UserWarning, match="two_point_initialisation"):
        for _ in range(6):
            old.step(np.array([[50e3, 20e3]]))


def test_a_preset_s_tracker_model_is_separate_from_its_traffic():
    """``Preset.tracker``: the world's tracker and IMM.from_preset run the tracker model (at
    the preset's dt and σ), the traffic (truth generator, matched imm_arguments) the
    preset's own modes, bit for bit as without a tracker model."""
    from airspace_sim.dynamics import truth
    from airspace_sim.world.trackers import ImmTracker

    base = presets.get("realistic")
    both = base.with_(tracker=presets.get("imm-ct"), dt=2.0, measurement_sigma=80.0)
    own = base.with_(dt=2.0, measurement_sigma=80.0)
    fm = both.filter_model()
    assert (fm.name, fm.dt, fm.measurement_sigma, fm.n_modes) == ("imm-ct", 2.0, 80.0, 3)
    np.testing.assert_array_equal(  # Π of the tracker's sojourns at the new dt
        fm.transition_matrix, presets.get("imm-ct", dt=2.0).transition_matrix
    )
    for k, v in own.imm_arguments().items():
        np.testing.assert_array_equal(both.imm_arguments()[k], v)
    a = truth.simulate(own, 3, 50, rng=np.random.default_rng(1))
    b = truth.simulate(both, 3, 50, rng=np.random.default_rng(1))
    for name in ("states", "modes", "measurements"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    t = ImmTracker(both, 80.0)
    assert t.n_modes == 3 and t.mode_names == fm.mode_names() and len(set(t.mode_names)) == 3
    ref = ImmTracker(presets.get("imm-ct", dt=2.0), 80.0)
    for name in ("_F", "_Q", "_U", "_Pi", "_R", "_ct"):
        np.testing.assert_array_equal(getattr(t.imm, name), getattr(ref.imm, name))
    x0 = np.array([[0.0, 150.0, 0.0, 60.0, 0.0]])
    assert IMM.from_preset(both, x0, np.eye(5) * 100.0).mode_names == fm.mode_names()


def four_mode_preset(dt):
    """Quiet CV, steady CT, roll-in/roll-out CT (a larger σ_Ω of its own), manoeuvring CV."""
    from dataclasses import replace

    from airspace_sim.dynamics import markov
    from airspace_sim.dynamics.presets import _tup

    base = presets.get("imm-ct", dt=dt)
    sojourn = (120.0, 60.0, 15.0, 10.0)
    switch = [[0, 0.7, 0.2, 0.1], [0.5, 0, 0.4, 0.1], [0.3, 0.6, 0, 0.1], [0.4, 0.3, 0.3, 0]]
    return replace(
        base, turn_rates=(0.0, 0.03, 0.03, 0.0), estimated_turn_rate=(False, True, True, False),
        transition_matrix=_tup(markov.transition_matrix_from_sojourn(sojourn, dt, switch)),
        sojourn_s=sojourn, switch_probabilities=_tup(switch),
        filter_mode_sigma_accel=(0.3, 1.5, 1.5, 5.0),
        filter_mode_sigma_turn_rate=tuple(math.radians(v) for v in (0.0, 0.3, 1.5, 0.0)),
    )  # fmt: skip


def test_two_estimated_rate_modes_with_their_own_sigma_omega_equal_filterpy_imm():
    """Four modes, two of them EKF turns that differ only by σ_Ω, against filterpy's
    IMMEstimator over two KalmanFilters and two EKFs whose Q_ΩΩ is written here
    (σ_Ω,j² T): the per-mode σ_Ω reaches the kernel, and each EKF mode keeps its own."""
    rng = np.random.default_rng(7)
    T, sigma = 4.0, 100.0
    p = four_mode_preset(T).with_(measurement_sigma=sigma)
    a = p.imm_arguments()
    assert a["estimated_turn_rate"].tolist() == [False, True, True, False]
    for j, deg in ((1, 0.3), (2, 1.5)):
        assert a["process_noise"][j, 4, 4] == pytest.approx(math.radians(deg) ** 2 * T, rel=1e-12)
    assert p.mode_names() == ("straight 0.3 m/s²", "turn 1.5 m/s² 0.3°/s/√s",
                              "turn 1.5 m/s² 1.5°/s/√s", "straight 5 m/s²")  # fmt: skip
    x0 = np.array([0.0, 150.0, 0.0, 60.0, 0.005])
    P0 = np.diag([100.0**2, 30.0**2, 100.0**2, 30.0**2, 0.01**2])
    mu0 = p.mu0()
    imm = IMM(**a, x0=x0[None], P0=P0, mu0=mu0, gate_probability=1.0)
    H, R = a["measurement_matrix"], a["measurement_noise"]
    ekfs = [CTEKF(T, a["process_noise"][j], H, R, x0, P0) for j in (1, 2)]
    filters = [linear_kf(a, 0, x0, P0), *ekfs, linear_kf(a, 3, x0, P0)]
    ref = IMMEstimator(filters, mu0.copy(), a["transition_matrix"].copy())
    imm_equals_filterpy(imm, ref, turning_measurements(rng, 80, T, sigma))
    # the roll-in mode's rate moves further than the steady one's after the rate change
    assert not np.allclose(imm.x_modes[0, 1, 4], imm.x_modes[0, 2, 4])


def test_per_mode_sigma_omega_is_checked_and_defaults_to_the_shared_one():
    from airspace_sim.errors import UserError

    p = presets.get("imm-ct", dt=2.0)
    same = p.with_(filter_mode_sigma_turn_rate=(0.0, p.ct_sigma_turn_rate, 0.0))
    np.testing.assert_array_equal(same.imm_arguments()["process_noise"],
                                  p.imm_arguments()["process_noise"])  # fmt: skip
    assert same.mode_names() == p.mode_names()  # no duplicate to tell apart
    for bad in ((0.1, 0.2), (0.0, -0.1, 0.0), (0.0, float("nan"), 0.0)):
        with pytest.raises(UserError, match="filter_mode_sigma_turn_rate must be 3 non-negative"):
            p.with_(filter_mode_sigma_turn_rate=bad)
