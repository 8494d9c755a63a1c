"""Intent-based band search ("bands-flown-intent", avoidance/intent_bands.py): intruders
predicted along the heading they broadcast they steer to, judged against a brute-force
oracle, and the CDA policy's intents and what it hands the resolver."""

import math

import numpy as np
import pytest
from _flight import K1, arc_path

from airspace_sim import registry
from airspace_sim.avoidance.flown_bands import FlownBandsResolver
from airspace_sim.avoidance.intent_bands import (
    IntentFlownBandsResolver,
    crossing_times,
    intent_turns,
)
from airspace_sim.geometry import wrap_angle

RATE = math.radians(3.0)
RADIUS = 3300.0


def test_registered():
    assert registry.get("resolver", "bands-flown-intent") is IntentFlownBandsResolver
    assert IntentFlownBandsResolver.uses_intruder_intent
    assert not FlownBandsResolver.uses_intruder_intent
    # the conflict test stays the straight one: the world's prefilter holds
    assert IntentFlownBandsResolver.prefilter


def test_intent_turns():
    intent = np.array([[0.3, -0.6, np.nan, 0.2, 0.0]])
    limit = np.array([[RATE, RATE / 2, RATE, np.inf, RATE]])
    omega, turn_s = intent_turns(intent, limit)
    np.testing.assert_allclose(omega[0], [RATE, -RATE / 2, 0.0, 0.0, 0.0])
    np.testing.assert_allclose(turn_s[0], [0.3 / RATE, 0.6 / (RATE / 2), 0.0, 0.0, 0.0])


def _scene(seed, n=30, k=4):
    rng = np.random.default_rng(seed)
    vo = rng.normal(size=(n, 2))
    vo *= rng.uniform(180, 260, (n, 1)) / np.linalg.norm(vo, axis=1, keepdims=True)
    # intruders ahead-ish, converging, so most rows are in conflict
    r = rng.uniform(-9000, 9000, (n, k, 2))
    r = np.where(np.hypot(r[..., :1], r[..., 1:]) < 3500.0, r * 3.0, r)
    vi = -r / np.linalg.norm(r, axis=-1, keepdims=True) * rng.uniform(180, 260, (n, k, 1))
    vi += rng.normal(0, 60, (n, k, 2))
    valid = rng.random((n, k)) < 0.9
    intent = np.radians(rng.uniform(-60, 60, (n, k)))
    intent[rng.random((n, k)) < 0.3] = 0.0
    limit = np.full((n, k), RATE)
    return vo, r, vi - vo[:, None], valid, np.full(n, math.radians(60.0)), intent, limit


def _resolve(cls, scene, intents=True, side=-1.0, **params):
    vo, r, v, valid, mx, intent, limit = scene
    extra = dict(intruder_intent=intent, intruder_turn_limit=limit) if intents else {}
    return cls(cls.Params(**params)).resolve(
        vo,
        r,
        v,
        valid,
        mx,
        turn_rate=np.full(vo.shape[0], RATE),
        committed_side=np.full(vo.shape[0], side),
        **extra,
    )


def _assert_same_output(out, ref):
    for field in ("heading_change", "first_clear", "best_blocked", "min_ratio"):
        np.testing.assert_array_equal(getattr(out, field), getattr(ref, field))


def _assert_is_masked_trust(out, scene, kept):
    """``out`` equals full trust of the intents ``kept`` (the scene's intents, some zeroed:
    predicted straight), and the mask kept some intents and dropped others."""
    vo, r, v, valid, mx, intent, limit = scene
    assert 0 < np.count_nonzero(kept) < np.count_nonzero(intent)
    _assert_same_output(
        out, _resolve(IntentFlownBandsResolver, (vo, r, v, valid, mx, kept, limit), **K1)
    )


def test_without_intents_it_is_bands_flown():
    scene = _scene(0)
    out = _resolve(IntentFlownBandsResolver, scene, intents=False, **K1)
    ref = _resolve(FlownBandsResolver, scene, intents=False, **K1)
    for field in ("heading_change", "conflict", "first_clear", "best_blocked", "min_ratio"):
        np.testing.assert_array_equal(getattr(out, field), getattr(ref, field))


@pytest.mark.parametrize("seed", [1, 2])
def test_candidates_are_judged_against_the_intents_by_a_sampled_oracle(seed):
    """On rows in conflict (the straight test, as bands-flown's), every candidate's ratio is
    the minimum distance with the ownship flying it as flown and each intruder turning to
    its intent at its limit, then straight, both paths sampled every 10 ms."""
    scene = _scene(seed)
    vo, r, v, valid, mx, intent, limit = scene
    out = _resolve(IntentFlownBandsResolver, scene, **K1)
    ref = _resolve(FlownBandsResolver, scene, intents=False, **K1)
    np.testing.assert_array_equal(out.conflict, ref.conflict)
    rows = np.flatnonzero(out.conflict)
    assert rows.size >= 10
    t = np.linspace(0.0, 120.0, 12001)
    omega, turn_s = intent_turns(intent, limit)
    for i in rows[:8]:
        speed, h0 = np.hypot(*vo[i]), math.atan2(vo[i, 1], vo[i, 0])
        cand = out.candidates[i]
        for c in np.flatnonzero(~np.isnan(cand))[::9]:
            psi = cand[c]
            ox, oy = arc_path(speed, h0, math.copysign(RATE, psi), abs(psi) / RATE, t)
            best = np.inf
            for q in np.flatnonzero(valid[i]):
                vi = v[i, q] + vo[i]
                h = math.atan2(vi[1], vi[0])
                ix, iy = arc_path(np.hypot(*vi), h, omega[i, q], turn_s[i, q], t)
                best = min(best, np.hypot(r[i, q, 0] + ix - ox, r[i, q, 1] + iy - oy).min())
            assert out.min_ratio[i, c] == pytest.approx(best / RADIUS, abs=4.0 / RADIUS)


def test_an_intruder_turning_away_frees_the_ownship():
    """Head-on at 16 km closing at 460 m/s, the intruder steering 60° to its right: judged
    straight, flying on is blocked and the ownship turns; with the intent, flying on is clear
    and it keeps its heading (still reporting the straight conflict)."""
    vo = np.array([[230.0, 0.0]])
    r = np.array([[[16000.0, 300.0]]])
    v = np.array([[[-460.0, 0.0]]])
    # the intruder flies west, 300 m north of the ownship's track; 60° to its right is
    # north-west, away from the ownship
    scene = (vo, r, v, np.ones((1, 1), bool), np.array([math.pi / 2]))
    intent = np.array([[-math.radians(60.0)]])
    limit = np.array([[RATE]])
    out = _resolve(IntentFlownBandsResolver, (*scene, intent, limit), **K1)
    ref = _resolve(FlownBandsResolver, (*scene, intent, limit), intents=False, **K1)
    assert out.conflict[0] and ref.conflict[0]
    assert ref.heading_change[0] != 0.0
    assert out.heading_change[0] == 0.0


def test_policy_broadcasts_intents_and_hands_them_over():
    """The CDA policy's intent is the held advised heading of an aircraft following the
    advice in conflict, NaN for aircraft that do not fly the policy; the resolver gets, per
    slot, that intent minus the track's heading (0 where there is none)."""
    from airspace_sim.scenarios import load
    from airspace_sim.world import World

    sc = load(
        "ring",
        ["traffic.count=8", "traffic.radius=9000.0", 'resolver.kind="bands-flown-intent"'],
    )
    world = World(sc, seed=0)
    policy = world.policy
    assert isinstance(policy.resolver, IntentFlownBandsResolver)
    resolve, seen = policy.resolver.resolve, []
    # every gathered ownship reaches the resolver, so the policy's encounters are its rows
    policy.resolver.prefilter = False

    def spy(*args, **kw):
        enc, view = policy._encounters, world.tracks.view()
        ids = np.where(enc.rows >= 0, view.intruder[np.maximum(enc.rows, 0)], -1)
        seen.append((args, kw, policy.intent_heading.copy(), ids, policy.intent_age_s.copy()))
        np.testing.assert_array_equal(kw["own_intent_age_s"], policy.intent_age_s[enc.owners])
        return resolve(*args, **kw)

    policy.resolver.resolve = spy
    followed = handed = 0
    for _ in range(60):
        held, conflict = policy.held_heading.copy(), policy.conflict.copy()
        seen.clear()
        world.step()
        mask = policy.following & conflict
        np.testing.assert_array_equal(policy.intent_heading[mask], held[mask])
        followed += int(mask.sum())
        for args, kw, intent_heading, ids, age in seen:
            np.testing.assert_array_equal(
                kw["intruder_intent_age_s"], np.where(ids >= 0, age[np.maximum(ids, 0)], 0.0)
            )
            vo, rel_v = args[0], args[2]
            vi = rel_v + vo[:, None, :]
            track_heading = np.arctan2(vi[..., 1], vi[..., 0])
            target = np.where(ids >= 0, intent_heading[np.maximum(ids, 0)], np.nan)
            want = np.where(np.isfinite(target), wrap_angle(target - track_heading), 0.0)
            np.testing.assert_allclose(kw["intruder_intent"], want, atol=1e-12)
            np.testing.assert_allclose(kw["intruder_turn_limit"][ids >= 0], RATE, rtol=1e-12)
            handed += int((np.abs(want) > 1e-3).sum())
    assert followed > 20 and handed > 10
    assert world.metrics()["los_pairs"] == 0


def test_intent_share_scales_the_intended_turns():
    """``intent_share = s`` is the full trust of intents scaled by ``s``."""
    vo, r, v, valid, mx, intent, limit = _scene(3)
    scene = (vo, r, v, valid, mx, intent, limit)
    shared = _resolve(IntentFlownBandsResolver, scene, intent_share=0.4, **K1)
    scaled = _resolve(IntentFlownBandsResolver, (vo, r, v, valid, mx, 0.4 * intent, limit), **K1)
    full = _resolve(IntentFlownBandsResolver, scene, **K1)
    finite = np.isfinite(shared.min_ratio)
    # the share matters on this scene
    assert np.abs(shared.min_ratio[finite] - full.min_ratio[finite]).max() > 1e-3
    _assert_same_output(shared, scaled)


def test_priority_uses_only_the_intents_of_lower_indices():
    """Prioritized planning: the intents of intruders of a higher aircraft index than the
    ownship's are ignored (predicted straight), those of lower ones trusted."""
    vo, r, v, valid, mx, intent, limit = _scene(4)
    n, k = valid.shape
    rng = np.random.default_rng(9)
    own = rng.permutation(n) + 5
    ids = rng.integers(0, n + 10, (n, k))
    ids[~valid] = -1
    resolver = IntentFlownBandsResolver(IntentFlownBandsResolver.Params(priority=True, **K1))
    kw = dict(turn_rate=np.full(n, RATE), committed_side=np.full(n, -1.0))
    out = resolver.resolve(vo, r, v, valid, mx, intruder_intent=intent, intruder_turn_limit=limit,
                           aircraft_ids=own, intruder_ids=ids, **kw)  # fmt: skip
    kept = np.where((ids >= 0) & (ids < own[:, None]), intent, 0.0)
    _assert_is_masked_trust(out, (vo, r, v, valid, mx, intent, limit), kept)


def test_intent_min_age_and_max_conflicts_mask_intents():
    """``intent_min_age_s`` uses only intents held that long; ``intent_max_conflicts`` only
    on ownships with that many intruders in conflict at most (the straight test): both are
    the full trust of the intents so masked."""
    from airspace_sim.avoidance.cpa import cpa_pair_ratios

    vo, r, v, valid, mx, intent, limit = _scene(6)
    n = vo.shape[0]
    age = np.random.default_rng(2).uniform(0.0, 20.0, valid.shape)
    resolver = IntentFlownBandsResolver(
        IntentFlownBandsResolver.Params(intent_min_age_s=8.0, intent_max_conflicts=1, **K1)
    )
    kw = dict(turn_rate=np.full(n, RATE), committed_side=np.full(n, -1.0))
    out = resolver.resolve(vo, r, v, valid, mx, intruder_intent=intent, intruder_turn_limit=limit,
                           intruder_intent_age_s=age, **kw)  # fmt: skip
    alone = cpa_pair_ratios(vo, r, v, valid, np.zeros((n, 1)), RADIUS, 120.0)[:, :, 0]
    few = ((alone < 1.0 - 1e-9).sum(axis=1) <= 1)[:, None]
    kept = np.where((age >= 8.0) & few, intent, 0.0)
    _assert_is_masked_trust(out, (vo, r, v, valid, mx, intent, limit), kept)


def test_policy_intent_age_counts_seconds_the_intent_held():
    from airspace_sim.scenarios import load
    from airspace_sim.world import World

    sc = load("ring", ["traffic.count=8", "traffic.radius=9000.0"])
    world = World(sc, seed=0)
    policy = world.policy
    grew = reset = 0
    for _ in range(60):
        before, age = policy.intent_heading.copy(), policy.intent_age_s.copy()
        world.step()
        same = np.abs(wrap_angle(policy.intent_heading - before)) <= math.radians(1.0)
        np.testing.assert_array_equal(policy.intent_age_s[same], age[same] + world.dt)
        np.testing.assert_array_equal(policy.intent_age_s[~same], 0.0)
        grew += int(same.sum())
        reset += int((~same & np.isfinite(policy.intent_heading)).sum())
    assert grew > 50 and reset > 5


def test_priority_by_age_uses_only_intents_older_than_the_ownships():
    """Prioritized planning by who committed first: an intruder's intent is used when it has
    held longer than the ownship's own, or as long and the intruder's index is lower."""
    vo, r, v, valid, mx, intent, limit = _scene(7)
    n, k = valid.shape
    rng = np.random.default_rng(4)
    own = np.arange(n) + 3
    ids = rng.integers(0, n + 6, (n, k))
    ids[~valid] = -1
    age = rng.integers(0, 4, (n, k)).astype(float)  # ties are common
    mine = rng.integers(0, 4, n).astype(float)
    resolver = IntentFlownBandsResolver(IntentFlownBandsResolver.Params(priority_by_age=True, **K1))
    out = resolver.resolve(
        vo, r, v, valid, mx, turn_rate=np.full(n, RATE), committed_side=np.full(n, -1.0),
        intruder_intent=intent, intruder_turn_limit=limit, intruder_intent_age_s=age,
        own_intent_age_s=mine, aircraft_ids=own, intruder_ids=ids,
    )  # fmt: skip
    first = (age > mine[:, None]) | ((age == mine[:, None]) & (ids < own[:, None]))
    kept = np.where((ids >= 0) & first, intent, 0.0)
    _assert_is_masked_trust(out, (vo, r, v, valid, mx, intent, limit), kept)


def test_crossing_times_solve_where_the_straight_tracks_meet():
    """Against each pair's 2x2 system ``vo·t_own = r + vi·t_intruder`` solved on its own;
    tracks within 10° of parallel have no crossing (NaN)."""
    rng = np.random.default_rng(11)
    n, k = 40, 5
    vo = rng.normal(size=(n, 2)) * 200.0
    r = rng.normal(size=(n, k, 2)) * 20000.0
    v = rng.normal(size=(n, k, 2)) * 300.0
    v[0, 0] = 0.0  # same velocity: parallel
    v[1, 0] = -2.0 * vo[1]  # head-on: antiparallel
    t_own, t_intruder = crossing_times(vo, r, v)
    for i in range(n):
        for j in range(k):
            vi = v[i, j] + vo[i]
            angle = abs(math.atan2(vo[i, 0] * vi[1] - vo[i, 1] * vi[0], np.dot(vo[i], vi)))
            if min(angle, math.pi - angle) <= math.radians(10.0):
                assert np.isnan(t_own[i, j]) and np.isnan(t_intruder[i, j])
                continue
            a, b = np.linalg.solve(np.column_stack([vo[i], -vi]), r[i, j])
            np.testing.assert_allclose([t_own[i, j], t_intruder[i, j]], [a, b], rtol=1e-9)
    assert np.isnan(t_own[0, 0]) and np.isnan(t_own[1, 0])
    # seen from the intruder the two times swap: the order has no two-cycles
    vi = v[2, 1] + vo[2]
    back = crossing_times(vi[None], -r[2, 1][None, None], -v[2, 1][None, None])
    np.testing.assert_allclose([back[0][0, 0], back[1][0, 0]], [t_intruder[2, 1], t_own[2, 1]])


def test_priority_by_crossing_uses_only_intents_of_intruders_crossing_first():
    """An intruder's intent counts when it reaches the tracks' crossing at least
    ``crossing_margin_s`` before the ownship; the others (and near-parallel tracks) are
    predicted straight."""
    vo, r, v, valid, mx, intent, limit = _scene(8)
    n = vo.shape[0]
    resolver = IntentFlownBandsResolver(
        IntentFlownBandsResolver.Params(priority_by_crossing=True, crossing_margin_s=3.0, **K1)
    )
    out = resolver.resolve(vo, r, v, valid, mx, turn_rate=np.full(n, RATE),
                           committed_side=np.full(n, -1.0), intruder_intent=intent,
                           intruder_turn_limit=limit)  # fmt: skip
    t_own, t_intruder = crossing_times(vo, r, v)
    kept = np.where(t_own - t_intruder > 3.0, intent, 0.0)
    _assert_is_masked_trust(out, (vo, r, v, valid, mx, intent, limit), kept)
