"""World-frame exact heading changes: tangency, static-intruder limit, roots vs brute force."""

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from airspace_sim.avoidance import escape_rotation, tangent_heading_change
from airspace_sim.avoidance.heading import (
    range_at_time_heading_changes,
    rotate,
    tangent_direction,
    tangent_heading_changes,
    wrap_angle,
)

R = 3000.0


def cross(a, b):
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def ray_distance(b, d):
    """Distance from O of the ray B + t·d, t ≥ 0."""
    t = max(-np.dot(b, d) / np.dot(d, d), 0.0)
    return np.linalg.norm(b + t * d)


vec = st.tuples(st.floats(-600, 600), st.floats(-600, 600)).map(np.array)
position = st.tuples(st.floats(1.05, 8.0), st.floats(-np.pi, np.pi)).map(
    lambda kb: kb[0] * R * np.array([np.cos(kb[1]), np.sin(kb[1])])
)


@settings(max_examples=150, deadline=None)
@given(vec, vec, position, st.sampled_from([-1.0, 1.0]))
def test_roots_put_relative_track_on_tangent(vo, vi, b, side):
    assume(np.linalg.norm(vo) > 1.0)
    roots = tangent_heading_changes(vo, vi, b, R, side)
    assert roots.shape == (2,)
    u = tangent_direction(b, R, side)
    for psi in roots[~np.isnan(roots)]:
        v_rel = vi - rotate(vo, psi)
        assume(np.linalg.norm(v_rel) > 1e-3)
        # on the tangent ray through the origin of velocity space, pointing forward
        assert cross(u, v_rel) == pytest.approx(0.0, abs=1e-9 * np.linalg.norm(v_rel))
        assert np.dot(u, v_rel) >= 0
        assert ray_distance(b, v_rel) == pytest.approx(R, rel=1e-9)
        assert -np.pi <= psi < np.pi


@settings(max_examples=120, deadline=None)
@given(vec, vec, position)
def test_smallest_root_and_reachability_vs_brute_force(vo, vi, b):
    assume(np.linalg.norm(vo) > 10.0)
    psi, ok = tangent_heading_change(vo, vi, b, R)
    # side the relative velocity already passes (or right on head-on)
    v0 = vi - vo
    gamma = np.arctan2(cross(v0, -b), np.dot(v0, -b))
    side = 1.0 if gamma < -1e-9 else -1.0
    u = tangent_direction(b, R, side)
    # brute force: sign changes of cross(u, v_rel(ψ)) on a fine grid, forward half only
    grid = np.linspace(-np.pi, np.pi, 8001)
    v_rel = vi - rotate(np.broadcast_to(vo, (grid.size, 2)), grid)
    f = cross(np.broadcast_to(u, v_rel.shape), v_rel)
    fwd = v_rel @ u > 0
    # the scan cannot resolve a locus passing within a few grid steps of the origin
    assume(np.min(np.linalg.norm(v_rel, axis=1)) > 10 * np.linalg.norm(vo) * (grid[1] - grid[0]))
    change = (np.sign(f[:-1]) != np.sign(f[1:])) & fwd[:-1] & fwd[1:]
    found = grid[:-1][change]
    assert ok == (found.size > 0)
    if not ok:
        assert np.isnan(psi)
        return
    best = found[np.argmin(np.abs(found))]
    assert abs(abs(psi) - abs(best)) <= 2 * (grid[1] - grid[0])


@settings(max_examples=150, deadline=None)
@given(st.floats(20.0, 600.0), st.floats(-np.pi, np.pi), position, st.floats(-0.95, 0.95))
def test_static_intruder_heading_change_equals_paper_theta(speed, heading, b, frac):
    # v_i = 0: v_rel = −v_o, and turning v_o by ψ turns v_rel by ψ, so ψ = θ (unclamped)
    beta = np.arcsin(R / np.linalg.norm(b))
    v_rel = speed * rotate(-b / np.linalg.norm(b), frac * beta)  # in conflict
    vo = -v_rel
    psi, ok = tangent_heading_change(vo, np.zeros(2), b, R)
    theta = escape_rotation(b, v_rel, R)
    assert ok
    assert psi == pytest.approx(theta, abs=1e-9)


def test_static_intruder_any_state_including_head_on():
    b = np.array([0.0, 6000.0])
    vo = np.array([0.0, 250.0])  # head-on: right turn
    psi, ok = tangent_heading_change(vo, np.zeros(2), b, R)
    assert ok and psi == pytest.approx(-np.arcsin(0.5), abs=1e-12)
    assert psi == pytest.approx(escape_rotation(b, -vo, R), abs=1e-12)


def test_unreachable_is_nan():
    # slow ownship, fast intruder head-on: turning cannot move v_rel off the cone
    vo = np.array([0.0, 10.0])
    vi = np.array([0.0, -400.0])
    b = np.array([0.0, 20000.0])
    psi, ok = tangent_heading_change(vo, vi, b, R)
    assert not ok and np.isnan(psi)
    assert np.all(np.isnan(tangent_heading_changes(vo, vi, b, R, 1.0)))


def test_world_frame_differs_from_theta_for_moving_intruder():
    # head-on, equal speeds: v_rel = −2 v_o; the ownship must turn more than θ
    vo = np.array([0.0, 250.0])
    vi = np.array([0.0, -250.0])
    b = np.array([0.0, 10000.0])
    psi, ok = tangent_heading_change(vo, vi, b, R)
    theta = escape_rotation(b, vi - vo, R)
    assert ok and psi < theta < 0
    v_rel = vi - rotate(vo, psi)
    assert ray_distance(b, v_rel) == pytest.approx(R, rel=1e-9)
    # closed form: rotating v_o by ψ turns v_i − v_o by ψ/2 when |v_i| = |v_o|
    assert psi == pytest.approx(2 * theta, abs=1e-12)


@settings(max_examples=120, deadline=None)
@given(vec, vec, position, st.floats(-np.pi, np.pi))
def test_rotation_invariance(vo, vi, b, alpha):
    assume(np.linalg.norm(vo) > 1.0)
    # a relative velocity of ~1e-56 m/s has no direction to rotate: ill-conditioned
    assume(np.linalg.norm(vi - vo) > 1e-6 * np.linalg.norm(vo))
    assume(abs(cross(vi - vo, -b)) > 1e-3 * np.linalg.norm(b) * np.linalg.norm(vi - vo))
    p1, ok1 = tangent_heading_change(vo, vi, b, R)
    p2, ok2 = tangent_heading_change(rotate(vo, alpha), rotate(vi, alpha), rotate(b, alpha), R)
    assert ok1 == ok2
    if ok1:
        assert wrap_angle(p2 - p1) == pytest.approx(0.0, abs=1e-8)


@settings(max_examples=120, deadline=None)
@given(vec, vec, position, st.floats(1.0, 300.0))
def test_range_at_time_roots(vo, vi, b, t):
    assume(np.linalg.norm(vo) > 1.0)
    roots = range_at_time_heading_changes(vo, vi, b, R, t)
    for psi in roots[~np.isnan(roots)]:
        p = b + t * (vi - rotate(vo, psi))
        assert np.linalg.norm(p) == pytest.approx(R, rel=1e-8)


def test_vectorised_shapes():
    rng = np.random.default_rng(1)
    vo = rng.uniform(-300, 300, (4, 3, 2))
    vi = rng.uniform(-300, 300, (4, 3, 2))
    b = rng.uniform(-20000, 20000, (4, 3, 2))
    psi, ok = tangent_heading_change(vo, vi, b, R)
    assert psi.shape == ok.shape == (4, 3)
    for i in range(4):
        for j in range(3):
            p, o = tangent_heading_change(vo[i, j], vi[i, j], b[i, j], R)
            assert o == ok[i, j]
            assert (np.isnan(p) and np.isnan(psi[i, j])) or p == psi[i, j]


def _reference_roots(vo, r, vi, valid, radius, t):
    """(N, K, 6) from the numpy functions: tangents side −1, side +1, range at ``t``."""
    vo3 = vo[:, None, :]
    out = np.concatenate(
        [
            tangent_heading_changes(vo3, vi, r, radius, -1.0),
            tangent_heading_changes(vo3, vi, r, radius, 1.0),
            range_at_time_heading_changes(vo3, vi, r, radius, np.full(r.shape[:-1], t)),
        ],
        axis=-1,
    )
    return np.where(valid[..., None], out, np.nan)


def _assert_kernel_matches(vo, r, vi, valid, radius, t):
    from airspace_sim.avoidance.heading import boundary_heading_changes

    with np.errstate(all="ignore"):
        ref = _reference_roots(vo, r, vi, valid, radius, t)
    got = boundary_heading_changes(vo, r, vi, valid, radius, t)
    # same roots exist; values equal up to the last bits of libm vs numpy's SIMD sin/cos
    # (an angle at ±π may come out on either side of the wrap)
    assert np.array_equal(np.isnan(got), np.isnan(ref))
    ok = ~np.isnan(ref)
    assert np.all(np.abs(wrap_angle(got[ok] - ref[ok])) <= 1e-12)
    return got, ref


def test_boundary_kernel_equals_numpy_random():
    rng = np.random.default_rng(5)
    n, k = 40, 25
    vo = rotate(np.array([250.0, 0.0]), rng.uniform(-np.pi, np.pi, n))
    r = rng.uniform(-20000.0, 20000.0, (n, k, 2))
    r[:, :3] *= 0.05  # some intruders inside the radius
    vi = rotate(
        np.stack([rng.uniform(0.0, 500.0, (n, k)), np.zeros((n, k))], -1),
        rng.uniform(-np.pi, np.pi, (n, k)),
    )
    valid = rng.random((n, k)) < 0.9
    radius = rng.uniform(2000.0, 4000.0, (n, k))
    got, ref = _assert_kernel_matches(vo, r, vi, valid, radius, 120.0)
    assert np.isnan(got[~valid]).all()
    assert (~np.isnan(got)).sum(axis=-1).max() >= 4  # both tangents and the range roots occur


def test_boundary_kernel_equals_numpy_degenerate():
    """Components from a small set (signed zeros, equal speeds, on-axis geometry): zero
    relative velocity, coincident positions, intruders inside or on the radius, zero own
    speed, roots at exactly ±π — and the sign of zero that decides atan2 there."""
    rng = np.random.default_rng(6)
    vals = np.array([0.0, -0.0, 250.0, -250.0, 800.0, -800.0, 3300.0, -3300.0, 1e-300])
    n, k = 200, 30
    vo = rng.choice(vals[:4], (n, 2))
    vo[0] = 0.0  # no own speed
    r = rng.choice(vals, (n, k, 2))
    vi = rng.choice(vals[:4], (n, k, 2))
    vi[:, :5] = vo[:, None, :]  # zero relative velocity
    r[:, 5] = 0.0  # coincident
    # ψ = ±π exactly: p = (−5800, ±0) behind, |p − 10·R(π)v_o| = 3300 at t = 10 s (a double root)
    vo[1] = [250.0, 0.0]
    r[1, 6], vi[1, 6] = [-5800.0, 0.0], [0.0, 0.0]
    r[1, 7], vi[1, 7] = [-5800.0, -0.0], [0.0, -0.0]
    valid = np.ones((n, k), bool)
    got, ref = _assert_kernel_matches(vo, r, vi, valid, np.full((n, k), 3300.0), 10.0)
    assert np.all(np.abs(np.abs(got[1, 6:8, 4:]) - np.pi) < 1e-12)
    assert not np.any(got[:, :5, :4] == 0.0)  # ψ = 0 has no relative motion: no tangent ray
    assert np.isnan(got[0]).all()  # no own speed: no heading change moves anything


def test_boundary_kernel_equals_numpy_equal_speeds():
    """Intruders as fast as the ownship: one tangent root per side has ``v_rel ≈ 0``
    (``λ`` near the ray test's threshold), where the kernel's angle-sum cos / sin must
    give way to libm's; the roots that exist are the reference's."""
    rng = np.random.default_rng(8)
    n, k = 60, 20
    vo = rotate(np.array([230.0, 0.0]), rng.uniform(-np.pi, np.pi, n))
    r = rng.uniform(-30000.0, 30000.0, (n, k, 2))
    vi = rotate(np.repeat(vo[:, None, :], k, axis=1), rng.uniform(-np.pi, np.pi, (n, k)))
    valid = np.ones((n, k), bool)
    got, _ = _assert_kernel_matches(vo, r, vi, valid, np.full((n, k), 3300.0), 120.0)
    assert np.isnan(got[..., :4]).sum() > 0 and (~np.isnan(got[..., :4])).sum() > 0


def _ray_scene(rng):
    """A random root ψ, own velocity ``vo`` (50–300 m/s), tangent direction ``u`` and the
    turned own velocity ``ro = R(ψ)·vo`` for the tangent-ray tests (libm's cos / sin)."""
    psi = rng.uniform(-np.pi, np.pi)
    vo = rotate(np.array([rng.uniform(50.0, 300.0), 0.0]), rng.uniform(-np.pi, np.pi))
    u = rotate(np.array([1.0, 0.0]), rng.uniform(-np.pi, np.pi))
    ro = np.array([np.cos(psi) * vo[0] - np.sin(psi) * vo[1], 0.0])
    ro[1] = np.sin(psi) * vo[0] + np.cos(psi) * vo[1]
    return psi, vo, u, ro


def test_tangent_ray_test_is_the_reference_decision_near_its_threshold():
    # the fast test with cos / sin off by up to 5e-8 (above the angle-sum formula's error)
    # decides like λ = (v_i − R(ψ) v_o)·u > 1e-12·scale with libm's cos / sin, also for
    # relative speeds right at the threshold
    from airspace_sim.avoidance.heading import _on_tangent_ray

    rng = np.random.default_rng(9)
    for _ in range(3000):
        psi, vo, u, ro = _ray_scene(rng)
        scale = float(np.hypot(*vo)) * 2.0
        lam = rng.choice([0.0, 1e-12, 1e-9, 1e-7, 1e-3, 1.0]) * scale * rng.choice([-1, 1, 2])
        vi = ro + lam * u
        ref = float(np.sum((vi - ro) * u)) > 1e-12 * scale
        e = rng.uniform(-5e-8, 5e-8, 2)
        got = _on_tangent_ray(psi, np.cos(psi) + e[0], np.sin(psi) + e[1], *vo, *vi, *u, scale)
        assert got == ref


def test_fast_ray_test_decides_only_as_the_exact_test():
    # _ray_fast decides (0 / 1) with a scale from sqrt (a few ulp off; inf or NaN: never)
    # only where _on_tangent_ray with the exact scale sv + hypot(v_i) decides the same,
    # also with cos / sin off by up to 5e-8 and relative speeds at the threshold
    from airspace_sim.avoidance.heading import _on_tangent_ray, _ray_fast

    rng = np.random.default_rng(10)
    decided = 0
    for _ in range(3000):
        psi, vo, u, ro = _ray_scene(rng)
        sv = float(np.hypot(*vo))
        scale0 = 2.0 * sv
        lam = rng.choice([0.0, 1e-12, 1e-9, 1e-7, 1e-6, 1e-3, 1.0]) * scale0
        vi = ro + lam * rng.choice([-1, 1, 2]) * u
        exact = sv + float(np.hypot(*vi))
        approx = rng.choice(
            [exact, np.nextafter(exact, 0.0), np.nextafter(exact, np.inf), exact * (1 + 4e-16)]
            + [np.inf, np.nan]
        )
        e = rng.uniform(-5e-8, 5e-8, 2)
        c, s_ = np.cos(psi) + e[0], np.sin(psi) + e[1]
        got = _ray_fast(c, s_, *vo, *vi, *u, approx)
        if np.isfinite(approx):
            assert got in (0, 1, 2)
        else:
            assert got == 2
        if got != 2:
            decided += 1
            assert bool(got) == _on_tangent_ray(psi, c, s_, *vo, *vi, *u, exact)
    assert decided > 500


def test_wrap_kernel_is_numpy_wrap_angle_bit_for_bit():
    # the kernel's wrap skips fmod for |x + π| < 4π; on and around every branch edge, far
    # outside them, and at signed zeros, it must give numpy's bits
    from airspace_sim.avoidance.heading import _wrap

    rng = np.random.default_rng(12)
    edges = np.pi * np.array([-5.0, -3.0, -1.0, 0.0, 1.0, 3.0, 5.0, 7.0, -7.0])
    x = np.concatenate(
        [
            rng.uniform(-3 * np.pi, 3 * np.pi, 20000),
            rng.uniform(-1e4, 1e4, 2000),
            edges,
            np.nextafter(edges, np.inf),
            np.nextafter(edges, -np.inf),
            [0.0, -0.0, 2 * np.pi, -2 * np.pi, 1e300, -1e300],
        ]
    )
    got = np.array([_wrap(v) for v in x])
    ref = wrap_angle(x)
    assert np.array_equal(got, ref) and np.array_equal(np.signbit(got), np.signbit(ref))


@pytest.mark.parametrize("seed", range(3))
def test_roots_in_window_are_the_kernel_roots_inside_the_window(seed):
    # boundary_roots_in_window keeps, per row and in order, the roots of
    # boundary_heading_changes: all of those with |ψ| ≤ limit (same bits), only roots of
    # that kernel, none far outside the window; limits 0, small, 90°, just below π, π,
    # beyond π and NaN
    from airspace_sim.avoidance.heading import boundary_heading_changes, boundary_roots_in_window

    rng = np.random.default_rng(30 + seed)
    n, k = 300, 15
    vo = rotate(np.array([230.0, 0.0]), rng.uniform(-np.pi, np.pi, n))
    r = rng.uniform(-25000.0, 25000.0, (n, k, 2))
    r[:, :2] *= 0.1  # some inside the radius
    vi = rotate(
        np.stack([rng.uniform(0.0, 460.0, (n, k)), np.zeros((n, k))], -1),
        rng.uniform(-np.pi, np.pi, (n, k)),
    )
    valid = rng.random((n, k)) < 0.85
    radius = np.full((n, k), 3300.0)
    limit = rng.choice([0.0, 0.05, np.pi / 2, np.pi - 1e-9, np.pi, 4.0, np.nan], n)
    limit[:20] = np.pi / 2
    rel = vi - vo[:, None, :]  # the window kernel takes the relative velocity, adds vo
    vi = rel + vo[:, None, :]
    full = boundary_heading_changes(vo, r, vi, valid, radius, 120.0).reshape(n, -1)
    got, count = boundary_roots_in_window(vo, r, rel, valid, radius, 120.0, limit)
    assert got.shape == full.shape
    kept_some_out = False
    for i in range(n):
        roots = full[i][~np.isnan(full[i])]
        g = got[i, : count[i]]
        assert np.isnan(got[i, count[i] :]).all() and not np.isnan(g).any()
        # a subsequence of the kernel's roots, holding every one inside the window
        it = iter(roots)
        assert all(any(x == y for y in it) for x in g)
        inside = roots[np.abs(roots) <= limit[i]]
        assert np.array_equal(g[np.abs(g) <= limit[i]], inside)
        if limit[i] < np.pi:  # outside by more than the guard: left out
            assert (np.cos(g) >= np.cos(limit[i]) - 1e-5).all()
            kept_some_out |= count[i] < roots.size
        else:
            assert np.array_equal(g, roots)
    assert kept_some_out


def test_root_screen_only_drops_equations_without_roots_in_the_window():
    # _may_have_roots is False only where a cos ψ + b sin ψ = c has no root by the exact
    # test (|c / hypot(a, b)| ≤ 1), or both of its roots (as _solve_cos_sin computes them)
    # are outside the window; equations right at the edge (|c| = amp within 1e-9) and far
    # from it, windows of several widths
    from airspace_sim.avoidance.heading import _may_have_roots, _solve_cos_sin

    rng = np.random.default_rng(21)
    n = 20000
    a, b = rng.normal(0.0, 200.0, (2, n))
    amp = np.hypot(a, b)
    c = (
        amp
        * rng.choice([-1.0, 1.0], n)
        * (1.0 + rng.choice([0.0, 1e-12, 1e-9, 1e-6, 0.3], n) * rng.choice([-1.0, 1.0], n))
    )
    c[: n // 4] = rng.uniform(-1.2, 1.2, n // 4) * amp[: n // 4]
    limit = rng.choice([0.1, 1.0, np.pi / 2, 3.0], n)
    cos_min = np.cos(limit) - 1e-6
    roots = _solve_cos_sin(a, b, c)
    got = np.array([_may_have_roots(a[i], b[i], c[i], cos_min[i]) for i in range(n)])
    none = ~(np.abs(c / amp) <= 1.0)
    outside = (np.abs(roots) > limit[:, None]).all(axis=1)
    assert (none | outside)[~got].all()
    assert (~got & none).sum() > 1000 and (~got & ~none).sum() > 1000  # both reasons occur
    assert got[none].sum() > 10  # at the edge the exact test decides
