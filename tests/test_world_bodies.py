"""The pymunk side of the world: collision handlers and spatial surveillance against brute force."""

import numpy as np
import pytest

from airspace_sim.scenarios.schema import (
    AircraftSpec,
    ResolverSpec,
    Scenario,
    SensorSpec,
    Separation,
    TrackerSpec,
)
from airspace_sim.world import World
from airspace_sim.world.bodies import (
    LOS,
    NMAC,
    RANGE,
    SETS,
    Airspace,
    _delete_sorted,
    _insert_sorted,
    _kinematic_step,
)


def busy_scenario(n=30, side=30000.0, seed=3, nmac=1000.0, sensor_range=8000.0):
    """Markov pilots in a small square, no avoidance: many LoS, NMACs and range changes."""
    rng = np.random.default_rng(seed)
    aircraft = [
        AircraftSpec(
            id=f"M{i}",
            position=tuple(rng.uniform(-side / 2, side / 2, 2)),
            heading_deg=float(rng.uniform(0, 360)),
            speed=float(rng.uniform(150, 250)),
            autopilot="markov",
        )
        for i in range(n)
    ]
    return Scenario(
        name="busy",
        seed=seed,
        dt=1.0,
        duration=120.0,
        separation=Separation(r_safe=3000.0, nmac=nmac),
        sensor=SensorSpec(range=sensor_range, sigma=50.0),
        tracker=TrackerSpec(kind="truth"),
        resolver=ResolverSpec(kind="none"),
        aircraft=aircraft,
    )


def brute_pairs(pos, radius, active=None):
    d = np.hypot(*(pos[:, None, :] - pos[None, :, :]).transpose(2, 0, 1))
    i, j = np.nonzero(np.triu(d < radius, k=1))
    if active is not None:
        keep = active[i] & active[j]
        i, j = i[keep], j[keep]
    return set(zip(i.tolist(), j.tolist()))


def world_pairs(world, kind):
    i, j = world.airspace.pair_arrays(kind)
    return set(zip(i.tolist(), j.tolist()))


def test_los_nmac_and_range_equal_brute_force_every_step():
    world = World(busy_scenario())
    seen = {LOS: 0, NMAC: 0, RANGE: 0}
    changes = 0
    prev = None
    for _ in range(120):
        world.step()
        pos = world.positions
        for kind, radius in ((LOS, 3000.0), (NMAC, 1000.0), (RANGE, 8000.0)):
            expected = brute_pairs(pos, radius)
            assert world_pairs(world, kind) == expected, (kind, world.time)
            seen[kind] += len(expected)
        # per-aircraft flags agree too
        los = brute_pairs(pos, 3000.0)
        flag = np.zeros(world.n, bool)
        for i, j in los:
            flag[i] = flag[j] = True
        assert np.array_equal(world.in_los, flag)
        cur = world_pairs(world, RANGE)
        changes += prev is not None and cur != prev
        prev = cur
    # the run really exercised all three sets and their begin/separate events
    assert seen[LOS] > 0 and seen[NMAC] > 0 and seen[RANGE] > seen[LOS]
    assert changes > 10
    m = world.metrics()
    assert m["los_events"] > 0 and m["nmac_events"] > 0


def test_los_episodes_counted_from_begin_events():
    world = World(busy_scenario(seed=5))
    episodes = 0
    prev = world_pairs(world, LOS)
    episodes += len(prev)
    for _ in range(120):
        world.step()
        cur = brute_pairs(world.positions, 3000.0)
        episodes += len(cur - prev)
        prev = cur
    assert world.metrics()["los_events"] == episodes > 0


def test_boundary_is_strict():
    # two aircraft exactly r_safe apart are not in LoS; a hair closer they are
    sp = Airspace(
        np.array([[0.0, 0.0], [3000.0, 0.0], [0.0, 10000.0], [2999.999, 10000.0]]),
        r_safe=3000.0,
        nmac=152.4,
        sensor_range=40000.0,
    )
    assert set(zip(*[a.tolist() for a in sp.pair_arrays(LOS)])) == {(2, 3)}


def test_removed_aircraft_leave_all_pairs():
    sp = Airspace(
        np.array([[0.0, 0.0], [100.0, 0.0], [200.0, 0.0]]),
        r_safe=3000.0,
        nmac=152.4,
        sensor_range=40000.0,
    )
    assert len(sp.pairs[LOS]) == 3 and len(sp.pairs[NMAC]) == 2
    sp.remove([1])
    assert sp.pair_arrays(LOS)[0].tolist() == [0] and sp.pair_arrays(LOS)[1].tolist() == [2]
    assert len(sp.pairs[NMAC]) == 0
    pos = np.zeros((3, 2))
    sp.set_velocities(np.array([[10.0, 0.0], [0.0, 0.0], [-10.0, 0.0]]))
    sp.step(1.0, pos)
    assert pos[0].tolist() == [10.0, 0.0] and pos[2].tolist() == [190.0, 0.0]


@pytest.mark.parametrize("n", [1, 2])
def test_tiny_worlds(n):
    sc = busy_scenario(n=n)
    world = World(sc)
    world.run(5)
    assert world.step_count == 5


# --------------------------------------------------------------------------- pickling


def _copies(sp):
    import copy
    import pickle

    return [pickle.loads(pickle.dumps(sp)), copy.deepcopy(sp)]


def _state(sp, pos):
    """Everything an airspace step produces: positions (bytes), pair sets, begun pairs."""
    return (
        pos.tobytes(),
        {t: sp.pairs[t].tolist() for t in (LOS, NMAC, RANGE)},
        {t: sp.began[t].tolist() for t in (LOS, NMAC, RANGE)},
    )


def airspace_pairs(sp, kind):
    i, j = sp.pair_arrays(kind)
    return set(zip(i.tolist(), j.tolist()))


def test_copy_taken_while_pairs_overlap_fires_separate_and_no_second_begin():
    # Aircraft 0 and 1 overlap in all three sets when copied; 1 flies away east at 500 m/s,
    # leaving NMAC (1000 m) after 1 s, LoS (3000 m) after 5 s, range (8000 m) after 15 s,
    # turns round at 20 s and comes back, so every set separates and begins again.
    # Aircraft 2 was removed before the copy. Oracles: brute-force distances every step,
    # and the original stepped with the same velocities.
    start = np.array([[0.0, 0.0], [500.0, 0.0], [100.0, 100.0], [0.0, 30000.0]])
    sp = Airspace(start, r_safe=3000.0, nmac=1000.0, sensor_range=8000.0)
    sp.remove([2])
    assert [len(sp.pairs[t]) for t in (LOS, NMAC, RANGE)] == [1, 1, 1]
    copies = _copies(sp)
    pos = [start.copy() for _ in range(3)]
    separated, began = set(), set()
    for k in range(60):
        v = np.zeros((4, 2))
        v[1] = (500.0, 0.0) if k < 20 else (-500.0, 0.0)
        for s, p in zip([sp, *copies], pos):
            s.set_velocities(v)
            s.step(1.0, p)
        for t, r in ((LOS, 3000.0), (NMAC, 1000.0), (RANGE, 8000.0)):
            expected = brute_pairs(pos[0], r, active=sp.in_space)
            assert airspace_pairs(sp, t) == expected, (t, k)
            if not expected:
                separated.add(t)
            elif sp.began[t].size:
                began.add(t)
            if k < 20:  # going away: nothing begins (a copy without arbiters would begin)
                assert sp.began[t].size == 0
        for s, p in zip(copies, pos[1:]):
            assert _state(s, p) == _state(sp, pos[0]), k
    assert separated == began == {LOS, NMAC, RANGE}


@pytest.mark.parametrize("spatial_hash, margin", [(False, None), (True, None), (False, 3000.0)])
def test_copies_of_a_busy_airspace_step_identically(spatial_hash, margin):
    # 40 aircraft at 200 m/s turning at random in a 30 km square: pairs begin and end all
    # the time. The airspace is copied after 20 steps, then all are stepped 80 more with the
    # same velocities; one aircraft is removed on the way.
    rng = np.random.default_rng(7)
    n = 40
    pos0 = rng.uniform(-15000.0, 15000.0, (n, 2))
    heading = rng.uniform(-np.pi, np.pi, n)
    sp = Airspace(pos0, 3000.0, 1000.0, 8000.0, spatial_hash=spatial_hash, margin=margin)
    pos = pos0.copy()

    def velocities():
        heading[:] += rng.normal(0.0, 0.2, n)
        return 200.0 * np.stack([np.cos(heading), np.sin(heading)], axis=1)

    for _ in range(20):
        sp.set_velocities(velocities())
        sp.step(1.0, pos)
    copies = _copies(sp)
    assert all(c.spatial_hash == spatial_hash for c in copies)
    cpos = [pos.copy() for _ in copies]
    events = 0
    for k in range(80):
        v = velocities()
        if k == 30:
            for s in [sp, *copies]:
                s.remove([5])
        for s, p in zip([sp, *copies], [pos, *cpos]):
            s.set_velocities(v)
            s.step(1.0, p)
        for s, p in zip(copies, cpos):
            assert _state(s, p) == _state(sp, pos), k
        assert airspace_pairs(sp, LOS) == brute_pairs(pos, 3000.0, active=sp.in_space)
        events += sum(sp.began[t].shape[0] for t in (LOS, NMAC, RANGE))
    assert events > 20


def test_unpickling_checks_the_rebuilt_contacts_against_the_stored_pairs():
    sp = Airspace(np.array([[0.0, 0.0], [100.0, 0.0]]), 3000.0, 1000.0, 8000.0)
    state = sp.__getstate__()
    state["pairs"][LOS] = np.zeros(0, np.int64)  # claims no LoS although they overlap
    broken = Airspace.__new__(Airspace)
    with pytest.raises(RuntimeError, match="set 1 differ from the stored pairs"):
        broken.__setstate__(state)


# ----------------------------------------------------------------- busy random traffic


def _random_flight(n, side, seed, steps, speed=230.0, turn_sigma=0.1):
    """Positions (N, 2) m and a generator of (N, 2) m/s velocities of aircraft turning at
    random in a square of side ``side`` m."""
    rng = np.random.default_rng(seed)
    pos0 = rng.uniform(-side / 2, side / 2, (n, 2))
    heading = rng.uniform(-np.pi, np.pi, n)

    def velocities():
        for _ in range(steps):
            heading[:] += rng.normal(0.0, turn_sigma, n)
            yield speed * np.stack([np.cos(heading), np.sin(heading)], axis=1)

    return pos0, velocities()


@pytest.mark.parametrize(
    "spatial_hash, margin", [(False, None), (True, None), (False, 0.0), (False, 15000.0)]
)
def test_busy_random_traffic_pairs_and_begin_events_equal_brute_force(spatial_hash, margin):
    # 300 aircraft, one per 30 km² (3x the benchmark's density), 20 km range circles
    # (~1300 range pairs), 2 s steps at 230 m/s: every step many range pairs begin and
    # end, and several LoS / NMAC pairs. Oracle: brute-force distances; the begun pairs of
    # a step are exactly the brute-force pairs that were not there the step before, the
    # ended ones those that were there and are not now (pair sets equal every step). The
    # candidates are found again every step (margin 0), every fifth step (default) or
    # every 17 steps (15 km).
    n, side = 300, 95000.0
    radii = {LOS: 3000.0, NMAC: 1000.0, RANGE: 20000.0}
    pos, velocities = _random_flight(n, side, seed=11, steps=60)
    sp = Airspace(
        pos, radii[LOS], radii[NMAC], radii[RANGE], spatial_hash=spatial_hash, margin=margin
    )
    prev = {t: brute_pairs(pos, r) for t, r in radii.items()}
    for t in SETS:
        assert airspace_pairs(sp, t) == prev[t]
        assert set(map(tuple, sp.began[t].tolist())) == prev[t]  # all begin at the start
    began_total = {t: 0 for t in SETS}
    ended_total = {t: 0 for t in SETS}
    pos = pos.copy()
    for k, v in enumerate(velocities):
        if k == 25:
            sp.remove([3, 150])
        sp.set_velocities(v)
        sp.step(2.0, pos)
        for t, r in radii.items():
            now = brute_pairs(pos, r, active=sp.in_space)
            assert airspace_pairs(sp, t) == now, (t, k)
            began = sp.began[t]
            assert list(map(tuple, began.tolist())) == sorted(now - prev[t]), (t, k)  # sorted
            if k != 25:  # the removal's ends are not in the step's difference
                began_total[t] += len(now - prev[t])
                ended_total[t] += len(prev[t] - now)
            prev[t] = now
    assert min(began_total[t] for t in SETS) > 0 and min(ended_total[t] for t in SETS) > 0
    # the airspace's positions are the ones handed out; the candidates were found again
    assert sp.positions[sp.in_space].tobytes() == pos[sp.in_space].tobytes()
    expected_refreshes = {None: 12, 0.0: 60, 15000.0: 3}[margin]
    assert sp.refreshes == expected_refreshes
    assert began_total[RANGE] > 500 and ended_total[RANGE] > 500


def test_pairs_overlapping_at_the_start_separate_at_the_first_step():
    # The begin handler is installed after the priming step: the arbiters created there
    # must still report their separation at the very next step, in the original and in a
    # copy made before any step.
    start = np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 50000.0]])
    sp = Airspace(start, r_safe=3000.0, nmac=1000.0, sensor_range=8000.0)
    assert [len(sp.pairs[t]) for t in SETS] == [1, 1, 1]
    assert all(sp.began[t].tolist() == [[0, 1]] for t in SETS)
    for s in [sp, *_copies(sp)]:
        pos = start.copy()
        s.set_velocities(np.array([[0.0, 0.0], [20000.0, 0.0], [0.0, 0.0]]))
        s.step(1.0, pos)
        assert [len(s.pairs[t]) for t in SETS] == [0, 0, 0]
        assert all(s.began[t].size == 0 for t in SETS)
        s.set_velocities(np.array([[0.0, 0.0], [-20000.0, 0.0], [0.0, 0.0]]))
        s.step(1.0, pos)  # back where it started: every set begins again, once
        assert all(s.began[t].tolist() == [[0, 1]] for t in SETS)


def test_sorted_key_updates_equal_numpy_set_operations():
    rng = np.random.default_rng(2)
    for _ in range(300):
        keys = np.unique(rng.integers(0, 200, rng.integers(0, 60)))
        new = np.unique(rng.integers(0, 200, rng.integers(0, 10)))
        gone = rng.integers(0, 200, rng.integers(0, 10))  # unsorted, repeats, absent keys
        assert np.array_equal(_insert_sorted(keys, new), np.union1d(keys, new))
        assert np.array_equal(_delete_sorted(keys, gone), keys[~np.isin(keys, gone)])


def test_arbiter_bodies_map_to_aircraft_with_and_without_the_id_map():
    # the id map (a KeyMap of pymunk body ids) against the sorted-ids binary search it
    # replaced, and the candidates found through either against brute force (overlapping
    # candidate circles, radius (R + margin)/2)
    rng = np.random.default_rng(2)
    pos = rng.uniform(0.0, 60000.0, (80, 2))
    sp = Airspace(pos, 3000.0, 1000.0, 10000.0)
    ids = np.array([b.id for b in sp.bodies], dtype=np.uintp)[rng.permutation(80)]
    via_map = sp._aircraft_of(ids)
    sp._id_map = None
    np.testing.assert_array_equal(via_map, sp._aircraft_of(ids))
    np.testing.assert_array_equal(via_map, [sp.bodies.index(b) for b in _by_id(sp, ids)])
    reach = 10000.0 + sp.margin
    d = np.hypot(*(pos[:, None, :] - pos[None, :, :]).transpose(2, 0, 1))
    i, j = np.nonzero(np.triu(d < reach, 1))
    np.testing.assert_array_equal(sp._candidates, np.sort(i * 80 + j))  # through the map
    np.testing.assert_array_equal(sp._arbiter_keys(), np.sort(i * 80 + j))


def _by_id(sp, ids):
    bodies = {b.id: b for b in sp.bodies}
    return [bodies[int(x)] for x in ids]


@pytest.mark.parametrize("case", ["all", "some", "none", "nan"])
def test_kinematic_step_equals_the_numpy_update(case):
    """``_kinematic_step`` moves the live rows as ``positions[live] += v[live]·dt`` and
    returns numpy's ``max(sqrt((v·v).sum(axis=1)))`` over them (NaN kept; −1 if none)."""
    rng = np.random.default_rng(7)
    n, dt = 50, 1.0 / 3.0
    pos = rng.uniform(-1e5, 1e5, (n, 2))
    vel = rng.uniform(-300, 300, (n, 2))
    live = {"all": np.ones(n, bool), "some": rng.random(n) < 0.5, "none": np.zeros(n, bool)}
    live = live.get(case, np.ones(n, bool))
    if case == "nan":
        vel[3, 1] = np.nan
    ref_pos, ref_out = pos.copy(), np.zeros((n, 2))
    if live.any():
        v = vel[live]
        ref_pos[live] += v * dt
        ref_fast = float(np.sqrt((v * v).sum(axis=1)).max())
        ref_out[live] = ref_pos[live]
    else:
        ref_fast = -1.0
    out = np.zeros((n, 2))
    fast = _kinematic_step(pos, vel, live, dt, out)
    np.testing.assert_array_equal(pos, ref_pos)
    np.testing.assert_array_equal(out, ref_out)
    assert fast == ref_fast or (np.isnan(fast) and np.isnan(ref_fast))
