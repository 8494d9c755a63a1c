"""The as-flown band search ("bands-flown", avoidance/flown_bands.py): the open sides are
"bands"', the heading on a side is the first clear at once and as flown, and a scene whose
choice follows from the closed-form as-flown miss distance."""

import math

import numpy as np
import pytest
from scipy.optimize import brentq

from airspace_sim import registry
from airspace_sim.avoidance.cpa_turning import cpa_min_ratio_turning
from airspace_sim.avoidance.flown_bands import FlownBandsResolver
from airspace_sim.avoidance.resolvers import BandsResolver

RATE = math.radians(3.0)


def _random_scene(seed, n=120, k=5):
    rng = np.random.default_rng(seed)
    vo = rng.normal(size=(n, 2))
    vo *= rng.uniform(180, 260, (n, 1)) / np.linalg.norm(vo, axis=1, keepdims=True)
    r = rng.uniform(-15000, 15000, (n, k, 2))
    vi = rng.normal(size=(n, k, 2))
    vi *= rng.uniform(180, 260, (n, k, 1)) / np.linalg.norm(vi, axis=-1, keepdims=True)
    valid = (rng.random((n, k)) < 0.85) & (np.hypot(r[..., 0], r[..., 1]) > 3300.0)
    return vo, r, vi - vo[:, None], valid, np.full(n, math.pi / 2)


def _committed_sides(n):
    """(n,) committed sides for random-scene tests: left on every third row, fresh (0) on
    every fifth, right elsewhere."""
    kept = np.where(np.arange(n) % 3 == 0, 1.0, -1.0)
    kept[np.arange(n) % 5 == 0] = 0.0
    return kept


def _head_on(ahead_m, right_m):
    """One ownship east at 230 m/s committed right, a head-on intruder (460 m/s closing)
    ``ahead_m`` ahead and ``right_m`` to the right, turn limit ±30°, turn rate 3°/s:
    ``(vo, r, v, valid, mx, rate, side)``."""
    return (
        np.array([[230.0, 0.0]]),
        np.array([[[ahead_m, -right_m]]]),
        np.array([[[-460.0, 0.0]]]),
        np.ones((1, 1), bool),
        np.array([math.radians(30.0)]),
        np.array([RATE]),
        np.array([-1.0]),
    )


def _policy_pick(params, scene):
    """The resolver's output on a :func:`_head_on` scene and the heading change and side
    the CDA policy (right-of-way preference) flies from it: ``(out, psi (1,), side (1,))``."""
    from airspace_sim.world.policy import commit_reference

    vo, r, v, valid, mx, rate, side = scene
    out = FlownBandsResolver(params).resolve(
        vo, r, v, valid, mx, turn_rate=rate, committed_side=side
    )
    psi, new_side = commit_reference(
        "right",
        out.heading_change,
        out.conflict,
        side,
        out.candidates,
        out.first_clear,
        out.best_blocked,
    )
    return out, psi, new_side


def test_registered():
    assert registry.get("resolver", "bands-flown") is FlownBandsResolver


@pytest.mark.parametrize("seed", [0, 1])
def test_sides_are_bands_and_heading_is_first_clear_as_flown(seed):
    vo, r, v, valid, mx = _random_scene(seed)
    rate = np.full(vo.shape[0], RATE)
    ob = BandsResolver(BandsResolver.Params(lookahead_s=45.0)).resolve(
        vo, r, v, valid, mx, turn_rate=rate
    )
    of = FlownBandsResolver(FlownBandsResolver.Params(lookahead_s=45.0)).resolve(
        vo, r, v, valid, mx, turn_rate=rate
    )
    np.testing.assert_array_equal(of.conflict, ob.conflict)
    np.testing.assert_array_equal(of.first_clear >= 0, ob.first_clear >= 0)
    rows = np.flatnonzero(of.conflict)
    cand = of.candidates[rows]
    flown = cpa_min_ratio_turning(
        vo[rows], r[rows], v[rows], valid[rows], np.nan_to_num(cand), 3300.0, 45.0, rate[rows]
    )
    good = of.band[rows] & (flown >= 1.0 - 1e-9)
    checked = 0
    for col, mask in enumerate((cand <= 0, cand >= 0, cand < 0)):
        idx = of.first_clear[rows, col]
        has = (good & mask).any(axis=1)
        np.testing.assert_array_equal(idx[has], np.argmax((good & mask)[has], axis=1))
        # an open side without a heading clear as flown: its best as-flown clear heading
        weak = ~has & (idx >= 0)
        top = np.max(np.where(of.band[rows] & mask, flown, -np.inf), axis=1)
        np.testing.assert_allclose(flown[weak, idx[weak]], top[weak])
        checked += int(has.sum() + weak.sum())
    assert checked > 0
    assert np.isin(of.heading_change[rows], cand).all()


def test_closed_form_stationary_obstacle():
    """Ownship east at 230 m/s, a stationary intruder 12 km dead ahead, r_safe·1.1 = 3.3 km.
    At once, the miss is D·|sin ψ| ("bands": ψ = −asin(R0/D), ties go right). As flown,
    a right turn by a at ω = 3°/s ends at X(a) = ρ(sin a, −(1 − cos a)), ρ = v/ω, heading
    −a, and the miss is the distance from the obstacle to that line (its closest point
    ahead of X; the arc stays farther): ``"bands-flown"`` takes the first candidate beyond
    the root a_f of miss(a) = R0, the next 1° grid step."""
    speed, dist, radius = 230.0, 12000.0, 3300.0
    rho = speed / RATE

    def miss(a):
        x = np.array([rho * math.sin(a), -rho * (1.0 - math.cos(a))])
        u = np.array([math.cos(a), -math.sin(a)])
        d = np.array([dist, 0.0]) - x
        assert d @ u > 0
        return abs(d[0] * u[1] - d[1] * u[0])

    a_f = brentq(lambda a: miss(a) - radius, 0.01, 1.0)
    assert math.asin(radius / dist) < a_f < math.asin(radius / dist) + math.radians(1.5)
    vo = np.array([[speed, 0.0]])
    r = np.array([[[dist, 0.0]]])
    args = (vo, r, -vo[:, None], np.ones((1, 1), bool), np.array([math.pi / 2]))
    rate = np.array([RATE])
    ob = BandsResolver(BandsResolver.Params()).resolve(*args, turn_rate=rate)
    of = FlownBandsResolver(FlownBandsResolver.Params()).resolve(*args, turn_rate=rate)
    assert ob.heading_change[0] == pytest.approx(-math.asin(radius / dist), abs=1e-12)
    step = math.radians(1.0)
    assert of.heading_change[0] == pytest.approx(-math.ceil(a_f / step) * step, abs=1e-12)


def test_fresh_sides_only_is_model_turn_but_for_a_fresh_ownships_open_sides():
    """fresh_sides_only: a committed ownship gets exactly "bands"' model_turn search; a
    fresh one sees "bands"' open sides, each with its first heading clear as flown, else
    its best as-flown one."""
    vo, r, v, valid, mx = _random_scene(3)
    n = vo.shape[0]
    rate = np.full(n, RATE)
    params = dict(lookahead_s=45.0)
    flown = FlownBandsResolver(FlownBandsResolver.Params(fresh_sides_only=True, **params))
    model = BandsResolver(BandsResolver.Params(model_turn=True, **params))
    kept = np.where(np.arange(n) % 2 == 0, -1.0, 1.0)
    a = flown.resolve(vo, r, v, valid, mx, turn_rate=rate, committed_side=kept)
    b = model.resolve(vo, r, v, valid, mx, turn_rate=rate, committed_side=kept)
    c = a.conflict
    np.testing.assert_array_equal(a.heading_change[c], b.heading_change[c])
    np.testing.assert_array_equal(a.first_clear[c], b.first_clear[c])
    np.testing.assert_array_equal(a.best_blocked[c], b.best_blocked[c])
    fresh = np.zeros(n)
    a = flown.resolve(vo, r, v, valid, mx, turn_rate=rate, committed_side=fresh)
    at_once = BandsResolver(BandsResolver.Params(**params)).resolve(
        vo, r, v, valid, mx, turn_rate=rate, committed_side=fresh
    )
    b = model.resolve(vo, r, v, valid, mx, turn_rate=rate, committed_side=fresh)
    c = a.conflict
    np.testing.assert_array_equal(
        a.first_clear[c] >= 0, (at_once.first_clear[c] >= 0) | (b.first_clear[c] >= 0)
    )
    lifted = (a.first_clear[c] != b.first_clear[c]).any(axis=1)
    assert lifted.any()
    cand, ratio = a.candidates[c], a.min_ratio[c]
    for col, mask in enumerate((cand <= 0, cand >= 0, cand < 0)):
        idx = a.first_clear[c, col]
        moved = idx != b.first_clear[c, col]
        top = np.max(np.where(mask & ~np.isnan(cand), ratio, -np.inf), axis=1)
        np.testing.assert_array_equal(ratio[moved, idx[moved]], top[moved])
        assert (ratio[moved, idx[moved]] < 1.0).all()


@pytest.mark.parametrize("at_once", [False, True])
def test_switch_below_sends_a_boxed_committed_ownship_to_the_other_sides_clear_heading(at_once):
    """switch_below: on random scenes the output is fresh_sides_only's except the committed
    side's best blocked where that side is boxed, the other side clear and the best blocked
    ratio below the threshold; there it is the other side's first clear candidate. With
    switch_blocked_at_once, only where the committed side has no candidate clear at once
    (the reported band is the at-once one)."""
    vo, r, v, valid, mx = _random_scene(5, n=300)
    n = vo.shape[0]
    rate = np.full(n, RATE)
    kept = _committed_sides(n)
    p = dict(lookahead_s=45.0, fresh_sides_only=True)
    base = FlownBandsResolver(FlownBandsResolver.Params(**p)).resolve(
        vo, r, v, valid, mx, turn_rate=rate, committed_side=kept
    )
    switched = at_once_kept = 0
    for below in (0.6, 1.0):
        params = FlownBandsResolver.Params(switch_below=below, switch_blocked_at_once=at_once, **p)
        out = FlownBandsResolver(params).resolve(
            vo, r, v, valid, mx, turn_rate=rate, committed_side=kept
        )
        np.testing.assert_array_equal(out.first_clear, base.first_clear)
        np.testing.assert_array_equal(out.heading_change, base.heading_change)
        for col, other, value in ((0, 1, -1.0), (1, 0, 1.0)):
            b = base.best_blocked[:, col]
            ratio = base.min_ratio[np.arange(n), np.maximum(b, 0)]
            swap = (
                (kept == value)
                & (base.first_clear[:, col] < 0)
                & (base.first_clear[:, other] >= 0)
                & (b >= 0)
                & (ratio < below)
            )
            side_mask = base.candidates <= 0 if col == 0 else base.candidates >= 0
            open_at_once = (base.band & side_mask).any(axis=1)
            if at_once:
                swap &= ~open_at_once
            else:
                at_once_kept += int((swap & open_at_once).sum())
            np.testing.assert_array_equal(
                out.best_blocked[:, col], np.where(swap, base.first_clear[:, other], b)
            )
            switched += int(swap.sum())
    assert switched > 0
    assert at_once or at_once_kept > 0  # the two rules differ on these scenes


def test_switch_below_head_on_intruder_offset_to_the_right():
    """Ownship east at 230 m/s committed right, a head-on intruder 15 km ahead and 1 km to
    the right, turn limit ±30°: every right turn steers toward the intruder's side and
    stays inside 3.3 km as flown (a 30° right turn gains about v·sin 30°·t ≈ 3.4 km over the
    ~30 s to the crossing, minus the 1 km offset), while a left turn clears it. Without the
    switch the CDA policy flies the right side's best blocked heading; with it, the left
    side's first clear one, which is clear as flown."""
    scene = _head_on(15000.0, 1000.0)
    vo, r, v, valid, mx, rate, side = scene
    picks = {}
    for below in (0.0, 1.0):
        params = FlownBandsResolver.Params(fresh_sides_only=True, switch_below=below)
        out, psi, new_side = _policy_pick(params, scene)
        assert out.first_clear[0, 0] < 0 <= out.first_clear[0, 1]  # right boxed, left clear
        picks[below] = psi[0]
        assert new_side[0] == -1.0
    assert picks[0.0] <= 0.0
    assert picks[1.0] > 0.0
    flown = cpa_min_ratio_turning(
        vo, r, v, valid, np.array([[picks[0.0], picks[1.0]]]), 3300.0, 120.0, rate
    )[0]
    assert flown[0] < 1.0 <= flown[1] + 1e-9


AO = dict(fresh_sides_only=True, switch_below=1.0, switch_blocked_at_once=True)


def test_boxed_best_both_is_fresh_ao_except_where_boxed_on_both_sides():
    """boxed_best_both: on random scenes the output is fresh:ao's (``AO``) except for a
    committed ownship with no heading clear as flown on either side; there the committed
    side's best blocked (and so the chosen heading) is the candidate of largest as-flown
    ratio over both sides when that beats the committed side's own best."""
    vo, r, v, valid, mx = _random_scene(7, n=400, k=8)
    n = vo.shape[0]
    rate = np.full(n, RATE)
    kept = _committed_sides(n)
    base = FlownBandsResolver(FlownBandsResolver.Params(**AO)).resolve(
        vo, r, v, valid, mx, turn_rate=rate, committed_side=kept
    )
    out = FlownBandsResolver(FlownBandsResolver.Params(boxed_best_both=True, **AO)).resolve(
        vo, r, v, valid, mx, turn_rate=rate, committed_side=kept
    )
    np.testing.assert_array_equal(out.first_clear, base.first_clear)
    np.testing.assert_array_equal(out.min_ratio, base.min_ratio)
    np.testing.assert_array_equal(out.conflict, base.conflict)
    rows = np.arange(n)
    usable = ~np.isnan(base.candidates)
    score = np.where(usable, base.min_ratio, -np.inf)
    top = np.argmax(score, axis=1)
    boxed = (base.first_clear[:, 0] < 0) & (base.first_clear[:, 1] < 0)
    swapped = np.zeros(n, dtype=bool)
    for col, value in ((0, -1.0), (1, 1.0)):
        b = base.best_blocked[:, col]
        own = np.where(b >= 0, score[rows, np.maximum(b, 0)], -np.inf)
        swap = boxed & (kept == value) & (score[rows, top] > own)
        np.testing.assert_array_equal(out.best_blocked[:, col], np.where(swap, top, b))
        swapped |= swap
    assert swapped.sum() > 5
    np.testing.assert_array_equal(out.heading_change[~swapped], base.heading_change[~swapped])
    np.testing.assert_array_equal(
        out.heading_change[swapped], base.candidates[swapped, top[swapped]]
    )
    # the rows that change are boxed on both sides and committed, never fresh
    assert (kept[swapped] != 0).all()


def test_boxed_best_both_head_on_intruder_offset_to_the_right():
    """Ownship east at 230 m/s committed right, a head-on intruder 8 km ahead and 500 m to
    the right, turn limit ±30°: ~17 s to the crossing, too short for a clear turn either way
    (boxed on both sides as flown), but a left turn opens the miss further than any right
    one. fresh:ao keeps the right side's best; with boxed_best_both the policy flies the
    left heading of largest as-flown ratio, still committed right."""
    scene = _head_on(8000.0, 500.0)
    vo, r, v, valid, mx, rate, side = scene
    picks = {}
    for both in (False, True):
        params = FlownBandsResolver.Params(boxed_best_both=both, **AO)
        out, psi, new_side = _policy_pick(params, scene)
        assert (out.first_clear[0, :2] < 0).all()  # boxed on both sides
        picks[both] = psi[0]
        assert new_side[0] == -1.0
    assert picks[False] <= 0.0 < picks[True]
    cand = out.candidates[~np.isnan(out.candidates)][None, :]
    flown = cpa_min_ratio_turning(vo, r, v, valid, cand, 3300.0, 120.0, rate)[0]
    pair = cpa_min_ratio_turning(
        vo, r, v, valid, np.array([[picks[False], picks[True]]]), 3300.0, 120.0, rate
    )[0]
    assert pair[0] < pair[1] < 1.0
    assert pair[0] == pytest.approx(flown[cand[0] <= 0].max())
    assert pair[1] == pytest.approx(flown.max())


@pytest.mark.parametrize("seed", [7, 11])
def test_boxed_margin_spans_boxed_best_both_to_fresh_ao(seed):
    """boxed_margin: at 0 the output is boxed_best_both's, at a margin above any ratio gap it
    is fresh:ao's (``AO``), and in between the swap is boxed_best_both's where the gain
    exceeds the margin."""
    vo, r, v, valid, mx = _random_scene(seed, n=400, k=8)
    n = vo.shape[0]
    rate = np.full(n, RATE)
    kept = _committed_sides(n)

    def run(**kw):
        return FlownBandsResolver(FlownBandsResolver.Params(**AO, **kw)).resolve(
            vo, r, v, valid, mx, turn_rate=rate, committed_side=kept
        )

    base, both = run(), run(boxed_best_both=True)
    fields = ("heading_change", "conflict", "first_clear", "best_blocked", "min_ratio")
    for name in fields:
        np.testing.assert_array_equal(
            getattr(run(boxed_best_both=True, boxed_margin=0.0), name), getattr(both, name)
        )
        np.testing.assert_array_equal(
            getattr(run(boxed_best_both=True, boxed_margin=1e6), name), getattr(base, name)
        )
    rows = np.arange(n)
    score = np.where(~np.isnan(base.candidates), base.min_ratio, -np.inf)
    col = np.where(kept > 0, 1, 0)
    changed = both.heading_change != base.heading_change
    gain = np.full(n, -np.inf)
    c = rows[changed]
    gain[c] = score[c, both.best_blocked[c, col[c]]] - score[c, base.best_blocked[c, col[c]]]
    assert changed.sum() > 5
    margin = float(np.median(gain[changed]))
    mid = run(boxed_best_both=True, boxed_margin=margin)
    keep = changed & (gain > margin)
    assert 0 < keep.sum() < changed.sum()
    np.testing.assert_array_equal(mid.heading_change[keep], both.heading_change[keep])
    np.testing.assert_array_equal(mid.heading_change[~keep], base.heading_change[~keep])


def test_boxed_margin_decides_the_head_on_case():
    """The head-on case of boxed_best_both: the left pick beats the right side's best by a
    gain g of as-flown ratio; a margin below g still flies left, one above g keeps the
    committed right side's best (fresh:ao's pick)."""
    scene = _head_on(8000.0, 500.0)

    def pick(**kw):
        out = _policy_pick(FlownBandsResolver.Params(**AO, **kw), scene)[0]
        assert (out.first_clear[0, :2] < 0).all()
        b = out.best_blocked[0, 0]
        return out.candidates[0, b], out.min_ratio[0, b]

    psi_ao, ratio_ao = pick()
    psi_bb, ratio_bb = pick(boxed_best_both=True)
    gain = ratio_bb - ratio_ao
    assert psi_ao <= 0.0 < psi_bb and gain > 0.0
    assert pick(boxed_best_both=True, boxed_margin=0.5 * gain)[0] == psi_bb
    assert pick(boxed_best_both=True, boxed_margin=1.5 * gain)[0] == psi_ao


def test_boxed_horizon_at_the_lookahead_is_boxed_best_both():
    """boxed_horizon_s equal to the look-ahead ranks by the same as-flown ratio (capped at 1,
    and a boxed row has none clear), so the output is boxed_best_both's, array for array."""
    vo, r, v, valid, mx = _random_scene(7, n=400, k=8)
    n = vo.shape[0]
    rate, kept = np.full(n, RATE), _committed_sides(n)

    def run(**kw):
        params = FlownBandsResolver.Params(boxed_best_both=True, boxed_margin=0.1, **AO, **kw)
        return FlownBandsResolver(params).resolve(
            vo, r, v, valid, mx, turn_rate=rate, committed_side=kept
        )

    plain, same = run(), run(boxed_horizon_s=120.0)
    for name in ("heading_change", "conflict", "first_clear", "best_blocked", "min_ratio"):
        np.testing.assert_array_equal(getattr(same, name), getattr(plain, name))


def _boxed_pick(short, full, own, guard, margin, tol=1e-9):
    """The candidate a boxed row flies, one row at a time: among the candidates whose full
    ratio ``full`` (C,) is at least (1 - guard) times the incumbent ``own``'s, the one of
    largest full ratio among those of largest short-horizon ratio ``short`` (C,), if it beats
    the incumbent by more than ``margin`` over the short horizon (or ties there and beats over
    the look-ahead); else ``own``."""
    key = np.where(full >= (1.0 - guard) * full[own], short, -np.inf)
    top = int(np.argmax(np.where(key >= key.max() - tol, full, -np.inf)))
    beats = short[top] > short[own] + margin or (
        short[top] >= short[own] - tol and full[top] > full[own] + margin
    )
    return top if beats else own


@pytest.mark.parametrize("seed", [7, 11])
def test_boxed_horizon_ranks_by_the_short_horizon_first(seed):
    """boxed_horizon_s = H: a committed ownship boxed on both sides flies the candidate of
    largest full as-flown ratio among those of largest as-flown ratio over H (capped at 1,
    from an independent cpa_min_ratio_turning call over every row), counting only
    candidates whose full ratio is at least (1 - guard) times the committed side's best, when it
    beats the committed side's best over H, or ties over H and beats over the look-ahead,
    by more than the margin; every other row is boxed_best_both's."""
    H, margin, guard = 20.0, 0.05, 0.2
    vo, r, v, valid, mx = _random_scene(seed, n=400, k=8)
    n = vo.shape[0]
    rate, kept = np.full(n, RATE), _committed_sides(n)

    def run(**kw):
        params = FlownBandsResolver.Params(boxed_best_both=True, boxed_margin=margin, **AO, **kw)
        return FlownBandsResolver(params).resolve(
            vo, r, v, valid, mx, turn_rate=rate, committed_side=kept
        )

    plain, out = run(), run(boxed_horizon_s=H, boxed_horizon_guard=guard)
    np.testing.assert_array_equal(out.first_clear, plain.first_clear)
    np.testing.assert_array_equal(out.min_ratio, plain.min_ratio)
    usable = ~np.isnan(plain.candidates)
    safe = np.where(usable, plain.candidates, 0.0)
    short = np.minimum(cpa_min_ratio_turning(vo, r, v, valid, safe, 3300.0, H, rate), 1.0)
    short = np.where(usable, short, -np.inf)
    full = np.where(usable, plain.min_ratio, -np.inf)
    boxed = (plain.first_clear[:, 0] < 0) & (plain.first_clear[:, 1] < 0) & (kept != 0)
    expected = plain.heading_change.copy()
    # the committed side's own best is fresh:ao's (before any both-sides swap)
    own_best = (
        FlownBandsResolver(FlownBandsResolver.Params(**AO))
        .resolve(vo, r, v, valid, mx, turn_rate=rate, committed_side=kept)
        .best_blocked
    )
    for i in np.flatnonzero(boxed):
        own = own_best[i, 0 if kept[i] < 0 else 1]
        assert own >= 0
        expected[i] = plain.candidates[i, _boxed_pick(short[i], full[i], own, guard, margin)]
    np.testing.assert_array_equal(out.heading_change, expected)
    changed = out.heading_change != plain.heading_change
    assert changed.sum() >= 3
    assert boxed[changed].all()
    # the guard leaves candidates out: without it some row flies another heading
    unguarded = run(boxed_horizon_s=H, boxed_horizon_guard=1.0)
    assert (unguarded.heading_change != out.heading_change).any()


def test_boxed_horizon_clears_the_imminent_intruder_first():
    """Ownship east committed right, intruder A head-on 8 km ahead and 500 m to the right
    (~17 s to the crossing), intruder B 10 km ahead and 6 km to the left heading south-west:
    boxed on both sides as flown. Over the look-ahead the right side's best (−30°) beats the
    left side's (B crosses a left turn later), so boxed_best_both keeps right; over 20 s
    only A counts and a left turn opens its miss by far, so boxed_horizon_s = 20 turns left."""
    vo = np.array([[230.0, 0.0]])
    vb = 230.0 * np.array([math.cos(math.radians(-135.0)), math.sin(math.radians(-135.0))])
    r = np.array([[[8000.0, -500.0], [10000.0, 6000.0]]])
    v = np.array([[[-460.0, 0.0], vb - vo[0]]])
    scene = (
        vo,
        r,
        v,
        np.ones((1, 2), bool),
        np.array([math.radians(30.0)]),
        np.array([RATE]),
        np.array([-1.0]),
    )
    picks = {}
    for H in (0.0, 20.0):
        params = FlownBandsResolver.Params(
            boxed_best_both=True, boxed_margin=0.1, boxed_horizon_s=H, **AO
        )
        out, psi, side = _policy_pick(params, scene)
        assert (out.first_clear[0, :2] < 0).all() and side[0] == -1.0
        picks[H] = psi[0]
    assert picks[0.0] <= 0.0 < picks[20.0]
    pair = np.array([[picks[0.0], picks[20.0]]])
    rate = np.array([RATE])
    over_h = cpa_min_ratio_turning(vo, r, v, scene[3], pair, 3300.0, 20.0, rate)[0]
    over_t = cpa_min_ratio_turning(vo, r, v, scene[3], pair, 3300.0, 120.0, rate)[0]
    assert over_h[1] > over_h[0] + 0.1  # the left turn clears A further within 20 s
    assert over_t[0] > over_t[1]  # but over the look-ahead the right one is better


@pytest.mark.slow
def test_dense_random_default_loses_fewer_pairs_than_bands():
    """scenarios/dense_random.toml's resolver (bands-flown with the boxed fallbacks and the
    crossing order of intents) against plain bands at margin 0.1 on the same seeds 0-3:
    fewer than half the losses of separation, and no NMAC."""
    from airspace_sim.scenarios import load
    from airspace_sim.world import World

    los = {}
    shipped = load("dense_random")
    assert shipped.resolver.kind == "bands-flown-intent"
    assert shipped.resolver.params["priority_by_crossing"]
    bands = load("dense_random", ['resolver.kind="bands"', "resolver.margin=0.1"])
    for name, sc in (("shipped", shipped), ("bands", bands)):
        runs = [World(sc, seed=s).run() for s in range(4)]
        assert all(m["nmac_pairs"] == 0 for m in runs), name
        los[name] = sum(m["los_pairs"] for m in runs)
    assert los["shipped"] < los["bands"] / 2, los


@pytest.mark.parametrize("seed", [0, 1])
def test_boxed_horizon_keeps_a_tight_ring_clear(seed):
    """8 aircraft on a 9 km ring (all meet in the centre 39 s in): everyone is boxed at once,
    and flying on ahead is clear for 20 s but then at a ratio near 0. Ranked over 20 s with
    no guard on the full ratio, that pick lost 3-4 pairs on these seeds."""
    from airspace_sim.scenarios import load
    from airspace_sim.world import World

    sc = load(
        "ring",
        [
            "traffic.count=8",
            "traffic.radius=9000.0",
            "duration=90.0",
            "resolver.params.boxed_horizon_s=20.0",
        ],
    )
    m = World(sc, seed=seed).run()
    assert m["los_pairs"] == 0 and m["nmac_pairs"] == 0, m


def test_held_candidate_is_the_nearest_usable_candidate_within_tolerance():
    from airspace_sim.avoidance.flown_bands import held_candidate

    cand = np.array([[0.0, -0.1, 0.1, -0.2, np.nan], [0.0, -0.1, 0.1, np.nan, np.nan]] * 2)
    usable = ~np.isnan(cand)
    held = np.array([0.09, -0.25, np.nan, 0.3])
    # rows 1 and 3 have no -0.2: their nearest (-0.1, 0.1) are 0.15 and 0.2 away
    np.testing.assert_array_equal(held_candidate(cand, usable, held, 0.06), [2, -1, -1, -1])
    np.testing.assert_array_equal(held_candidate(cand, usable, held, 0.25), [2, 1, -1, 2])


@pytest.mark.parametrize("seed, hold_margin", [(3, 0.2), (4, 0.05)])
def test_boxed_hold_heading_measures_gains_against_the_held_heading(seed, hold_margin):
    """boxed_hold_heading: a committed ownship boxed on both sides keeps the candidate it was
    advised (``held_heading_change``) unless the top-ranked candidate (over 20 s first, then
    over the look-ahead, from an independent cpa_min_ratio_turning call) beats it by more
    than boxed_hold_margin; rows without a held heading, and rows not boxed, are the rule
    without it."""
    H, margin, guard = 20.0, 0.1, 0.7
    vo, r, v, valid, mx = _random_scene(seed, n=400, k=8)
    n = vo.shape[0]
    rate, kept = np.full(n, RATE), _committed_sides(n)
    base = dict(boxed_best_both=True, boxed_margin=margin, boxed_horizon_s=H, **AO)
    base["boxed_horizon_guard"] = guard
    plain = FlownBandsResolver(FlownBandsResolver.Params(**base)).resolve(
        vo, r, v, valid, mx, turn_rate=rate, committed_side=kept
    )
    usable = ~np.isnan(plain.candidates)
    rng = np.random.default_rng(seed)
    held_idx = np.array([rng.choice(np.flatnonzero(u)) for u in usable])
    held_idx[np.arange(n) % 4 == 0] = -1
    held = np.where(held_idx >= 0, plain.candidates[np.arange(n), np.maximum(held_idx, 0)], np.nan)
    params = FlownBandsResolver.Params(
        boxed_hold_heading=True, boxed_hold_margin=hold_margin, **base
    )
    out = FlownBandsResolver(params).resolve(
        vo, r, v, valid, mx, turn_rate=rate, committed_side=kept, held_heading_change=held
    )
    np.testing.assert_array_equal(out.first_clear, plain.first_clear)
    safe = np.where(usable, plain.candidates, 0.0)
    short = np.minimum(cpa_min_ratio_turning(vo, r, v, valid, safe, 3300.0, H, rate), 1.0)
    short = np.where(usable, short, -np.inf)
    full = np.where(usable, plain.min_ratio, -np.inf)
    boxed = (plain.first_clear[:, 0] < 0) & (plain.first_clear[:, 1] < 0) & (kept != 0)
    expected = plain.heading_change.copy()
    for i in np.flatnonzero(boxed & (held_idx >= 0)):
        pick = _boxed_pick(short[i], full[i], held_idx[i], guard, hold_margin)
        expected[i] = plain.candidates[i, pick]
    np.testing.assert_array_equal(out.heading_change, expected)
    changed = out.heading_change != plain.heading_change
    assert changed.sum() >= 3
    assert (boxed & (held_idx >= 0))[changed].all()


def test_policy_holds_the_advised_heading_and_hands_it_back():
    """The CDA policy owns the held heading: after each detection it is the heading the
    ownship in conflict was advised to reach (its advice is that minus the current heading,
    clipped to the turn limit), NaN elsewhere; at the next detection the resolver receives it
    minus the new heading, wrapped."""
    from airspace_sim.geometry import wrap_angle
    from airspace_sim.scenarios import load
    from airspace_sim.world import World

    sc = load(
        "ring",
        ["traffic.count=8", "traffic.radius=9000.0", "resolver.params.boxed_hold_heading=true"],
    )
    world = World(sc, seed=0)
    policy, given = world.policy, []
    resolve = policy.resolver.resolve
    # every gathered ownship reaches the resolver (the prefilter only saves work)
    policy.resolver.prefilter = False

    def spy(*args, **kw):
        given.append(kw["held_heading_change"].copy())
        return resolve(*args, **kw)

    policy.resolver.resolve = spy
    handed_back = 0
    for _ in range(40):
        before = policy.held_heading.copy()
        given.clear()
        world.step()
        held, conflict = policy.held_heading, policy.conflict
        assert np.isnan(held[~conflict]).all() and np.isfinite(held[conflict]).all()
        heading = np.arctan2(world.velocities[:, 1], world.velocities[:, 0])
        mx = world.max_turn_rate * world.dt
        np.testing.assert_allclose(
            np.clip(wrap_angle(held - heading), -mx, mx)[conflict],
            policy.advice[conflict],
            atol=1e-12,
        )
        if given:
            owners = policy._encounters.owners
            np.testing.assert_allclose(
                given[0], wrap_angle(before[owners] - heading[owners]), atol=1e-12
            )
            handed_back += int(np.isfinite(given[0]).sum())
    assert handed_back > 20


def test_policy_unpickles_a_checkpoint_from_before_the_held_heading():
    from airspace_sim.scenarios import load
    from airspace_sim.world import World
    from airspace_sim.world.policy import AvoidancePolicy

    world = World(load("ring"), seed=0)
    state = dict(world.policy.__dict__)
    del state["held_heading"]
    policy = AvoidancePolicy.__new__(AvoidancePolicy)
    policy.__setstate__(state)
    assert policy.held_heading.shape == (world.n,) and np.isnan(policy.held_heading).all()


class _SlotRadius(FlownBandsResolver):
    """A clear radius per slot through the ``clear_radius`` hook: ``scale`` times the padded
    radius on every slot."""

    scale = 1.0

    def clear_radius(self, vo, r, v, valid):
        p = self.params
        return np.full(valid.shape, self.scale * p.r_safe * (1.0 + p.margin))


@pytest.mark.parametrize("scale", [1.0, 1.5])
def test_a_clear_radius_per_slot_is_the_scalar_radius_it_equals(scale):
    """An (N, K) clear radius from the hook gives the output of the scalar radius of the same
    value (r_safe scaled), on every path of the search (as flown, boxed fallbacks)."""
    vo, r, v, valid, mx = _random_scene(5, n=200, k=6)
    n = vo.shape[0]
    kept = _committed_sides(n)
    knobs = dict(AO, boxed_best_both=True, boxed_horizon_s=20.0)
    hooked = _SlotRadius(FlownBandsResolver.Params(**knobs))
    hooked.scale = scale
    plain = FlownBandsResolver(FlownBandsResolver.Params(r_safe=3000.0 * scale, **knobs))
    rate = np.full(n, RATE)
    a = hooked.resolve(vo, r, v, valid, mx, turn_rate=rate, committed_side=kept)
    b = plain.resolve(vo, r, v, valid, mx, turn_rate=rate, committed_side=kept)
    for field in ("heading_change", "conflict", "first_clear", "best_blocked"):
        np.testing.assert_array_equal(getattr(a, field), getattr(b, field))
    np.testing.assert_allclose(a.min_ratio, b.min_ratio, rtol=1e-12)
