"""Multi-intruder band search: exact boundaries, brute-force oracle, symmetry, limits."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from airspace_sim.avoidance import band_search, resume_heading_change, tangent_heading_change
from airspace_sim.avoidance.bands import CLEAR_TOLERANCE
from airspace_sim.avoidance.cpa import cpa_min_ratio
from airspace_sim.geometry import rotate

R = 3000.0
RES = np.radians(1.0)


def random_scene(rng, n, k, spread=30000.0):
    vo = rotate(np.array([250.0, 0.0]), rng.uniform(-np.pi, np.pi, n))
    pos = rng.uniform(-spread, spread, (n, k, 2))
    # intruders mostly heading roughly toward the ownship, so conflicts are common
    aim = np.arctan2(-pos[..., 1], -pos[..., 0]) + rng.normal(0.0, 0.3, (n, k))
    vi = rotate(np.stack([rng.uniform(150, 500, (n, k)), np.zeros((n, k))], -1), aim)
    valid = rng.random((n, k)) < 0.8
    return vo, pos, vi - vo[:, None, :], valid


def slow_choice(vo, r, v, valid, cands, radius, T):
    """Pure-Python oracle: CPA per candidate per intruder, then the documented choice rule."""
    vi = v + vo
    best = None
    scored = []
    for psi in cands:
        c, s = np.cos(psi), np.sin(psi)
        ro = np.array([c * vo[0] - s * vo[1], s * vo[0] + c * vo[1]])
        worst = np.inf
        for j in range(len(r)):
            if not valid[j]:
                continue
            w = vi[j] - ro
            t = 0.0 if w @ w == 0 else min(max(-(r[j] @ w) / (w @ w), 0.0), T)
            worst = min(worst, np.linalg.norm(r[j] + t * w) / radius)
        scored.append((psi, worst))
    clear = [(psi, w) for psi, w in scored if w >= 1 - CLEAR_TOLERANCE]

    def key(pw):
        return (abs(pw[0]), pw[0] > 0)

    if clear:
        best = min(clear, key=key)[0]
    else:
        top = max(w for _, w in scored)
        best = min([pw for pw in scored if pw[1] == top], key=key)[0]
    zero = [w for psi, w in scored if psi == 0.0]
    return best, not (zero[0] >= 1 - CLEAR_TOLERANCE), {p for p, w in clear}


def grid_candidates(mx):
    m = int(np.floor(mx / RES + 1e-9))
    return [k * RES for k in range(-m, m + 1)] + [-mx, mx]


@pytest.mark.parametrize("seed", range(4))
def test_vectorised_equals_brute_force_grid(seed):
    rng = np.random.default_rng(seed)
    n, k = 12, 4
    vo, r, v, valid = random_scene(rng, n, k)
    mx = rng.uniform(0.0, np.pi / 3, n)
    mx[0] = 0.0
    res = band_search(vo, r, v, valid, mx, R, 120.0, 0.1, RES, exact_candidates=False)
    for i in range(n):
        psi, conflict, clear = slow_choice(
            vo[i], r[i], v[i], valid[i], grid_candidates(mx[i]), R * 1.1, 120.0
        )
        assert res.heading_change[i] == psi
        assert res.conflict[i] == conflict
        got = set(res.candidates[i][res.band[i]].tolist())
        assert got == clear


@pytest.mark.parametrize("seed", range(4))
def test_vectorised_equals_brute_force_with_exact_candidates(seed):
    rng = np.random.default_rng(100 + seed)
    n, k = 10, 3
    vo, r, v, valid = random_scene(rng, n, k)
    mx = np.full(n, np.pi / 4)
    res = band_search(vo, r, v, valid, mx, R, 90.0, 0.2, RES)
    for i in range(n):
        cands = res.candidates[i][~np.isnan(res.candidates[i])]
        # the candidate set holds the grid and the limits
        assert set(grid_candidates(mx[i])) <= set(cands.tolist())
        psi, conflict, _ = slow_choice(vo[i], r[i], v[i], valid[i], cands, R * 1.2, 90.0)
        assert res.heading_change[i] == psi
        assert res.conflict[i] == conflict


def single_intruder_scene(rng):
    vo = rotate(np.array([250.0, 0.0]), rng.uniform(-np.pi, np.pi))
    d = rng.uniform(8000, 40000)
    bearing = rng.uniform(-np.pi, np.pi)
    b = d * np.array([np.cos(bearing), np.sin(bearing)])
    # intruder velocity such that the relative velocity points inside the collision cone
    beta = np.arcsin(R * 1.1 / d)
    v_rel = rng.uniform(200, 700) * rotate(-b / d, rng.uniform(-0.9, 0.9) * beta)
    return vo, b, v_rel


@pytest.mark.parametrize("seed", range(30))
def test_single_intruder_reaches_exact_boundary(seed):
    rng = np.random.default_rng(seed)
    vo, b, v_rel = single_intruder_scene(rng)
    T, margin = 2000.0, 0.1  # long look-ahead: the boundary is a tangent of the cone
    mx = np.pi / 2
    res = band_search(
        vo[None],
        b[None, None],
        v_rel[None, None],
        np.ones((1, 1), bool),
        np.array([mx]),
        R,
        T,
        margin,
    )
    psi = res.heading_change[0]
    assert res.conflict[0]
    # the choice is one of heading.py's exact tangents with radius R·(1+margin) ...
    tangents = [
        tangent_heading_change(vo, v_rel + vo, b, R * (1 + margin), side)[0] for side in (-1.0, 1.0)
    ]
    ratio = cpa_min_ratio(
        vo[None],
        b[None, None],
        v_rel[None, None],
        np.ones((1, 1), bool),
        np.array([[psi]]),
        R * (1 + margin),
        T,
    )[0, 0]
    if ratio >= 1 - CLEAR_TOLERANCE and abs(psi) < mx:
        assert min(abs(psi - t) for t in tangents if np.isfinite(t)) < 1e-12
        # ... and nothing closer to the current heading is clear (fine scan)
        scan = np.linspace(-abs(psi), abs(psi), 4001)[1:-1]
        ratios = cpa_min_ratio(
            vo[None],
            b[None, None],
            v_rel[None, None],
            np.ones((1, 1), bool),
            scan[None],
            R * (1 + margin),
            T,
        )[0]
        assert np.all(ratios < 1 - CLEAR_TOLERANCE)
    # the grid-only search lands within one grid step outside of the exact boundary
    grid = band_search(
        vo[None],
        b[None, None],
        v_rel[None, None],
        np.ones((1, 1), bool),
        np.array([mx]),
        R,
        T,
        margin,
        exact_candidates=False,
    )
    if grid.band[0].any() and abs(psi) < mx - RES:
        assert 0 <= abs(grid.heading_change[0]) - abs(psi) <= RES + 1e-12


def test_all_clear_no_turn():
    vo = np.array([[250.0, 0.0], [0.0, 200.0]])
    r = np.array([[[50000.0, 50000.0]], [[-20000.0, 0.0]]])
    v = np.array([[[0.0, 300.0]], [[-300.0, -200.0]]])  # both moving away
    res = band_search(vo, r, v, np.ones((2, 1), bool), np.full(2, np.pi / 4))
    assert np.array_equal(res.heading_change, [0.0, 0.0])
    assert not res.conflict.any()
    # no valid intruder at all, or no slot at all
    res = band_search(vo, r, v, np.zeros((2, 1), bool), np.full(2, np.pi / 4))
    assert np.array_equal(res.heading_change, [0.0, 0.0]) and not res.conflict.any()
    res = band_search(
        vo, np.zeros((2, 0, 2)), np.zeros((2, 0, 2)), np.zeros((2, 0), bool), np.full(2, np.pi / 4)
    )
    assert np.array_equal(res.heading_change, [0.0, 0.0]) and not res.conflict.any()
    assert res.band[~np.isnan(res.candidates)].all()


def test_head_on_prefers_right_turn_exactly_on_tangent():
    vo = np.array([0.0, 250.0])
    vi = np.array([0.0, -250.0])
    b = np.array([0.0, 30000.0])
    res = band_search(
        vo[None],
        b[None, None],
        (vi - vo)[None, None],
        np.ones((1, 1), bool),
        np.array([np.pi / 2]),
        R,
        1000.0,
        0.1,
    )
    psi = res.heading_change[0]
    assert psi < 0 and res.conflict[0]
    exact, ok = tangent_heading_change(vo, vi, b, R * 1.1, -1.0)
    assert ok and psi == pytest.approx(exact, abs=1e-12)


def test_two_symmetric_intruders_deterministic_right_turn():
    vo = np.array([[0.0, 250.0]])
    r = np.array([[[-4000.0, 15000.0], [4000.0, 15000.0]]])
    vi = np.array([[[60.0, -250.0], [-60.0, -250.0]]])
    v = vi - vo[:, None, :]
    valid = np.ones((1, 2), bool)
    out = [band_search(vo, r, v, valid, np.array([np.pi / 3]), R, 120.0, 0.1) for _ in range(2)]
    assert out[0].conflict[0]
    assert out[0].heading_change[0] < 0
    assert out[0].heading_change[0] == out[1].heading_change[0]
    # the mirror choice is clear too: the band is symmetric
    mirror = band_search(vo, r * [-1, 1], v * [-1, 1], valid, np.array([np.pi / 3]), R)
    assert mirror.heading_change[0] == out[0].heading_change[0]
    # nothing clear within a tight limit: any turn brings one of the two closer, so the
    # maximin choice is to hold the heading
    tight = band_search(vo, r, v, valid, np.array([np.radians(2.0)]), R, 120.0, 0.1)
    assert not tight.band.any()
    assert tight.heading_change[0] == 0.0
    # one intruder dead ahead: both limits are equally good, the right one is taken
    head_on = band_search(
        vo,
        np.array([[[0.0, 15000.0]]]),
        np.array([[[0.0, -500.0]]]),
        np.ones((1, 1), bool),
        np.array([np.radians(2.0)]),
        R,
        120.0,
        0.1,
    )
    assert not head_on.band.any()
    assert head_on.heading_change[0] == -np.radians(2.0)


def test_rotation_of_whole_scene_is_invariant():
    rng = np.random.default_rng(7)
    n, k = 40, 3
    vo, r, v, valid = random_scene(rng, n, k)
    mx = np.full(n, np.pi / 4)
    base = band_search(vo, r, v, valid, mx, R, 120.0, 0.1)
    for alpha in (0.3, -2.0, np.pi / 2):
        rot = band_search(
            rotate(vo, alpha), rotate(r, alpha), rotate(v, alpha), valid, mx, R, 120.0, 0.1
        )
        assert np.array_equal(rot.conflict, base.conflict)
        assert np.allclose(rot.heading_change, base.heading_change, atol=1e-9)


@settings(max_examples=60, deadline=None)
@given(
    st.integers(0, 2**32 - 1),
    st.integers(1, 6),
    st.integers(0, 5),
    st.floats(0.0, np.pi),
    st.floats(10.0, 300.0),
)
def test_never_exceeds_max_heading_change(seed, n, k, top, T):
    rng = np.random.default_rng(seed)
    vo, r, v, valid = random_scene(rng, n, k)
    mx = rng.uniform(0.0, top, n)
    res = band_search(vo, r, v, valid, mx, R, T, 0.1)
    assert res.heading_change.shape == res.conflict.shape == (n,)
    assert np.all(np.abs(res.heading_change) <= mx + 1e-15)
    assert np.all(np.isfinite(res.heading_change))
    used = ~np.isnan(res.candidates)
    assert np.all(
        np.abs(res.candidates[used])
        <= mx.repeat(used.shape[1]).reshape(used.shape)[used] * (1 + 1e-12) + 1e-15
    )
    assert not (res.band & ~used).any()


def test_invalid_slots_are_ignored_even_with_garbage():
    rng = np.random.default_rng(3)
    vo, r, v, valid = random_scene(rng, 8, 4)
    base = band_search(vo, r, v, valid, np.full(8, 0.7))
    r2, v2 = r.copy(), v.copy()
    r2[~valid] = np.nan
    v2[~valid] = 1e9
    other = band_search(vo, r2, v2, valid, np.full(8, 0.7))
    assert np.array_equal(base.heading_change, other.heading_change)
    assert np.array_equal(base.conflict, other.conflict)


def test_per_pair_radius():
    # a bigger radius for one pair only changes the result like a bigger common radius
    rng = np.random.default_rng(5)
    vo, r, v, _ = random_scene(rng, 6, 1)
    valid = np.ones((6, 1), bool)
    a = band_search(vo, r, v, valid, np.full(6, 0.8), np.full((6, 1), 5000.0))
    b = band_search(vo, r, v, valid, np.full(6, 0.8), 5000.0)
    assert np.array_equal(a.heading_change, b.heading_change)


def test_resume():
    vo = np.array([[250.0, 0.0], [250.0, 0.0], [250.0, 0.0]])
    desired = np.array([0.5, 0.5, -2.0])
    r = np.array([[[0.0, 90000.0]], [[30000.0, 30000.0 * np.tan(0.5)]], [[0.0, 90000.0]]])
    v = np.array([[[0.0, 0.0]], [[-250.0 * np.cos(0.5), -250.0 * np.sin(0.5)]], [[0.0, 0.0]]])
    v = v - vo[:, None, :]
    psi, clear = resume_heading_change(
        vo, desired, r, v, np.ones((3, 1), bool), np.array([1.0, 1.0, 0.2])
    )
    assert clear[0] and psi[0] == pytest.approx(0.5)
    assert not clear[1] and psi[1] == 0.0  # the desired heading points at a head-on intruder
    assert clear[2] and psi[2] == pytest.approx(-0.2)  # limited


def test_kernel_equals_numpy_reference():
    from airspace_sim.avoidance.cpa import cpa_min_ratio_numpy

    rng = np.random.default_rng(11)
    vo, r, v, valid = random_scene(rng, 9, 5)
    r[~valid] = np.nan  # garbage in unused slots
    v[~valid] = np.inf
    cand = rng.uniform(-1.0, 1.0, (9, 30))
    cand[0, 3] = np.nan
    radius = rng.uniform(2000.0, 4000.0, (9, 5))
    v[1, 0] = -vo[1] + rotate(vo[1], 0.2)  # zero relative velocity at candidate ψ = 0.2
    cand[1, 0] = 0.2
    a = cpa_min_ratio(vo, r, v, valid, cand, radius, 100.0)
    b = cpa_min_ratio_numpy(vo, r, v, valid, cand, radius, 100.0)
    assert np.array_equal(a, b, equal_nan=True)
    assert np.isnan(a[0, 3]) and np.isfinite(a[1:]).all()


def test_pair_ratios_are_each_intruder_alone():
    from airspace_sim.avoidance.cpa import cpa_min_ratio_numpy, cpa_pair_ratios

    rng = np.random.default_rng(12)
    vo, r, v, valid = random_scene(rng, 7, 4)
    cand = rng.uniform(-1.0, 1.0, (7, 6))
    radius = rng.uniform(2000.0, 4000.0, (7, 1))  # per ownship, as the resume rules pass it
    got = cpa_pair_ratios(vo, r, v, valid, cand, radius, 100.0)
    assert got.shape == (7, 4, 6)
    for k in range(4):  # the numpy reference with every other intruder masked out
        alone = valid & (np.arange(4) == k)
        want = cpa_min_ratio_numpy(vo, r, v, alone, cand, radius, 100.0)
        assert np.array_equal(got[:, k], want)
    assert np.all(got[~valid] == np.inf) and (~valid).any() and valid.any()
    none = cpa_pair_ratios(vo, r[:, :0], v[:, :0], valid[:, :0], cand, 1.0, 100.0)
    assert none.shape == (7, 0, 6)


def test_left_penalty_biases_toward_right_turns():
    # intruder slightly right of dead ahead: the nearest clear heading is a left turn
    vo = np.array([[0.0, 250.0]])
    r = np.array([[[600.0, 20000.0]]])
    v = np.array([[[0.0, -500.0]]])
    valid = np.ones((1, 1), bool)
    mx = np.array([np.pi / 2])
    plain = band_search(vo, r, v, valid, mx, R, 120.0, 0.1)
    assert plain.heading_change[0] > 0
    biased = band_search(vo, r, v, valid, mx, R, 120.0, 0.1, left_penalty=np.radians(30))
    assert biased.heading_change[0] < 0
    assert biased.band[0][biased.candidates[0] == biased.heading_change[0]].all()


# ---------------------------------------------------------------- turn dynamics


def _flown_min_ratio(vo, r, v, valid, psi, radius, T, w, steps=24001):
    """Brute force: ownship turns at ``w`` until ``psi``, then straight; dense time samples."""
    t = np.linspace(0.0, T, steps)
    s, h0 = np.hypot(*vo), np.arctan2(vo[1], vo[0])
    h = h0 + np.sign(psi) * np.minimum(w * t, abs(psi))
    dt = np.diff(t)
    mid = 0.5 * (h[:-1] + h[1:])
    ox = np.concatenate([[0.0], np.cumsum(s * np.cos(mid) * dt)])
    oy = np.concatenate([[0.0], np.cumsum(s * np.sin(mid) * dt)])
    vi = v + vo
    d = [
        np.hypot(r[k, 0] + vi[k, 0] * t - ox, r[k, 1] + vi[k, 1] * t - oy).min() / radius
        for k in range(len(valid))
        if valid[k]
    ]
    return min(d) if d else np.inf


def test_turning_cpa_instantaneous_rate_is_plain_cpa():
    from airspace_sim.avoidance.cpa_turning import cpa_min_ratio_turning

    rng = np.random.default_rng(3)
    vo, r, v, valid = random_scene(rng, 20, 6)
    psi = rng.uniform(-np.pi / 2, np.pi / 2, (20, 15))
    a = cpa_min_ratio(vo, r, v, valid, psi, R * 1.1, 120.0)
    for w in (np.inf, 0.0):
        b = cpa_min_ratio_turning(vo, r, v, valid, psi, R * 1.1, 120.0, w)
        np.testing.assert_allclose(b, a, rtol=1e-9, atol=1e-12)


def test_turning_cpa_matches_dense_flown_trajectory():
    from airspace_sim.avoidance.cpa_turning import cpa_min_ratio_turning

    rng = np.random.default_rng(4)
    w = np.radians(3.0)
    vo, r, v, valid = random_scene(rng, 12, 5, spread=15000.0)
    psi = rng.uniform(-np.pi / 2, np.pi / 2, (12, 4))
    fine = cpa_min_ratio_turning(vo, r, v, valid, psi, R, 120.0, w, segment=np.radians(0.5))
    coarse = cpa_min_ratio_turning(vo, r, v, valid, psi, R, 120.0, w)
    for n in range(12):
        for c in range(4):
            ref = _flown_min_ratio(vo[n], r[n], v[n], valid[n], psi[n, c], R, 120.0, w)
            assert fine[n, c] == pytest.approx(ref, abs=2e-3)
            # 15° chords: within the chord sagitta (≈ 45 m at 250 m/s, 3°/s)
            assert abs(coarse[n, c] - ref) * R < 60.0


def test_band_search_with_turn_rate_sees_the_turn_path():
    # an intruder sits just off the right of the ownship's path: an instant 90° right turn
    # looks clear, but the flown arc (radius 250/ω ≈ 4.8 km) sweeps through it
    vo = np.array([[250.0, 0.0]])
    r = np.array([[[3500.0, -4500.0]]])
    v = -vo[:, None, :]  # stationary intruder
    valid = np.ones((1, 1), bool)
    psi = np.array([[-np.pi / 2]])
    from airspace_sim.avoidance.cpa_turning import cpa_min_ratio_turning

    inst = cpa_min_ratio(vo, r, v, valid, psi, R, 120.0)[0, 0]
    flown = cpa_min_ratio_turning(vo, r, v, valid, psi, R, 120.0, np.radians(3.0))[0, 0]
    assert inst > 1.0 and flown < 1.0
    res = band_search(
        vo, r, v, valid, np.array([np.pi / 2]), R, 120.0, 0.0, turn_rate=np.radians(3.0)
    )
    ok = res.band[0] & (res.candidates[0] == -np.pi / 2)
    assert not ok.any()


@pytest.mark.parametrize("seed", range(4))
def test_first_clear_search_equals_the_full_band(seed):  # noqa: D103
    # band_search(full=False) scans candidates only until each side has a clear one; its
    # choice, first clear candidates and (where a side has none) min ratios must equal the
    # full evaluation of every candidate against every intruder
    rng = np.random.default_rng(seed)
    n, k = 300, 12
    heading = rng.uniform(-np.pi, np.pi, n)
    vo = 230.0 * np.stack([np.cos(heading), np.sin(heading)], axis=1)
    r = rng.uniform(-30000.0, 30000.0, (n, k, 2))
    vi = rng.uniform(-300.0, 300.0, (n, k, 2))
    valid = rng.random((n, k)) < 0.8
    mx = np.radians(rng.choice([3.0, 45.0, 90.0, 180.0], n))
    full = band_search(vo, r, vi - vo[:, None], valid, mx, 3000.0, 120.0, 0.1)
    fast = band_search(vo, r, vi - vo[:, None], valid, mx, 3000.0, 120.0, 0.1, full=False)
    assert fast.band is None
    # the same sorted candidates, though the fast path sorts only the roots in the window
    assert np.array_equal(fast.candidates, full.candidates, equal_nan=True)
    np.testing.assert_array_equal(fast.heading_change, full.heading_change)
    np.testing.assert_array_equal(fast.conflict, full.conflict)
    np.testing.assert_array_equal(fast.first_clear, full.first_clear)
    np.testing.assert_array_equal(fast.best_blocked, full.best_blocked)
    blocked = full.first_clear[:, :2] < 0
    assert blocked.any() and (~blocked).any()  # both kinds of sides occur
    assert ((full.first_clear[:, :2] < 0) == (full.best_blocked >= 0)).all()
    # the best blocked candidate is the (first) maximum of the full min ratio on its side
    for col, on_side in enumerate((full.candidates <= 0, full.candidates >= 0)):
        score = np.where(on_side & ~np.isnan(full.candidates), full.min_ratio, -np.inf)
        rows = np.flatnonzero(blocked[:, col])
        np.testing.assert_array_equal(full.best_blocked[rows, col], np.argmax(score[rows], axis=1))


@pytest.mark.parametrize("left_penalty", [0.0, RES, 0.25, np.inf])
def test_fast_rows_equal_the_full_band_at_odd_limits(left_penalty):
    """The fast path's rows (packed roots, the sort's bucket placement, origin and usable
    written only up to the last usable entry) equal the full path's at zero, tiny, mixed
    and ±π limits and at any left penalty: the same sorted candidates, first clear, best
    blocked and choice. At infinite limits the sorted candidates (±inf among them) too;
    there the paths judge ψ = ±inf differently (NaN ratios: clear in the full kernel's
    running minimum, blocked in the scans), so only the candidates are compared."""
    rng = np.random.default_rng(11)
    n, k = 240, 10
    heading = rng.uniform(-np.pi, np.pi, n)
    vo = 230.0 * np.stack([np.cos(heading), np.sin(heading)], axis=1)
    r = rng.uniform(-25000.0, 25000.0, (n, k, 2))
    vi = rng.uniform(-300.0, 300.0, (n, k, 2))
    valid = rng.random((n, k)) < 0.8
    mx = np.radians(rng.choice([0.0, 1e-9, 0.5, 1.0, 7.3, 45.0, 90.0, 180.0], n))
    for lims in (mx, np.where(np.arange(n) % 7 == 0, np.inf, mx)):
        args = (vo, r, vi - vo[:, None], valid, lims, 3000.0, 120.0, 0.1)
        kw = dict(left_penalty=left_penalty)
        with np.errstate(invalid="ignore"):
            full = band_search(*args, **kw)
            fast = band_search(*args, full=False, **kw)
        assert np.array_equal(fast.candidates, full.candidates, equal_nan=True)
        assert np.array_equal(np.signbit(fast.candidates), np.signbit(full.candidates))
        if np.isinf(lims).any():
            assert np.isinf(fast.candidates).any()  # the infinite limits' ±inf are there
            continue
        np.testing.assert_array_equal(fast.first_clear, full.first_clear)
        np.testing.assert_array_equal(fast.best_blocked, full.best_blocked)
        np.testing.assert_array_equal(fast.heading_change, full.heading_change)


@pytest.mark.parametrize("seed", range(3))
def test_boundary_kernel_gives_the_numpy_candidates_choices(seed, monkeypatch):
    """band_search with the numba boundary kernel makes the same choices as with the numpy
    reference candidates (``exact_boundary_candidates_numpy``) on many random encounters."""
    from airspace_sim.avoidance import bands

    rng = np.random.default_rng(100 + seed)
    n, k = 150, 12
    vo, r, v, valid = random_scene(rng, n, k, spread=15000.0)
    mx = rng.uniform(0.0, np.pi, n)
    radius = rng.uniform(2000.0, 4000.0, (n, k))
    runs = []
    for fn in (bands.exact_boundary_candidates, bands.exact_boundary_candidates_numpy):
        monkeypatch.setattr(bands, "exact_boundary_candidates", fn)
        for full, penalty in ((False, 0.0), (True, 0.0), (False, 0.1)):
            runs.append(
                band_search(vo, r, v, valid, mx, radius, 120.0, 0.1, RES, True, penalty, full=full)
            )
    for fast, ref in zip(runs[:3], runs[3:]):
        # equal here; elsewhere numpy's SIMD sin/cos may differ from libm in the last bits
        assert np.array_equal(np.isnan(fast.candidates), np.isnan(ref.candidates))
        assert np.nanmax(np.abs(fast.candidates - ref.candidates)) <= 1e-12
        assert np.all(np.abs(fast.heading_change - ref.heading_change) <= 1e-12)
        assert np.array_equal(fast.conflict, ref.conflict)
        assert np.array_equal(fast.first_clear, ref.first_clear)
        assert np.array_equal(fast.best_blocked, ref.best_blocked)
    assert runs[0].conflict.sum() > n // 4  # the scene exercises the search


@pytest.mark.parametrize("left_penalty", [0.0, RES, 0.25, np.inf])
def test_preferred_candidates_equal_the_lexsort_reference(left_penalty):
    """The numba candidate sort gives the numpy lexsort's array bit for bit: ties in ``|ψ|``
    (grid ±kΔ, repeated boundary roots, ±0), NaN and out-of-limit extras, infinite and NaN
    limits."""
    from airspace_sim.avoidance.bands import (
        candidate_grid,
        preferred_candidates,
        sort_by_preference_numpy,
    )

    rng = np.random.default_rng(7)
    n, e = 60, 40
    mx = rng.uniform(0.0, np.pi, n)
    mx[:3] = [0.0, np.inf, np.nan]
    extra = rng.uniform(-np.pi, np.pi, (n, e))
    extra[rng.random((n, e)) < 0.4] = np.nan
    extra[:, :6] = rng.choice([0.0, -0.0, RES, -RES, 5 * RES, np.pi, -np.pi], (n, 6))
    extra[:, 6] = -mx  # duplicates of the limits
    extra[:, 7] = extra[:, 8] = rng.uniform(-1.0, 1.0, n)  # a repeated root
    extra[:, 9] = np.nextafter(mx, np.inf)  # just outside ±max: dropped unless within 1e-12
    extra[:, 10] = mx * (1 + 1e-11)
    got = preferred_candidates(mx, RES, extra, left_penalty)
    ref = sort_by_preference_numpy(candidate_grid(mx, RES, extra), left_penalty)
    assert got.shape == ref.shape
    assert np.array_equal(got, ref, equal_nan=True)
    assert np.array_equal(np.signbit(got), np.signbit(ref))
    assert np.isinf(got[1]).sum() >= 2  # ψ = ±inf are usable with an infinite limit
    assert np.array_equal(
        preferred_candidates(mx, RES, None, left_penalty),
        sort_by_preference_numpy(candidate_grid(mx, RES), left_penalty),
        equal_nan=True,
    )


@pytest.mark.parametrize("full", [False, True])
def test_committed_side_searches_only_that_side(full):
    # with a committed side, best_blocked is the side-free search's on that side and −1 on
    # the other; rows without a side are unchanged; where nothing is clear the choice is
    # the committed side's best
    rng = np.random.default_rng(11)
    n, k = 300, 12
    heading = rng.uniform(-np.pi, np.pi, n)
    vo = 230.0 * np.stack([np.cos(heading), np.sin(heading)], axis=1)
    r = rng.uniform(-20000.0, 20000.0, (n, k, 2))
    vi = rng.uniform(-300.0, 300.0, (n, k, 2))
    valid = rng.random((n, k)) < 0.9
    mx = np.radians(rng.choice([10.0, 45.0, 90.0], n))
    side = rng.choice([-1.0, 0.0, 1.0], n)
    args = (vo, r, vi - vo[:, None], valid, mx, 3000.0, 120.0, 0.1)
    free = band_search(*args, full=full)
    got = band_search(*args, full=full, committed_side=side)
    np.testing.assert_array_equal(got.first_clear, free.first_clear)
    np.testing.assert_array_equal(got.candidates, free.candidates)
    col = np.where(side < 0, 0, 1)
    rows = np.arange(n)
    on = side != 0
    np.testing.assert_array_equal(got.best_blocked[on, col[on]], free.best_blocked[on, col[on]])
    assert (got.best_blocked[on, 1 - col[on]] == -1).all()
    np.testing.assert_array_equal(got.best_blocked[~on], free.best_blocked[~on])
    none_clear = (free.first_clear[:, 0] < 0) & (free.first_clear[:, 1] < 0)
    assert (none_clear & on).sum() > 10  # the scene has rows blocked on both sides
    np.testing.assert_array_equal(
        got.heading_change[~(none_clear & on)], free.heading_change[~(none_clear & on)]
    )
    pick = free.candidates[rows, free.best_blocked[rows, col]]
    np.testing.assert_array_equal(got.heading_change[none_clear & on], pick[none_clear & on])


@pytest.mark.parametrize("seed", range(3))
def test_search_kernels_with_intruders_inside_the_radius_equal_the_full_band(seed):
    """Rows with an intruder already inside the clear radius (which the fast kernels settle
    from the current distance: no clear heading, no minimum above it), some exactly on the
    radius or just inside or outside it: the same first clear and best blocked candidates
    as the full evaluation."""
    rng = np.random.default_rng(40 + seed)
    n, k = 400, 10
    radius = 3300.0
    heading = rng.uniform(-np.pi, np.pi, n)
    vo = 230.0 * np.stack([np.cos(heading), np.sin(heading)], axis=1)
    r = rng.uniform(-25000.0, 25000.0, (n, k, 2))
    vi = rng.uniform(-300.0, 300.0, (n, k, 2))
    valid = rng.random((n, k)) < 0.9
    # intruder 0 at a distance of 0.2 to 1.2 radii, or on the radius (rounded either way)
    bearing = rng.uniform(-np.pi, np.pi, n)
    dist = radius * rng.uniform(0.2, 1.2, n)
    edge = rng.random(n) < 0.3
    dist[edge] = (
        radius * (1.0 - CLEAR_TOLERANCE) * rng.choice([1.0, 1 - 1e-15, 1 + 1e-15], edge.sum())
    )
    r[:, 0] = dist[:, None] * np.stack([np.cos(bearing), np.sin(bearing)], axis=1)
    vi[:, 0] = rng.uniform(-1.0, 1.0, (n, 2)) * rng.choice([0.0, 50.0, 300.0], (n, 1))
    mx = np.radians(rng.choice([3.0, 45.0, 90.0, 180.0], n))
    args = (vo, r, vi - vo[:, None], valid, mx, 3000.0, 120.0, 0.1)
    full = band_search(*args)
    fast = band_search(*args, full=False)
    np.testing.assert_array_equal(fast.first_clear, full.first_clear)
    np.testing.assert_array_equal(fast.best_blocked, full.best_blocked)
    np.testing.assert_array_equal(fast.heading_change, full.heading_change)
    inside = valid[:, 0] & (dist < radius * (1 - CLEAR_TOLERANCE))
    assert inside.sum() > n // 2 and (valid[:, 0] & ~inside).sum() > 20
    assert (full.first_clear[inside] == -1).all()
    # where the best blocked heading flies away from the close intruder, its minimum is
    # the current distance ratio (the bound the search stops at)
    rows = np.flatnonzero(inside & (full.best_blocked[:, 0] >= 0))
    best = full.min_ratio[rows, full.best_blocked[rows, 0]]
    now = np.sqrt(np.min(np.where(valid, np.sum(r * r, -1), np.inf), axis=1))[rows] / radius
    assert (best <= now).all() and (best == now).sum() > 10


def test_clear_ratio2_is_the_square_root_test():
    # q2 >= clear_ratio2(t) decides like np.sqrt(q2) >= t, at and around the edge, for the
    # band search's threshold and others
    from airspace_sim.avoidance.cpa import clear_ratio2

    rng = np.random.default_rng(3)
    ts = np.concatenate([[1.0 - CLEAR_TOLERANCE, 1.0, 0.5, 1e-160, 3e150], rng.uniform(0, 4, 300)])
    for t in ts:
        x0 = clear_ratio2(t)
        q2 = np.concatenate([[x0, t * t, 0.0, np.inf, np.nan], rng.uniform(0, 2, 20) * t * t])
        near = x0
        for _ in range(4):
            near = np.nextafter(near, 0.0)
            q2 = np.append(q2, near)
        near = x0
        for _ in range(4):
            near = np.nextafter(near, np.inf)
            q2 = np.append(q2, near)
        with np.errstate(invalid="ignore"):
            assert np.array_equal(q2 >= x0, np.sqrt(q2) >= t)
        assert np.sqrt(x0) >= t and not np.sqrt(np.nextafter(x0, 0.0)) >= t
    assert clear_ratio2(0.0) == -np.inf and clear_ratio2(np.inf) == np.inf
    assert np.isnan(clear_ratio2(np.nan))
