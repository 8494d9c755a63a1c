"""Resolvers by name: registry lookup and each resolver's basic behaviour."""

import numpy as np
import pytest

from airspace_sim import registry
from airspace_sim.avoidance import band_search, escape_angle, tangent_heading_change
from airspace_sim.avoidance.resolvers import DEFAULT_R_SAFE, ResolverOutput
from airspace_sim.errors import UserError
from airspace_sim.scenarios.loader import validate_params

R = DEFAULT_R_SAFE


def make(name, **params):
    """The resolver ``name`` with ``params`` validated against its ``Params``."""
    Params = registry.params_class("resolver", name)
    return registry.build("resolver", name, params=validate_params(Params, params, name))


def scene():
    """Three ownships: head-on static intruder ahead, nothing near, two intruders."""
    vo = np.array([[0.0, 250.0], [250.0, 0.0], [0.0, 250.0]])
    r = np.array(
        [
            [[0.0, 3300.0], [0.0, 0.0]],  # second slot unused
            [[50000.0, 0.0], [0.0, 60000.0]],
            [[500.0, 3400.0], [0.0, 3200.0]],
        ]
    )
    vi = np.array(
        [
            [[0.0, 0.0], [0.0, 0.0]],
            [[250.0, 0.0], [0.0, 250.0]],  # flying away
            [[0.0, 0.0], [0.0, 0.0]],
        ]
    )
    valid = np.array([[True, False], [True, True], [True, True]])
    return vo, r, vi - vo[:, None, :], valid


def test_registry_names_and_unknown_name():
    names = registry.names("resolver")
    for name in ("none", "seed", "seed-world", "bands", "bands-probabilistic"):
        assert name in names
    with pytest.raises(UserError, match="unknown resolver 'nope'.*bands"):
        registry.get("resolver", "nope")


@pytest.mark.parametrize("name", ["none", "seed", "seed-world", "bands", "bands-probabilistic"])
def test_output_shapes_and_limits(name):
    vo, r, v, valid = scene()
    mx = np.array([0.3, 0.3, 0.05])
    out = make(name).resolve(vo, r, v, valid, mx)
    assert isinstance(out, ResolverOutput)
    assert out.heading_change.shape == out.conflict.shape == (3,)
    assert out.conflict.dtype == bool
    assert np.all(np.abs(out.heading_change) <= mx)
    assert out.heading_change[1] == 0.0 and not out.conflict[1]  # nothing near


def test_none_never_turns_but_detects():
    vo, r, v, valid = scene()
    out = make("none").resolve(vo, r, v, valid, np.full(3, 0.5))
    assert np.array_equal(out.heading_change, np.zeros(3))
    assert np.array_equal(out.conflict, [True, False, True])


def test_seed_is_the_papers_theta():
    vo, r, v, valid = scene()
    dt = 2.0
    out = make("seed", dt=dt, horizon=3).resolve(vo, r, v, valid, np.full(3, np.pi))
    theta, conflict = escape_angle(r[0, 0], v[0, 0], R, dt, 3)
    assert conflict and out.conflict[0]
    assert out.heading_change[0] == theta < 0  # head-on: right turn
    assert out.heading_change[0] == -np.pi / 4  # β ≈ 65° clamped to the paper's π/4


def test_seed_governing_intruder_is_first_predicted_conflict():
    vo = np.array([[0.0, 250.0]])
    # slot 0: enters the circle at step 3; slot 1: already entering at step 1 (nearer in time)
    r = np.array([[[0.0, 3000.0 + 2.5 * 250.0 * 1.0], [1000.0, 3010.0]]])
    v = np.array([[[0.0, -250.0], [0.0, -250.0]]])
    valid = np.ones((1, 2), bool)
    out = make("seed", dt=1.0, horizon=3, max_angle=np.pi).resolve(
        vo, r, v, valid, np.array([np.pi])
    )
    th, c = escape_angle(r[0], v[0], R, 1.0, 3, np.pi)
    assert c.all()
    assert out.heading_change[0] == th[1]
    # with the second slot invalid, the first governs
    out = make("seed", dt=1.0, horizon=3, max_angle=np.pi).resolve(
        vo, r, v, np.array([[True, False]]), np.array([np.pi])
    )
    assert out.heading_change[0] == th[0]


def test_seed_respects_max_heading_change_and_no_conflict():
    vo, r, v, valid = scene()
    out = make("seed", dt=2.0).resolve(vo, r, v, valid, np.full(3, 0.1))
    assert out.heading_change[0] == -0.1
    out = make("seed", dt=0.01).resolve(vo, r, v, valid, np.full(3, 0.5))
    assert not out.conflict[0] and out.heading_change[0] == 0.0  # too short a horizon


def test_seed_world_equals_seed_for_static_intruder():
    # static intruder: the exact world-frame heading change is the paper's θ
    vo = np.array([[0.0, 250.0]])
    r = np.array([[[800.0, 6000.0]]])
    v = -vo[:, None, :]
    valid = np.ones((1, 1), bool)
    a = make("seed", dt=10.0, max_angle=np.pi).resolve(vo, r, v, valid, np.array([np.pi]))
    b = make("seed-world", dt=10.0, max_angle=np.pi).resolve(vo, r, v, valid, np.array([np.pi]))
    assert a.conflict[0] and b.conflict[0]
    assert b.heading_change[0] == pytest.approx(a.heading_change[0], abs=1e-12)


def test_seed_world_uses_exact_heading_for_moving_intruder():
    vo = np.array([[0.0, 250.0]])
    vi = np.array([[[0.0, -250.0]]])
    r = np.array([[[0.0, 10000.0]]])
    v = vi - vo[:, None, :]
    out = make("seed-world", dt=10.0, max_angle=np.pi).resolve(
        vo, r, v, np.ones((1, 1), bool), np.array([np.pi])
    )
    exact, ok = tangent_heading_change(vo[0], vi[0, 0], r[0, 0], R)
    assert ok and out.heading_change[0] == pytest.approx(exact, abs=1e-12)


def test_bands_matches_band_search_and_defaults():
    vo, r, v, valid = scene()
    mx = np.full(3, 0.6)
    out = make("bands").resolve(vo, r, v, valid, mx)
    ref = band_search(vo, r, v, valid, mx, R, 120.0, 0.1)
    assert np.array_equal(out.heading_change, ref.heading_change)
    assert np.array_equal(out.conflict, ref.conflict)
    np.testing.assert_array_equal(out.first_clear, ref.first_clear)
    assert out.heading_change[0] < 0  # head-on: right turn
    custom = make("bands", r_safe=1000.0, lookahead_s=30.0, margin=0.0).resolve(vo, r, v, valid, mx)
    ref = band_search(vo, r, v, valid, mx, 1000.0, 30.0, 0.0)
    assert np.array_equal(custom.heading_change, ref.heading_change)


def mode_predictions_for(r, v, sigma, steps=5, dt=10.0):
    """Straight-line predictions, identical for M = 3 modes, isotropic covariance."""
    n, k, _ = r.shape
    t = dt * np.arange(1, steps + 1)
    xs = r[:, :, None, None, :] + t[None, None, None, :, None] * v[:, :, None, None, :]
    xs = np.broadcast_to(xs, (n, k, 3, steps, 2))
    ps = np.broadcast_to(sigma**2 * np.eye(2), (n, k, 3, steps, 2, 2))
    mu = np.full((n, k, 3), 1 / 3)
    return xs, ps, mu


def test_bands_probabilistic():
    vo, r, v, valid = scene()
    mx = np.full(3, 0.6)
    res = make("bands-probabilistic", threshold=0.2)
    # without predictions it is "bands"
    plain = res.resolve(vo, r, v, valid, mx)
    ref = make("bands").resolve(vo, r, v, valid, mx)
    assert np.array_equal(plain.heading_change, ref.heading_change)
    # sharp predictions of the real motion: the same threats, the same choice
    out = res.resolve(vo, r, v, valid, mx, mode_predictions=mode_predictions_for(r, v, 10.0))
    assert out.probability.shape == (3, 2)
    assert np.all(out.probability[~valid] == 0.0)
    assert np.array_equal(out.conflict, [True, False, True])
    assert np.array_equal(out.heading_change, ref.heading_change)
    # hopelessly vague predictions: below the threshold, no turn and no conflict
    vague = res.resolve(vo, r, v, valid, mx, mode_predictions=mode_predictions_for(r, v, 1e6))
    assert not vague.conflict.any() and np.array_equal(vague.heading_change, np.zeros(3))


def ring_min_separation(name, n=8, **params):
    """Closed loop: n aircraft on a 40 km ring fly through the centre at 250 m/s, turning at
    most 3°/s toward the resolver's heading change (searched within ±90°), and back toward
    their goal (resume_heading_change) when no conflict is flagged. Returns the minimum
    separation, m."""
    from airspace_sim.avoidance import resume_heading_change
    from airspace_sim.geometry import rotate

    dt, rate = 2.0, np.radians(3.0)
    ang = np.linspace(0, 2 * np.pi, n, endpoint=False)
    pos = 40000.0 * np.stack([np.cos(ang), np.sin(ang)], -1)
    vel = 250.0 * np.stack([np.cos(ang + np.pi), np.sin(ang + np.pi)], -1)
    goal = -pos
    others = np.array([[j for j in range(n) if j != i] for i in range(n)])
    res = make(name, **params)
    valid = np.ones((n, n - 1), bool)
    lo = np.inf
    for _ in range(200):
        rp = pos[others] - pos[:, None, :]
        rv = vel[others] - vel[:, None, :]
        lo = min(lo, np.hypot(rp[..., 0], rp[..., 1]).min())
        out = res.resolve(vel, rp, rv, valid, np.full(n, np.pi / 2))
        desired = np.arctan2(goal[:, 1] - pos[:, 1], goal[:, 0] - pos[:, 0])
        back, _ = resume_heading_change(vel, desired, rp, rv, valid, np.full(n, rate * dt))
        turn = np.where(out.conflict, out.heading_change, back)
        vel = rotate(vel, np.clip(turn, -rate * dt, rate * dt))
        pos = pos + vel * dt
    return lo


def test_closed_loop_ring_keeps_separation():
    assert ring_min_separation("none") < 1.0  # all meet in the centre
    assert ring_min_separation("bands") >= R
    assert ring_min_separation("bands", left_penalty=np.radians(10.0)) >= R
    assert ring_min_separation("seed-world", dt=10.0) >= R
    # denser ring: the smallest-|ψ| rule alone lets neighbours pick opposite sides; a
    # right-turn bias keeps everyone clear
    assert ring_min_separation("bands", n=16, left_penalty=np.radians(10.0)) >= R


def test_bands_model_turn_uses_the_callers_turn_rate():
    # an instant 90° right turn clears a stationary intruder off the right of the path, the
    # flown arc (3°/s) does not: with model_turn the resolver must not pick it
    vo = np.array([[250.0, 0.0]])
    r = np.array([[[3500.0, -4500.0]]])
    v = -vo[:, None, :]
    valid = np.ones((1, 1), bool)
    mx = np.array([np.pi / 2])
    w = np.array([np.radians(3.0)])
    plain = make("bands", r_safe=3000.0, margin=0.0, full_band=True)
    flown = make("bands", r_safe=3000.0, margin=0.0, model_turn=True, full_band=True)
    # model_turn off (the default): turn_rate is accepted and ignored
    a = plain.resolve(vo, r, v, valid, mx, turn_rate=w)
    b = plain.resolve(vo, r, v, valid, mx)
    np.testing.assert_array_equal(a.band, b.band)
    c = flown.resolve(vo, r, v, valid, mx, turn_rate=w)
    right90 = c.candidates[0] == -np.pi / 2
    assert a.band[0][right90].all() and not c.band[0][right90].any()
    # without a turn rate model_turn has nothing to model
    d = flown.resolve(vo, r, v, valid, mx)
    np.testing.assert_array_equal(d.band, b.band)


def test_bands_reports_min_ratio_consistent_with_band():
    vo, r, v, valid = scene()
    out = make("bands", full_band=True).resolve(vo, r, v, valid, np.full(len(vo), np.pi / 2))
    assert out.min_ratio is not None and out.min_ratio.shape == out.band.shape
    used = ~np.isnan(out.candidates)
    np.testing.assert_array_equal(out.band, used & (out.min_ratio >= 1.0 - 1e-9))
    assert np.all(out.min_ratio[~used] == -np.inf)
