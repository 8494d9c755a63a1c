"""The coordinated turn with along-track acceleration (EKF, state [x, vx, y, vy, Ω, a])
against independent references.

- The model: the test's own ``f`` integrates the motion's differential equation
  (``ṗ = v``, ``v̇ = Ω·(−vy, vx) + a·v/|v|``, Ω and a constant) by classical Runge–Kutta in
  extended precision, not the closed form of ``along_track``; its Jacobian is the
  complex-step derivative of that integration (``|v|`` is written as a square root, which
  is analytic, so the complex step goes through it).
- ``along_track.transition`` and ``along_track.predict`` against them.
- A one-mode IMM with that mode against filterpy's ``ExtendedKalmanFilter`` step by step,
  and the ``imm-cta`` model (``presets.imm_cta``: quiet CV, the mode, manoeuvring CV, all in the 6-state
  layout) against filterpy's ``IMMEstimator`` over a KalmanFilter, that EKF and a
  KalmanFilter.
- Irregular sampling: ``step(z, dt)`` equals an IMM built at that dt, bit for bit.
- The 5-state models are untouched: their arguments and kernel flags are as before.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

filterpy = pytest.importorskip("filterpy")
from filterpy.kalman import ExtendedKalmanFilter, IMMEstimator, KalmanFilter  # noqa: E402

from airspace_sim.dynamics import presets  # noqa: E402
from airspace_sim.tracking import IMM, along_track  # noqa: E402

#: Runge–Kutta substeps per second of the reference integration
RK_PER_S = 100


def _rhs(x):
    """Time derivative of states x (..., 6), real or complex."""
    vx, vy, w, a = x[..., 1], x[..., 3], x[..., 4], x[..., 5]
    sp = np.sqrt(vx * vx + vy * vy)
    z = np.zeros_like(vx)
    return np.stack([vx, -w * vy + a * vx / sp, vy, w * vx + a * vy / sp, z, z], axis=-1)


def f_ref(x, T):
    """The state after ``T`` s of the model's differential equation, by RK4 (x (..., 6))."""
    n = max(int(round(RK_PER_S * float(T))), 1)
    h = T / n
    for _ in range(n):
        k1 = _rhs(x)
        k2 = _rhs(x + 0.5 * h * k1)
        k3 = _rhs(x + 0.5 * h * k2)
        k4 = _rhs(x + h * k3)
        x = x + (h / 6) * (k1 + 2 * k2 + 2 * k3 + k4)
    return x


def ref_transition(x, T, h=1e-30):
    """``f_ref(x)`` and its complex-step Jacobian (6, 6), in extended precision."""
    e = np.tile(np.asarray(x, dtype=np.clongdouble), (7, 1))
    e[np.arange(1, 7), np.arange(6)] += 1j * h
    out = f_ref(e, np.longdouble(T))
    return out[0].real.astype(float), (out[1:].imag / np.longdouble(h)).T.astype(float)


# |ΩT| over 4 s: 0.2, 0.08, 0.016 (closed forms), 1.2e-3 and 4e-4 (series of b_s, b_c;
# the last one also of s, c); a of both signs and none
@pytest.mark.parametrize(
    "omega, a", [(0.05, 0.8), (-0.02, -1.5), (0.004, 0.3), (3e-4, -0.6), (-1e-4, 0.0)]
)
def test_transition_matches_the_integrated_motion(omega, a):
    x = np.array([100.0, 180.0, -50.0, -120.0, omega, a])
    fx, J = along_track.transition(x[None], 4.0)
    ref, Jref = ref_transition(x, 4.0)
    np.testing.assert_allclose(fx[0], ref, rtol=1e-12, atol=1e-8)
    np.testing.assert_allclose(J[0], Jref, rtol=1e-8, atol=1e-9)
    # the speed changes by a T and the heading turns by Ω T, exactly
    assert np.hypot(fx[0, 1], fx[0, 3]) == pytest.approx(np.hypot(180, 120) + 4 * a, rel=1e-13)


def test_track_at_rest_stays_finite():
    fx, J = along_track.transition(np.array([[0.0, 0.0, 0.0, 0.0, 0.01, 1.0]]), 4.0)
    assert np.all(np.isfinite(fx)) and np.all(np.isfinite(J))


def test_predict_equals_repeated_reference_steps():
    x = np.array([0.0, 150.0, 0.0, 60.0, 0.02, 0.5])
    P = np.diag([100.0**2, 10.0**2, 100.0**2, 10.0**2, 0.01**2, 0.3**2])
    Q = np.diag([1.0, 0.5, 1.0, 0.5, 1e-6, 0.01])
    xs, Ps = along_track.predict(x[None], P[None], Q, 2.0, np.array([1, 3]))
    xr, Pr = x, P
    for k in range(1, 4):
        fx, J = ref_transition(xr, 2.0)
        xr, Pr = fx, J @ Pr @ J.T + Q
        if k in (1, 3):
            i = 0 if k == 1 else 1
            np.testing.assert_allclose(xs[0, i], xr, rtol=1e-10, atol=1e-7)
            np.testing.assert_allclose(Ps[0, i], Pr, rtol=1e-7, atol=1e-9)


class CTAEKF(ExtendedKalmanFilter):
    """filterpy EKF with the test's integrated motion; ``update(z)`` with a linear H."""

    def __init__(self, T, Q, H, R, x0, P0):
        super().__init__(dim_x=6, dim_z=2)
        self.T, self.Q, self.R, self.Hm = T, Q.copy(), R.copy(), H.copy()
        self.x, self.P = x0[:, None].copy(), P0.copy()

    def predict_x(self, u=0):
        self.x = self._fx[:, None]

    def predict(self, u=0):
        self._fx, self.F = ref_transition(self.x[:, 0], self.T)
        super().predict(u)

    def update(self, z):
        super().update(z, lambda x: self.Hm, lambda x: self.Hm @ x)


def accelerating_turn_measurements(rng, K, T, sigma):
    """Position measurements (K, 2) of a turn that speeds up, then turns the other way
    slowing down."""
    x = np.array([0.0, 150.0, 0.0, 60.0, math.radians(2.0), 1.0])
    zs = []
    for k in range(K):
        if k == K // 2:
            x[4], x[5] = -math.radians(1.0), -0.8
        x = f_ref(x, T)
        zs.append(x[[0, 2]] + sigma * rng.standard_normal(2))
    return np.array(zs)


def scaled_close(x, P, rx, rP):
    s = np.sqrt(np.diag(rP))
    np.testing.assert_allclose(x / s, rx / s, rtol=1e-7, atol=1e-8)
    np.testing.assert_allclose(P / np.outer(s, s), rP / np.outer(s, s), rtol=1e-7, atol=1e-8)


def linear_kf(a, j, x0, P0):
    """filterpy's KalmanFilter for the linear mode ``j`` of IMM arguments ``a``."""
    kf = KalmanFilter(dim_x=6, dim_z=2, dim_u=1)
    kf.F, kf.Q = a["transitions"][j].copy(), a["process_noise"][j].copy()
    kf.H, kf.R = a["measurement_matrix"].copy(), a["measurement_noise"].copy()
    kf.B = a["offsets"][j][:, None].copy()
    kf.x, kf.P = x0[:, None].copy(), P0.copy()
    return kf


def test_one_mode_equals_filterpy_ekf():
    rng = np.random.default_rng(3)
    T, sigma = 2.0, 40.0
    a = presets.imm_cta(T).with_(measurement_sigma=sigma).imm_arguments()
    j = 1
    assert a["along_track_acceleration"].tolist() == [False, True, False]
    args = dict(
        transitions=a["transitions"][j : j + 1], process_noise=a["process_noise"][j : j + 1],
        measurement_matrix=a["measurement_matrix"], measurement_noise=a["measurement_noise"],
        transition_matrix=[[1.0]], along_track_acceleration=[True], dt=T, gate_probability=1.0,
    )  # fmt: skip
    x0 = np.array([0.0, 140.0, 10.0, 70.0, 0.01, 0.0])
    P0 = np.diag([50.0**2, 20.0**2, 50.0**2, 20.0**2, 0.02**2, 1.0])
    imm = IMM(**args, x0=x0[None], P0=P0, mu0=[1.0])
    assert imm.kernel == "loops"
    ref = CTAEKF(T, a["process_noise"][j], a["measurement_matrix"], a["measurement_noise"], x0, P0)
    for z in accelerating_turn_measurements(rng, 60, T, sigma):
        imm.step(z[None])
        ref.predict()
        ref.update(z[:, None])
        scaled_close(imm.x[0], imm.P[0], ref.x[:, 0], ref.P)
    # the mode's own (noisy: σ 40 m every 2 s) estimates have the second half's signs
    # (-1 deg/s, -0.8 m/s²)
    assert -2.5 < math.degrees(imm.x[0, 4]) < -0.3
    assert -2.0 < imm.x[0, 5] < -0.2


def test_imm_cta_preset_equals_filterpy_imm():
    rng = np.random.default_rng(6)
    T, sigma = 4.0, 100.0
    p = presets.imm_cta(T).with_(measurement_sigma=sigma)
    a = p.imm_arguments()
    assert p.n_state == 6 and a["transitions"].shape == (3, 6, 6)
    assert p.mode_names() == ("straight 0.3 m/s²", "turn + speed 1 m/s²", "straight 6 m/s²")
    # the CV modes carry a pinned at 0; the along-track mode's a is a random walk
    assert a["transitions"][0, 5, 5] == 0.0 and a["process_noise"][0, 5, 5] == 0.0
    sig = p.filter_mode_sigma_along_track[1]
    assert a["process_noise"][1, 5, 5] == pytest.approx(sig**2 * T)
    # and the 5-state blocks are imm-ct's with the same σ_a
    b = presets.imm_ct(T).with_(
        measurement_sigma=sigma, filter_mode_sigma_accel=p.filter_mode_sigma_accel
    )
    b = b.imm_arguments()
    np.testing.assert_array_equal(a["transitions"][:, :5, :5], b["transitions"])
    np.testing.assert_array_equal(a["process_noise"][:, :5, :5], b["process_noise"])
    np.testing.assert_array_equal(a["transition_matrix"], b["transition_matrix"])
    x0 = np.array([0.0, 150.0, 0.0, 60.0, 0.005, 0.0])
    P0 = np.diag([100.0**2, 30.0**2, 100.0**2, 30.0**2, 0.01**2, 0.5**2])
    mu0 = p.mu0()
    imm = IMM(**a, x0=x0[None], P0=P0, mu0=mu0, gate_probability=1.0)
    ekf = CTAEKF(T, a["process_noise"][1], a["measurement_matrix"], a["measurement_noise"], x0, P0)
    ref = IMMEstimator(
        [linear_kf(a, 0, x0, P0), ekf, linear_kf(a, 2, x0, P0)], mu0.copy(),
        a["transition_matrix"].copy(),
    )  # fmt: skip
    for z in accelerating_turn_measurements(rng, 80, T, sigma):
        imm.step(z[None])
        ref.predict(u=np.ones((1, 1)))
        ref.update(z[:, None])
        scaled_close(imm.x[0], imm.P[0], ref.x[:, 0], ref.P)
        np.testing.assert_allclose(imm.mu[0], ref.mu, rtol=1e-7, atol=1e-12)


def test_predict_modes_at_uses_the_along_track_model():
    p = presets.imm_cta(2.0)
    x0 = np.array([[0.0, 150.0, 0.0, 60.0, 0.02, 0.7]])
    P0 = np.diag([50.0**2, 10.0**2, 50.0**2, 10.0**2, 1e-4, 0.2])
    imm = IMM.from_preset(p, x0, P0)
    xs, Ps = imm.predict_modes_at(np.array([1, 4]))
    ref_x, ref_P = along_track.predict(
        imm.x_modes[:, 1], imm.P_modes[:, 1], imm.slots._Q[1], 2.0, np.array([1, 4])
    )
    np.testing.assert_array_equal(xs[:, 1], ref_x)
    np.testing.assert_array_equal(Ps[:, 1], ref_P)
    # the CV modes' linear predictions keep a at 0
    assert np.all(xs[:, [0, 2], :, 5] == 0.0)
    full, _ = imm.predict_modes(4)
    np.testing.assert_allclose(full[:, :, [0, 3]], xs, rtol=1e-12)


def test_step_with_dt_equals_model_built_at_dt():
    rng = np.random.default_rng(5)
    p = presets.imm_cta()
    x0 = np.array([[0.0, 150.0, 0.0, 60.0, 0.0, 0.0]] * 3)
    P0 = np.diag([50.0**2, 30.0**2, 50.0**2, 30.0**2, 1e-4, 0.25])
    dts = rng.uniform(0.5, 6.0, 8)
    irregular = IMM.from_preset(p, x0, P0)
    zs = rng.normal(0, 50, (dts.size, 3, 2)) + 150.0 * np.cumsum(dts)[:, None, None]
    for dt, z in zip(dts, zs):
        irregular.step(z, dt=dt)
    ref = IMM.from_preset(p, x0, P0)
    s = ref.slots
    for dt, z in zip(dts, zs):
        other = IMM(**p.with_(dt=dt).imm_arguments(), x0=x0, P0=P0, mu0=p.mu0())
        other.slots._xs[...] = s._xs
        other.slots._Ps[...] = s._Ps
        other.slots._mus[...] = s._mus
        other.step(z)
        ref.step(z, dt=dt)
        np.testing.assert_array_equal(ref.x, other.x)


@pytest.mark.parametrize("name", ["realistic", "turn-rate", "imm-ct"])
def test_five_state_models_are_unchanged(name):
    p = presets.get(name)
    a = p.imm_arguments()
    assert p.n_state == 5 and "along_track_acceleration" not in a
    assert a["transitions"].shape[1:] == (5, 5)
    imm = IMM.from_preset(p, np.zeros((1, 5)), np.eye(5))
    # the kernel's flags keep their type (the same compiled kernels run these models)
    assert imm.slots._ct.dtype == bool


def test_bad_layouts_are_refused():
    from airspace_sim.errors import UserError

    a = presets.get("imm-ct").imm_arguments()
    with pytest.raises(UserError, match="n = 6"):
        IMM(**a, along_track_acceleration=[False, True, False], x0=np.zeros((1, 5)),
            P0=np.eye(5), mu0=[0.4, 0.4, 0.2])  # fmt: skip


def test_the_world_refuses_a_six_state_tracker_with_one_line():
    from airspace_sim.errors import UserError
    from airspace_sim.world.trackers import ImmTracker

    with pytest.raises(UserError, match="along-track acceleration"):
        ImmTracker(presets.imm_cta(), 50.0)
