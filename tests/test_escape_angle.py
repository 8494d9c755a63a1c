"""The paper's escape angle (§V, Figure 3): closed forms, geometry properties, conventions."""

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from airspace_sim.avoidance import escape_angle, escape_rotation, predicted_conflict
from airspace_sim.avoidance.escape import HEAD_ON_TOLERANCE, line_of_sight_angles

R = 3000.0


def rot(v, a):
    c, s = np.cos(a), np.sin(a)
    v = np.asarray(v, dtype=float)
    return np.stack([c * v[..., 0] - s * v[..., 1], s * v[..., 0] + c * v[..., 1]], axis=-1)


def cross(a, b):
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def line_distance(b, d):
    """Distance from O of the line through B with direction d."""
    return np.abs(cross(b, d)) / np.hypot(d[..., 0], d[..., 1])


def signed_angle(a, b):
    """CCW angle from a to b."""
    return np.arctan2(cross(a, b), np.sum(a * b, axis=-1))


# a scene: B outside the circle, relative velocity inside the collision cone
scene = st.tuples(
    st.floats(1.02, 10.0),  # |B| / R
    st.floats(-np.pi, np.pi),  # bearing of B
    st.floats(-0.98, 0.98),  # fraction of β for the direction of v about BO
    st.floats(50.0, 1000.0),  # |v| m/s
)


def build(scene_):
    k, bearing, frac, speed = scene_
    b = k * R * np.array([np.cos(bearing), np.sin(bearing)])
    beta = np.arcsin(1.0 / k)
    los = -b / np.linalg.norm(b)
    v = speed * rot(los, frac * beta)
    t_cpa = -np.dot(b, v) / np.dot(v, v)
    return b, v, t_cpa


def test_closed_form_offset_track():
    # B on the x axis, relative velocity at angle g below the line of sight BO = (−1, 0)
    d, g = 5000.0, 0.2
    b = np.array([d, 0.0])
    v = 400.0 * np.array([-np.cos(g), -np.sin(g)])  # BO rotated CCW by g: line of sight is
    # clockwise from v, so γ = −g and the track passes below O: rotate CCW by β − g
    beta = np.arcsin(R / d)
    theta, conflict = escape_angle(b, v, R, dt=4.0, horizon=3, max_angle=np.pi / 2)
    assert conflict
    assert theta == pytest.approx(beta - g, abs=1e-14)
    _, gamma = line_of_sight_angles(b, v, R)
    assert gamma == pytest.approx(-g, abs=1e-14)


def test_closed_form_matches_paper_magnitude_for_positive_gamma():
    # γ > 0: the paper's θ = β − γ, as a rotation of the frame; the velocity turns by −(β − γ)
    d, g = 4000.0, 0.3
    b = np.array([0.0, d])
    v = 300.0 * rot(np.array([0.0, -1.0]), -g)  # line of sight CCW of v by g
    _, gamma = line_of_sight_angles(b, v, R)
    assert gamma == pytest.approx(g, abs=1e-14)
    beta = np.arcsin(R / d)
    theta, conflict = escape_angle(b, v, R, dt=3.0, horizon=3, max_angle=np.pi / 2)
    assert conflict
    assert theta == pytest.approx(-(beta - g), abs=1e-14)


@settings(max_examples=150, deadline=None)
@given(scene)
def test_unclamped_rotation_makes_track_tangent(scene_):
    b, v, t_cpa = build(scene_)
    theta, conflict = escape_angle(b, v, R, dt=t_cpa, horizon=1, max_angle=np.pi)
    assert conflict  # the closest point of approach is inside
    assert theta == escape_rotation(b, v, R)
    d = rot(v, theta)
    assert line_distance(b, d) == pytest.approx(R, rel=1e-9)
    # the tangent point lies ahead on the ray, not behind
    assert -np.dot(b, d) > 0


@settings(max_examples=150, deadline=None)
@given(scene)
def test_rotation_moves_away_from_line_of_sight(scene_):
    b, v, _ = build(scene_)
    theta = escape_rotation(b, v, R)
    g0 = signed_angle(v, -b)
    g1 = signed_angle(rot(v, theta), -b)
    assert abs(g1) > abs(g0)
    assert abs(g1) == pytest.approx(np.arcsin(R / np.linalg.norm(b)), abs=1e-12)
    if abs(g0) > HEAD_ON_TOLERANCE:
        assert np.sign(g1) == np.sign(g0)  # stays on the side it already passes
        assert abs(theta) == pytest.approx(np.arcsin(R / np.linalg.norm(b)) - abs(g0), abs=1e-12)


@settings(max_examples=150, deadline=None)
@given(scene, st.floats(0.05, 1.0))
def test_mirror_scene_negates_theta(scene_, max_angle):
    b, v, t_cpa = build(scene_)
    assume(abs(signed_angle(v, -b)) > 1e-6)
    mirror = np.array([1.0, -1.0])
    t1, c1 = escape_angle(b, v, R, t_cpa, 1, max_angle)
    t2, c2 = escape_angle(b * mirror, v * mirror, R, t_cpa, 1, max_angle)
    assert c1 == c2
    assert t2 == pytest.approx(-t1, abs=1e-12)


@settings(max_examples=150, deadline=None)
@given(scene, st.floats(-np.pi, np.pi), st.floats(0.05, 1.0))
def test_rotating_whole_scene_keeps_theta(scene_, alpha, max_angle):
    b, v, t_cpa = build(scene_)
    assume(abs(signed_angle(v, -b)) > 1e-6)
    t1, c1 = escape_angle(b, v, R, t_cpa, 1, max_angle)
    t2, c2 = escape_angle(rot(b, alpha), rot(v, alpha), R, t_cpa, 1, max_angle)
    assert c1 and c2
    assert t2 == pytest.approx(t1, abs=1e-9)


@settings(max_examples=120, deadline=None)
@given(scene, st.floats(0.01, 0.5))
def test_clamp(scene_, max_angle):
    b, v, t_cpa = build(scene_)
    theta, _ = escape_angle(b, v, R, t_cpa, 1, max_angle)
    assert abs(theta) <= max_angle
    assert theta == np.clip(escape_rotation(b, v, R), -max_angle, max_angle)


def test_clamp_at_paper_bound():
    # head-on from just outside the circle: β close to π/2, clamped to π/4
    b = np.array([0.0, 3050.0])
    v = np.array([0.0, -600.0])
    theta, conflict = escape_angle(b, v, R, dt=0.1, horizon=3)
    assert conflict and theta == -np.pi / 4


def test_no_conflict_gives_zero():
    b = np.array([10000.0, 0.0])
    v = np.array([0.0, 300.0])  # passing, never inside
    theta, conflict = escape_angle(b, v, R, dt=10.0, horizon=3)
    assert not conflict and theta == 0.0
    # in the cone but too far to reach the circle within 3 steps
    theta, conflict = escape_angle(np.array([20000.0, 0.0]), np.array([-300.0, 0.0]), R, 0.1)
    assert not conflict and theta == 0.0


def test_head_on_turns_right():
    # ownship flies north at the origin, static intruder straight ahead: v_rel = −v_own
    v_own = np.array([0.0, 250.0])
    b = np.array([0.0, 5000.0])
    theta, conflict = escape_angle(b, -v_own, R, dt=4.0, horizon=3)
    assert conflict
    beta = np.arcsin(R / 5000.0)
    assert theta == pytest.approx(-min(beta, np.pi / 4), abs=1e-15)  # clockwise
    # the relative-frame rotation θ applied to the ownship velocity is a right turn ...
    new_own = rot(v_own, theta)
    assert cross(v_own, new_own) < 0
    # ... after which the intruder is on the ownship's left
    assert cross(new_own, b) > 0
    # both aircraft turning right (rules of the air) also rotates v_rel clockwise
    v_int = np.array([0.0, -250.0])
    new_rel = rot(v_int, theta) - rot(v_own, theta)
    assert cross(v_int - v_own, new_rel) < 0


@pytest.mark.parametrize("alpha", [0.0, 1.0, -2.5, np.pi])
def test_head_on_is_right_turn_in_any_direction(alpha):
    b = rot(np.array([0.0, 4000.0]), alpha)
    v = rot(np.array([0.0, -500.0]), alpha)
    theta, conflict = escape_angle(b, v, R, dt=2.0, max_angle=np.pi / 2)
    assert conflict and theta < 0
    assert theta == pytest.approx(-np.arcsin(R / 4000.0), abs=1e-12)


def test_zero_relative_velocity():
    theta, conflict = escape_angle(np.array([5000.0, 0.0]), np.zeros(2), R, 0.1)
    assert not conflict and theta == 0.0
    theta, conflict = escape_angle(np.array([2000.0, 100.0]), np.zeros(2), R, 0.1)
    assert conflict and theta == -np.pi / 4  # treated as head-on, β = π/2, clamped
    theta, conflict = escape_angle(np.zeros(2), np.zeros(2), R, 0.1, max_angle=np.pi)
    assert conflict and theta == -np.pi / 2


def test_inside_closing_and_opening():
    b = np.array([2000.0, 0.0])
    # closing obliquely, passing north of O (v at angle π − 0.5): β = π/2, rotate clockwise
    # until perpendicular to the line of sight (v pointing north)
    v = 300.0 * np.array([-np.cos(0.5), np.sin(0.5)])
    theta, conflict = escape_angle(b, v, R, 0.1, max_angle=np.pi)
    assert conflict
    assert theta == pytest.approx(-(np.pi / 2 - 0.5), abs=1e-12)
    assert np.dot(rot(v, theta), b) == pytest.approx(0.0, abs=1e-9)
    # already moving outward: no rotation needed, still a conflict
    theta, conflict = escape_angle(b, np.array([100.0, 50.0]), R, 0.1)
    assert conflict and theta == 0.0


@settings(max_examples=120, deadline=None)
@given(
    st.lists(
        st.tuples(
            st.floats(-12000, 12000),
            st.floats(-12000, 12000),
            st.floats(-800, 800),
            st.floats(-800, 800),
        ),
        min_size=1,
        max_size=12,
    ),
    st.floats(0.1, 5.0),
    st.integers(1, 5),
)
def test_conflict_flag_matches_brute_force(rows, dt, horizon):
    a = np.array(rows)
    b, v = a[:, :2], a[:, 2:]
    theta, conflict = escape_angle(b, v, R, dt, horizon)
    for i in range(len(a)):
        expect = any(np.hypot(*(b[i] + j * v[i] * dt)) < R for j in range(1, horizon + 1))
        assert conflict[i] == expect
        if not expect:
            assert theta[i] == 0.0
    assert np.array_equal(predicted_conflict(b, v, R, dt, horizon), conflict)


def test_vectorised_over_leading_shape():
    rng = np.random.default_rng(0)
    b = rng.uniform(-8000, 8000, (3, 4, 5, 2))
    v = rng.uniform(-600, 600, (3, 4, 5, 2))
    theta, conflict = escape_angle(b, v, R, 2.0)
    assert theta.shape == conflict.shape == (3, 4, 5)
    assert conflict.any() and (~conflict).any()
    flat_t, flat_c = escape_angle(b.reshape(-1, 2), v.reshape(-1, 2), R, 2.0)
    for i in range(flat_t.size):
        ti, ci = escape_angle(b.reshape(-1, 2)[i], v.reshape(-1, 2)[i], R, 2.0)
        assert ti == flat_t[i] and ci == flat_c[i]
    assert np.array_equal(theta.ravel(), flat_t)
    # per-pair radius broadcasts
    theta2, _ = escape_angle(b, v, np.full((3, 4, 5), R), 2.0)
    assert np.array_equal(theta2, theta)
