"""The world's track table over a slot tracker: life cycle, pending detections, slot reuse,
the truth tracker, and the built-in trackers against the Tracker protocol.

Oracles: an independent one-tracker :class:`IMM` per track, started from
:func:`two_point_initialisation` of the same two measurements and fed the same
measurements (NaN when missed): the table's track must equal it bit for bit.
"""

from __future__ import annotations

import numpy as np
import pytest

from airspace_sim import parts, registry
from airspace_sim.dynamics import presets
from airspace_sim.errors import UserError
from airspace_sim.tracking import IMM
from airspace_sim.tracking.initialisation import two_point_initialisation
from airspace_sim.world.trackers import (
    MANOEUVRE_VELOCITY_VAR,
    ImmTracker,
    TrackTable,
    TruthTracker,
    make_tracker,
)

SIGMA, N = 50.0, 4
PRESET = presets.get("realistic", dt=1.0)
OMEGA = np.radians(3.0)


def table(drop_after=2):
    return TrackTable.build(N, "imm", PRESET, SIGMA, drop_after, 1.0)


def reference(z0, z1, dt):
    x0, P0 = two_point_initialisation(
        z0[None], z1[None], dt, SIGMA**2 * np.eye(2), 0.0, OMEGA**2, MANOEUVRE_VELOCITY_VAR
    )
    p = PRESET.with_(measurement_sigma=SIGMA)
    return IMM(**p.imm_arguments(), x0=x0, P0=P0, mu0=p.mu0())


def track(t: TrackTable, owner, intruder):
    v = t.view()
    i = np.flatnonzero((v.owner == owner) & (v.intruder == intruder))
    return None if i.size == 0 else int(i[0])


def test_life_cycle_pending_two_point_misses_reuse_and_dead_aircraft():
    t = table(drop_after=2)
    alive = np.ones(N, dtype=bool)
    rng = np.random.default_rng(0)
    # each pair's intruder flies a straight line (its measurements are inside the gate:
    # a gated measurement counts as a miss)
    start = {k: rng.uniform(-1e4, 1e4, 2) for k in ((0, 1), (0, 2), (1, 3), (3, 0))}
    vel = {k: rng.uniform(-200.0, 200.0, 2) for k in start}

    def z(pair, time):
        return start[pair] + vel[pair] * time + rng.normal(0.0, SIGMA, 2)

    def upd(time, dets, scanned=True, alive=alive):
        o = np.array([d[0] for d in dets], dtype=np.int64)
        i = np.array([d[1] for d in dets], dtype=np.int64)
        zz = np.array([d[2] for d in dets]).reshape(-1, 2)
        t.update(time, scanned, o, i, zz, alive)

    a0, b0 = z((0, 1), 0.0), z((0, 2), 0.0)
    upd(0.0, [(0, 1, a0), (0, 2, b0), (1, 3, z((1, 3), 0.0))])
    assert len(t) == 0 and len(t.view()) == 0  # one detection is not a track yet
    a1 = z((0, 1), 1.0)
    upd(1.0, [(0, 1, a1)])
    assert len(t) == 1
    ref01 = reference(a0, a1, 1.0)
    r = track(t, 0, 1)
    np.testing.assert_array_equal(t.view().x[r], ref01.x[0])
    np.testing.assert_array_equal(t.view().P[r], ref01.P[0])
    slot01 = int(t.view().slots[r])
    # (0, 2): pending since t = 0, detected again 2 s later (within 2 scans): Δt = 2 s
    b2 = z((0, 2), 2.0)
    upd(2.0, [(0, 2, b2)])
    ref01.step(np.full((1, 2), np.nan))
    ref02 = reference(b0, b2, 2.0)
    v = t.view()
    assert v.age[track(t, 0, 1)] == 1 and v.misses[track(t, 0, 1)] == 1
    np.testing.assert_array_equal(v.x[track(t, 0, 1)], ref01.x[0])
    np.testing.assert_array_equal(v.x[track(t, 0, 2)], ref02.x[0])
    slot02 = int(v.slots[track(t, 0, 2)])
    # a step between scans: predicted only, misses unchanged
    upd(2.5, [], scanned=False)
    ref01.step(np.full((1, 2), np.nan))
    ref02.step(np.full((1, 2), np.nan))
    assert t.view().misses[track(t, 0, 1)] == 1
    np.testing.assert_array_equal(t.view().x[track(t, 0, 2)], ref02.x[0])
    # second missed scan: (0, 1) is dropped; (3, 0) detected for the first time
    b3, c3 = z((0, 2), 3.0), z((3, 0), 3.0)
    upd(3.0, [(0, 2, b3), (3, 0, c3)])
    assert track(t, 0, 1) is None and len(t) == 1
    ref02.step(b3[None])
    np.testing.assert_array_equal(t.view().x[track(t, 0, 2)], ref02.x[0])
    # (3, 0) starts in the freed slot; (0, 2) never moved
    c4 = z((3, 0), 4.0)
    upd(4.0, [(3, 0, c4), (0, 2, z((0, 2), 4.0))])
    v = t.view()
    assert int(v.slots[track(t, 3, 0)]) == slot01 and int(v.slots[track(t, 0, 2)]) == slot02
    np.testing.assert_array_equal(v.x[track(t, 3, 0)], reference(c3, c4, 1.0).x[0])
    # (1, 3): pending since t = 0, seen again at t = 5 (too late: 5 s > 2 scans) -> pending
    # again; at t = 6 the track starts from the t = 5 and t = 6 measurements
    d5, d6 = z((1, 3), 5.0), z((1, 3), 6.0)
    upd(5.0, [(1, 3, d5), (3, 0, z((3, 0), 5.0)), (0, 2, z((0, 2), 5.0))])
    assert track(t, 1, 3) is None
    upd(6.0, [(1, 3, d6), (3, 0, z((3, 0), 6.0)), (0, 2, z((0, 2), 6.0))])
    np.testing.assert_array_equal(t.view().x[track(t, 1, 3)], reference(d5, d6, 1.0).x[0])
    # aircraft 2 leaves: its track is dropped at once, the others stay
    gone = alive.copy()
    gone[2] = False
    upd(7.0, [(1, 3, z((1, 3), 7.0)), (3, 0, z((3, 0), 7.0))], alive=gone)
    v = t.view()
    assert sorted(zip(v.owner.tolist(), v.intruder.tolist(), strict=True)) == [(1, 3), (3, 0)]
    assert len(t) == len(v) == 2


def test_view_is_read_only_lazy_and_fixed_until_the_next_update():
    t = table()
    alive = np.ones(N, dtype=bool)
    o, i = np.array([0, 1, 2]), np.array([1, 2, 3])
    for time in (0.0, 1.0):
        t.update(time, True, o, i, np.full((3, 2), 100.0 * time), alive)
    v = t.view()
    assert t.view() is v and len(v) == 3
    for a in (v.slots, v.owner, v.intruder, v.misses, v.age, v.x, v.mu, v.P):
        assert not a.flags.writeable
    np.testing.assert_array_equal(v.P, np.asarray(t.tracker.P)[v.slots])
    assert v.mu.shape == (3, PRESET.n_modes) and np.allclose(v.mu.sum(axis=1), 1.0)
    t.update(2.0, True, o, i, np.full((3, 2), 200.0), alive)
    assert t.view() is not v
    assert t.n_modes == 3 and t.mode_names == ("straight", "left", "right")
    assert t.predicts_modes
    xs, Ps = t.predict_modes_at(np.array([1, 5]), t.view().slots[:2])
    assert xs.shape == (2, 3, 2, 5) and Ps.shape == (2, 3, 2, 5, 5)


def test_truth_tracker_starts_at_first_detection_and_holds_the_truth():
    t = TrackTable.build(N, "truth", PRESET, SIGMA, 2, 1.0)
    assert isinstance(t.tracker, TruthTracker) and t.tracker.uses_truth
    assert not t.predicts_modes and t.n_modes == PRESET.n_modes
    alive = np.ones(N, dtype=bool)
    rng = np.random.default_rng(1)
    o, i = np.array([0, 0, 3]), np.array([1, 2, 1])
    for step in range(4):
        truth = rng.normal(size=(N, 5))
        dets = slice(None) if step < 2 else slice(0, 1)  # (0, 2) and (3, 1) then missed
        t.update(float(step), True, o[dets], i[dets], np.zeros((3, 2))[dets], alive, truth)
        v = t.view()
        assert len(v) == (3 if step < 3 else 1)  # dropped after 2 missed scans
        np.testing.assert_array_equal(v.x, truth[v.intruder])
        assert np.all(v.P == 0) and np.isnan(v.mu).all() and v.mu.shape == (len(v), 3)
    with pytest.raises(UserError, match="needs truth_states"):
        t.update(5.0, True, o, i, np.zeros((3, 2)), alive)


@pytest.mark.parametrize("name", ["imm", "truth"])
def test_builtin_trackers_fit_the_protocol(name):
    cls = registry.get("tracker", name)
    assert issubclass(cls, parts.Tracker)
    parts.check("tracker", cls, name)
    tr = make_tracker(name, PRESET, SIGMA)
    assert tr.capacity == 0 and not tr.alive.any()
    slots = tr.birth(np.zeros((3, 5)), np.broadcast_to(np.eye(5), (3, 5, 5)))
    assert slots.tolist() == [0, 1, 2] and tr.alive[slots].all()
    tr.drop(slots[1:2])
    assert tr.alive.tolist()[:3] == [True, False, True]
    assert tr.x.shape == (tr.capacity, 5) and tr.P.shape == (tr.capacity, 5, 5)
    assert tr.mu.shape == (tr.capacity, tr.n_modes) == (tr.capacity, 3)


def test_make_tracker_params():
    tr = make_tracker("imm", PRESET, SIGMA, {"kernel": "loops"})
    assert isinstance(tr, ImmTracker) and tr.imm.kernel == "loops"
    # unknown or mistyped params are refused where every scenario key is, in the loader
    from airspace_sim.scenarios import load

    with pytest.raises(UserError, match="tracker.params.bogus"):
        load("head_on", ["tracker.params.bogus=1"])
    with pytest.raises(UserError, match="tracker.params.kernel"):
        load("head_on", ['tracker.params.kernel="fast"'])
    assert load("head_on", ['tracker.params.kernel="loops"']).tracker.params == {"kernel": "loops"}
    with pytest.raises(UserError, match="must be a parts.Tracker"):
        TrackTable(N, object(), SIGMA, 2, 1.0)


@pytest.mark.parametrize("kind", ["imm", "truth"])
def test_table_pickles_and_continues_bit_for_bit(kind):
    import copy
    import pickle

    rng = np.random.default_rng(3)
    t = TrackTable.build(N, kind, PRESET, SIGMA, 2, 1.0)
    alive = np.ones(N, dtype=bool)
    o, i = np.array([0, 0, 1, 2, 3]), np.array([1, 2, 3, 0, 1])
    pos = rng.uniform(-1e4, 1e4, (N, 2))
    vel = rng.uniform(-200, 200, (N, 2))

    def scan(tab, k):
        truth = np.zeros((N, 5))
        truth[:, [0, 2]] = pos + k * vel
        truth[:, [1, 3]] = vel
        det = (np.arange(5) + k) % 5 > 1  # two missed scans in five: drops and births
        z = truth[i][:, [0, 2]] + SIGMA * np.sin(np.arange(10) + k).reshape(5, 2)
        tab.update(float(k), True, o[det], i[det], z[det], alive, truth)

    seen = []
    for k in range(6):
        scan(t, k)
        v = t.view()
        seen.append(frozenset(zip(v.owner.tolist(), v.intruder.tolist(), strict=True)))
    assert len(set(seen[2:])) > 1  # tracks come and go
    copies = [pickle.loads(pickle.dumps(t)), copy.deepcopy(t)]
    for k in range(6, 14):
        for tab in [t, *copies]:
            scan(tab, k)
    for c in copies:
        a, b = t.view(), c.view()
        for name in ("slots", "owner", "intruder", "misses", "age", "x", "mu", "P"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name))


def test_a_track_whose_measurements_are_all_gated_drops_in_the_world():
    """A recorded flight that jumps 20 km (a position-source switch, a wrong icao24) is
    detected on every scan after the jump, every measurement gated: the track counts each
    gated update as a miss, so it drops at scan k + D − 1 (k the first gated scan, D
    drop_after_misses), the next detection is pending and the one after starts a new track
    at the new position (closed form from the module's life cycle)."""
    import math

    from airspace_sim.recorded.autopilot import Recording
    from airspace_sim.recorded.flights import Flight, turn_rates
    from airspace_sim.scenarios import AircraftSpec, from_dict
    from airspace_sim.world import World

    v, jump_s, jump_m, drop = 200.0, 60, 20000.0, 4
    t = np.arange(0.0, 121.0)
    ax, ay = -12000.0 + v * t, np.where(t >= jump_s, jump_m, 0.0)  # A flies east, then jumps
    bx, by = np.full(t.size, 0.0), -15000.0 + v * t  # B flies north, tracks A
    vx, vy = np.full(t.size, v), np.zeros(t.size)
    alt = np.full(t.size, 10000.0)
    a = Flight("A", "A", "", t, ax, ay, vx, vy, turn_rates(t, vx, vy), alt)
    b = Flight("B", "B", "", t, bx, by, vy, vx, turn_rates(t, vy, vx), alt)

    def spec(f):
        return AircraftSpec(
            id=f.id,
            position=(float(f.x_m[0]), float(f.y_m[0])),
            heading_deg=math.degrees(math.atan2(f.vy[0], f.vx[0])),
            speed=v,
            autopilot="recorded",
            avoid=True,
            recording=Recording(f, 0.0),
        )

    sc = from_dict(
        {
            "name": "jump",
            "duration": 100.0,
            "sensor": {"sigma": 20.0, "drop_after_misses": drop, "range": 60000.0},
        }
    )
    w = World(sc, seed=1, aircraft=[spec(a), spec(b)])
    seen = {}  # time -> (age, misses, position error m) of B's track of A
    while not w.done:
        w.step()
        v_ = w.tracks.view()
        i = np.flatnonzero((v_.owner == 1) & (v_.intruder == 0))
        if i.size:
            x = v_.x[i[0]]
            err = math.hypot(x[0] - w.positions[0, 0], x[2] - w.positions[0, 1])
            seen[round(w.time)] = (int(v_.age[i[0]]), int(v_.misses[i[0]]), err)
    dropped_at = jump_s + drop - 1
    assert sorted(set(range(1, 101)) - set(seen)) == [dropped_at, dropped_at + 1]
    for k in range(jump_s, dropped_at):  # gated: one more miss per scan, the error stays
        assert seen[k][1] == k - jump_s + 1 and seen[k][2] > 0.5 * jump_m
    assert seen[jump_s - 1][1] == 0 and seen[jump_s - 1][2] < 200.0
    restart = dropped_at + 2
    assert seen[restart][0] == 0 and seen[restart][1] == 0  # a new track
    assert all(seen[k][2] < 300.0 and seen[k][1] == 0 for k in range(restart, 101))


def test_a_table_pickled_before_the_gating_rule_continues():
    """A checkpoint's table from before ``_no_gate`` existed (truth tracker) still steps."""
    import pickle

    t = TrackTable.build(N, "truth", PRESET, SIGMA, 2, 1.0)
    truth = np.zeros((N, 5))
    t.update(0.0, True, [0], [1], np.zeros((1, 2)), np.ones(N, bool), truth)
    t.__dict__.pop("_no_gate", None)  # as unpickled from an older version
    t2 = pickle.loads(pickle.dumps(t))
    t2.update(1.0, True, [0], [1], np.zeros((1, 2)), np.ones(N, bool), truth)
    assert len(t2) == 1 and t2.view().misses.tolist() == [0]


@pytest.mark.parametrize("kept", [True, False])
def test_kept_view_buffers_hold_numpys_gathers_through_births_drops_and_pickling(kept, monkeypatch):
    """The view's kept buffers (one numba gather per update) against numpy's gathers of the
    table, every step of a world whose tracks start, drop and grow the capacity; a pickled
    table rebuilds them. ``kept`` False: a table above KEPT_VIEW_MAX_SLOTS (numpy's
    gathers, no buffers)."""
    import pickle

    from airspace_sim.scenarios import load
    from airspace_sim.world import World, trackers

    if not kept:
        monkeypatch.setattr(trackers, "KEPT_VIEW_MAX_SLOTS", 0)

    w = World(load("ring", ["traffic.count=8", "sensor.drop_after_misses=1"]), seed=2)
    caps, counts = set(), set()
    for step in range(160):
        w.step()
        t = w.tracks
        v = t.view()
        s = np.flatnonzero(t.tracker.alive)
        want = (s, t._owner[s], t._intruder[s], t._misses[s], t._age[s], t.tracker.x[s])
        got = (v.slots, v.owner, v.intruder, v.misses, v.age, v.x)
        for g, a in zip(got + (v.mu, v.P), want + (t.tracker.mu[s], t.tracker.P[s])):
            assert g.dtype == a.dtype and g.tobytes() == a.tobytes()
            assert not g.flags.writeable
        caps.add(t.tracker.capacity)
        counts.add(len(v))
        if step == 100:
            w = pickle.loads(pickle.dumps(w))
            assert w.tracks._view is None and "_live" not in w.tracks.__dict__
    assert len(counts) > 3 and len(caps) > 1
    assert ("_live" in w.tracks.__dict__) == kept


@pytest.mark.parametrize("sigma", [50.0, 0.5, 1e7])
def test_births_kernel_matches_the_numpy_reference(sigma):
    """:func:`trackers._pending_births` (one merge of the sorted detections with the
    pending ones, starts through ``birth_checked``) against ``_births_reference`` (numpy,
    the tracker's checked ``birth``): random detections over many scans (missed scans,
    stale pending detections, dead aircraft, a repeated key, an update at the same time
    twice); the pending detections, the view and the tracker's arrays bit for bit."""
    n = 12
    rng = np.random.default_rng(7)
    fast = TrackTable.build(n, "imm", PRESET, sigma, 2, 1.0)
    ref = TrackTable.build(n, "imm", PRESET, sigma, 2, 1.0)
    ref._births = ref._births_reference
    pairs = np.array([(o, i) for o in range(n) for i in range(n) if o != i])
    pos = rng.uniform(-2e4, 2e4, (n, 2))
    vel = rng.uniform(-250.0, 250.0, (n, 2))
    alive = np.ones(n, dtype=bool)
    time = 0.0
    for scan in range(60):
        time += 1.0 if scan != 30 else 0.0  # scan 30 at the time of scan 29
        if scan == 40:
            alive[3] = False
        pick = pairs[rng.random(len(pairs)) < 0.4]
        if scan == 20:  # a pair detected twice in one scan
            pick = np.concatenate([pick, pick[:1]])
        rng.shuffle(pick)
        z = pos[pick[:, 1]] + vel[pick[:, 1]] * time + rng.normal(0.0, 50.0, (len(pick), 2))
        for t in (fast, ref):
            t.update(time, True, pick[:, 0], pick[:, 1], z, alive)
        for a, b in zip(
            (fast._pend_key, fast._pend_z, fast._pend_t), (ref._pend_key, ref._pend_z, ref._pend_t)
        ):
            assert a.tobytes() == b.tobytes()
        vf, vr = fast.view(), ref.view()
        for name in ("slots", "owner", "intruder", "misses", "age", "x", "mu", "P"):
            assert getattr(vf, name).tobytes() == getattr(vr, name).tobytes(), name
        for name in ("x", "P", "mu", "alive"):
            assert getattr(fast.tracker, name).tobytes() == getattr(ref.tracker, name).tobytes()
        assert np.array_equal(fast._index.get(pairs @ [n, 1]), ref._index.get(pairs @ [n, 1]))
    assert len(fast) > 20


def test_birth_checked_is_birth_without_the_checks():
    """ImmTracker.birth_checked gives the slots, lanes and arrays of birth."""
    a, b = make_tracker("imm", PRESET, SIGMA), make_tracker("imm", PRESET, SIGMA)
    rng = np.random.default_rng(3)
    for k in (3, 40, 1, 100):
        x0, P0 = two_point_initialisation(
            rng.normal(0, 1e4, (k, 2)), rng.normal(0, 1e4, (k, 2)), rng.uniform(0.5, 3, k),
            SIGMA**2 * np.eye(2), 0.0, OMEGA**2, MANOEUVRE_VELOCITY_VAR,
        )  # fmt: skip
        assert np.array_equal(a.birth(x0, P0), b.birth_checked(x0, P0))
        a.drop(np.arange(0, a.capacity, 7)[a.alive[::7]])
        b.drop(np.arange(0, b.capacity, 7)[b.alive[::7]])
        for name in ("_xs", "_Ps", "_mus", "_x", "_P", "_mu", "_nis", "_ll", "_gated"):
            assert getattr(a.imm, name).tobytes() == getattr(b.imm, name).tobytes(), name


@pytest.mark.parametrize("order", ["world", "shuffled"])
def test_lookup_by_the_previous_detections_matches_the_index(order):
    """The slots found by merging with the previous update's detections
    (:func:`trackers._lookup_by_previous`) against the index alone: detections in the
    world's order (pairs ``owner < intruder``, then the others, each by pair) or shuffled,
    with missed detections, gated ones, drops, dead aircraft, updates between scans and a
    repeated pair; every table array bit for bit after every update."""
    n = 10
    rng = np.random.default_rng(11)
    fast = TrackTable.build(n, "imm", PRESET, SIGMA, 2, 1.0)
    ref = TrackTable.build(n, "imm", PRESET, SIGMA, 2, 1.0)
    i, j = np.triu_indices(n, 1)
    pairs = np.concatenate([np.stack([i, j], 1), np.stack([j, i], 1)])  # the world's order
    pos = rng.uniform(-2e4, 2e4, (n, 2))
    vel = rng.uniform(-250.0, 250.0, (n, 2))
    alive = np.ones(n, dtype=bool)
    used = 0
    for scan in range(80):
        time = float(scan)
        if scan == 51:  # (an update between scans: its drops)
            alive[4] = False
        pick = pairs[rng.random(len(pairs)) < 0.85]
        scanned = scan % 4 != 3
        if not scanned:
            pick = pick[:0]
        if order == "shuffled":
            rng.shuffle(pick)
        if scan == 33:
            pick = np.concatenate([pick[:5], pick[4:]])  # a pair twice
        z = pos[pick[:, 1]] + vel[pick[:, 1]] * time + rng.normal(0.0, SIGMA, (len(pick), 2))
        z[rng.random(len(pick)) < 0.05] += 5e3  # gated: a miss
        used += fast._prev_rank.size > 0
        ref._prev_rank = ref._prev_slot = np.zeros(0, np.int64)
        for t in (fast, ref):
            t.update(time, scanned, pick[:, 0], pick[:, 1], z, alive)
        vf, vr = fast.view(), ref.view()
        for name in ("slots", "owner", "intruder", "misses", "age", "x", "mu", "P"):
            assert getattr(vf, name).tobytes() == getattr(vr, name).tobytes(), name
        keys = pairs @ [n, 1]
        assert np.array_equal(fast._index.get(keys), ref._index.get(keys))
        if scanned:
            last = pick
        if fast._prev_rank.size:  # the kept slots are the index's, for the last scan
            want = ref._index.get(last[:, 0] * n + last[:, 1])
            assert np.array_equal(fast._prev_slot, want)
    assert (used > 55) == (order == "world") and len(fast) > 30
