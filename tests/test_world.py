"""The World: autopilots, turn limits, tracks, avoidance, determinism, isolation."""

import dataclasses
import math

import numpy as np
import pytest

from airspace_sim.errors import UserError
from airspace_sim.scenarios.schema import (
    AircraftSpec,
    ResolverSpec,
    Scenario,
    SensorSpec,
    Separation,
    TrackerSpec,
)
from airspace_sim.world import World


def scenario(aircraft, resolver="none", tracker="imm", duration=300.0, seed=0, **sensor):
    return Scenario(
        name="t",
        seed=seed,
        dt=1.0,
        duration=duration,
        separation=Separation(r_safe=3000.0),
        sensor=SensorSpec(**{"range": 40000.0, "sigma": 50.0, **sensor}),
        tracker=TrackerSpec(kind=tracker),
        resolver=ResolverSpec(kind=resolver, lookahead=120.0),
        aircraft=aircraft,
    )


def head_on(resolver, tracker="imm", seed=0):
    return scenario(
        [
            AircraftSpec(
                id="west",
                position=(-30000.0, 0.0),
                heading_deg=0.0,
                speed=230.0,
                autopilot="route",
                waypoints=[(60000.0, 0.0)],
            ),
            AircraftSpec(
                id="east",
                position=(30000.0, 0.0),
                heading_deg=180.0,
                speed=230.0,
                autopilot="route",
                waypoints=[(-60000.0, 0.0)],
            ),
        ],
        resolver=resolver,
        tracker=tracker,
        seed=seed,
    )


def markov_traffic(n=12, seed=1, resolver="none", tracker="imm"):
    rng = np.random.default_rng(seed)
    return scenario(
        [
            AircraftSpec(
                id=f"M{i}",
                position=tuple(rng.uniform(-20000, 20000, 2)),
                heading_deg=float(rng.uniform(0, 360)),
                speed=230.0,
                autopilot="markov",
            )
            for i in range(n)
        ],
        resolver=resolver,
        tracker=tracker,
        seed=seed,
    )


# ------------------------------------------------------------------ autopilots
def test_straight_flies_straight_at_constant_speed():
    sc = scenario(
        [
            AircraftSpec(id="a", position=(100.0, -50.0), heading_deg=30.0, speed=200.0),
            AircraftSpec(id="b", position=(0.0, 90000.0), heading_deg=250.0, speed=120.0),
        ]
    )
    world = World(sc)
    for _ in range(100):
        world.step()
    t = world.time
    for k, (p0, h, v) in enumerate((((100.0, -50.0), 30.0, 200.0), ((0.0, 90000.0), 250.0, 120.0))):
        expect = np.array(p0) + v * t * np.array(
            [math.cos(math.radians(h)), math.sin(math.radians(h))]
        )
        np.testing.assert_allclose(world.positions[k], expect, rtol=0, atol=1e-6)
        assert world.speeds[k] == v
        assert math.isclose(
            world.headings[k], math.radians(h) - (2 * math.pi if h > 180 else 0), abs_tol=1e-12
        )


def test_turn_limit_never_exceeded_and_agents_are_clipped():
    sc = markov_traffic(n=10, resolver="bands")
    sc.aircraft[0].controlled = True
    sc.aircraft[1].controlled = True
    sc.aircraft[2].max_turn_rate_deg = 1.0
    world = World(sc)
    limit = world.max_turn_rate * world.dt
    cmd = np.full(world.n, np.nan)
    turned = 0
    for k in range(150):
        cmd[0] = math.radians(10.0) * (1 if k % 20 < 10 else -1)  # asks for more than allowed
        h0 = world.headings.copy()
        p0 = world.positions.copy()
        world.step(cmd)
        dh = np.abs((world.headings - h0 + math.pi) % (2 * math.pi) - math.pi)
        assert np.all(dh <= limit + 1e-12)
        # speed along the flown chord is constant: |Δp| = v·dt·sinc
        step = np.hypot(*(world.positions - p0).T)
        assert np.all(step <= world.speeds * world.dt + 1e-9)
        turned += np.count_nonzero(dh > 0.99 * limit)
    assert math.isclose(abs(world.turn_rates[0]), math.radians(3.0))  # clipped agent command
    assert turned > 100  # Markov pilots do turn at the limit


def test_controlled_nan_means_builtin_and_bad_actions_rejected():
    sc = markov_traffic(n=3)
    sc.aircraft[0].controlled = True
    a, b = World(sc), World(sc)
    for _ in range(20):
        a.step()
        b.step(np.full(3, np.nan))
    assert np.array_equal(a.positions, b.positions)
    with pytest.raises(UserError):
        a.step(np.zeros(2))
    with pytest.raises(UserError):
        a.step(np.array([np.inf, 0.0, 0.0]))


def test_route_autopilot_reaches_every_waypoint_then_leaves():
    wps = [(20000.0, 0.0), (20000.0, 20000.0), (-5000.0, 25000.0)]
    sc = scenario(
        [
            AircraftSpec(
                id="r",
                position=(0.0, 0.0),
                heading_deg=90.0,
                speed=200.0,
                autopilot="route",
                waypoints=wps,
            )
        ],
        duration=1000.0,
    )
    world = World(sc)
    best = np.full(3, np.inf)
    while world.active[0] and world.step_count < 1000:
        world.step()
        best = np.minimum(best, np.hypot(*(np.array(wps) - world.positions[0]).T))
    assert not world.active[0]  # finished after the last waypoint
    assert np.all(best < 200.0 * 1.0 + 1e-9)  # came within one step's travel of each
    m = world.metrics()
    assert 0.0 <= m["extra_path_pct"] < 20.0  # turning radius only (a 90° initial turn)


def test_markov_modes_follow_the_chain_and_imm_recognises_them():
    world = World(markov_traffic(n=12))
    modes = []
    for _ in range(300):
        world.step()
        modes.append(world.modes.copy())
    modes = np.array(modes)
    assert set(np.unique(modes)) == {0, 1, 2}
    # realistic preset: ~60 s straight, ~20 s turning → stationary law about (.6, .2, .2)
    frac = np.bincount(modes.ravel(), minlength=3) / modes.size
    assert 0.4 < frac[0] < 0.8
    # turns are flown at the mode's rate
    np.testing.assert_allclose(
        world.turn_rates, np.array([0, 1, -1])[world.modes] * math.radians(3.0)
    )
    m = world.metrics()
    assert m["mode_accuracy"] > 0.7  # well above always guessing "straight" (~0.6)
    assert m["track_rmse_m"] < 50.0  # below the raw measurement error (σ√2 ≈ 71 m)


def test_mode_accuracy_only_for_a_tracker_whose_modes_are_the_traffics():
    """imm-ct has three modes like the realistic traffic, but other ones (quiet CV, CT, manoeuvring
    CV): comparing its mode indices with the traffic's would be meaningless, so no accuracy."""
    sc = markov_traffic(n=4)
    sc = dataclasses.replace(sc, duration=20.0, tracker=TrackerSpec(kind="imm", model="imm-ct"))
    m = World(sc).run()
    assert m["track_steps"] > 0
    assert math.isnan(m["mode_accuracy"])


# ---------------------------------------------------------------- track table
def track_set(world):
    v = world.tracks.view()
    return set(zip(v.owner.tolist(), v.intruder.tolist()))


def test_tracks_start_on_second_detection_and_drop_after_misses():
    # own flies east; "close" keeps 10 km ahead; "in" closes from 60 km (enters 40 km range
    # at t = 50 s); "out" opens from 35 km (leaves at t = 100 s); "quiet" does not avoid.
    sc = scenario(
        [
            AircraftSpec(id="own", position=(0.0, 0.0), heading_deg=0.0, speed=200.0),
            AircraftSpec(
                id="close", position=(10000.0, 0.0), heading_deg=0.0, speed=200.0, avoid=False
            ),
            AircraftSpec(
                id="in", position=(60000.0, 1000.0), heading_deg=180.0, speed=200.0, avoid=False
            ),
            AircraftSpec(
                id="out", position=(-35000.0, -1000.0), heading_deg=180.0, speed=50.0, avoid=False
            ),
        ],
        drop_after_misses=3,
        duration=200.0,
    )
    world = World(sc)
    assert len(world.tracks) == 0  # one detection is not a track yet
    world.step()
    assert track_set(world) == {(0, 1), (0, 3)}  # non-avoiding aircraft track nobody
    in_range_since = dropped_at = left_at = None
    while world.time < 130:
        world.step()
        d_in = np.hypot(*(world.positions[2] - world.positions[0]))
        d_out = np.hypot(*(world.positions[3] - world.positions[0]))
        if d_in < 40000.0 and in_range_since is None:
            in_range_since = world.step_count
            assert (0, 2) not in track_set(world)
        elif in_range_since is not None and world.step_count == in_range_since + 1:
            assert (0, 2) in track_set(world)
        if d_out >= 40000.0 and left_at is None:
            left_at = world.step_count
        if left_at is not None and dropped_at is None and (0, 3) not in track_set(world):
            dropped_at = world.step_count
    assert in_range_since is not None and left_at is not None
    assert dropped_at == left_at + 2  # misses at left_at, +1, +2 → dropped on the third
    assert (0, 1) in track_set(world)


def test_no_detections_no_tracks_and_period():
    sc = head_on("none", seed=0)
    sc.sensor.range = 100000.0  # in range from the start
    sc.sensor.detection_probability = 0.0
    world = World(sc)
    world.run(20)
    assert len(world.tracks) == 0
    sc = head_on("none", seed=0)
    sc.sensor.range = 100000.0
    sc.sensor.period = 4.0
    world = World(sc)
    ages = []
    for _ in range(12):
        world.step()
        ages.append(len(world.tracks))
    assert ages[:3] == [0, 0, 0] and ages[3] == 2  # second scan at t = 4 s starts both tracks


def test_tracks_are_in_the_world_frame_and_accurate():
    world = World(head_on("none"))
    world.run(60)
    t = world.tracks.view()
    err = np.hypot(*(t.x[:, (0, 2)] - world.positions[t.intruder]).T)
    verr = np.hypot(*(t.x[:, (1, 3)] - world.velocities[t.intruder]).T)
    assert len(t) == 2 and np.all(err < 150.0) and np.all(verr < 30.0)


# ------------------------------------------------------------------ avoidance
@pytest.mark.parametrize("seed", [0, 1])
def test_head_on_bands_avoids_none_collides(seed):
    none = World(head_on("none", seed=seed)).run(250)
    bands_world = World(head_on("bands", seed=seed))
    bands = bands_world.run(250)
    assert none["los_events"] == 1 and none["nmac_events"] == 1
    assert bands["los_events"] == 0 and bands["min_separation_m"] > 3000.0
    assert bands["alerts"] >= 2 and 0 < bands["extra_path_m"]
    # both turned right (rules of the air), then resumed toward their waypoints
    assert bands_world.positions[0, 1] < 0 or not bands_world.active[0]


def test_none_resolver_reports_conflicts_without_turning():
    world = World(head_on("none"))
    world.run(60)  # 32 km apart: in range, CPA 0 within the look-ahead
    assert world.conflict.all() and np.all(world.turn_rates == 0.0)


# ----------------------------------------------------- determinism, isolation
def run_record(world, steps):
    rec = []
    for _ in range(steps):
        world.step()
        rec.append((world.positions.copy(), np.array(world.tracks.view().x), world.advice.copy()))
    return rec


def same(a, b):
    return all(np.array_equal(x, y) for ra, rb in zip(a, b) for x, y in zip(ra, rb))


def test_deterministic_bit_for_bit_and_seed_matters():
    sc = markov_traffic(n=10, resolver="bands", seed=4)
    a, b = World(sc), World(sc)
    ra, rb = run_record(a, 80), run_record(b, 80)
    assert same(ra, rb)
    assert a.metrics() == b.metrics()
    c = World(sc, seed=5)
    rc = run_record(c, 80)
    assert not same(ra, rc)


def test_two_worlds_interleaved_equal_separate_runs():
    s1 = markov_traffic(n=8, resolver="bands", seed=2)
    s2 = head_on("bands", seed=3)
    alone1 = run_record(World(s1), 60)
    alone2 = run_record(World(s2), 60)
    w1, w2 = World(s1), World(s2)
    r1, r2 = [], []
    for _ in range(60):
        r1 += run_record(w1, 1)
        r2 += run_record(w2, 1)
    assert same(alone1, r1) and same(alone2, r2)


def test_generated_traffic_uses_build_aircraft():
    from airspace_sim.scenarios import load

    world = World(load("ring", ["traffic.count=8", "traffic.radius=20000"]))
    assert world.n == 8 and world.step_count == 0
    world.run(3)
    assert world.time == 3.0


def test_every_registered_resolver_and_tracker_runs_in_a_world():
    from airspace_sim import registry

    for res in registry.names("resolver"):
        m = World(head_on(res)).run(120)
        assert m["steps"] == 120, res
    for tr in registry.names("tracker") + ["truth"]:
        world = World(head_on("bands", tracker=tr))
        world.run(120)
        assert len(world.tracks) == 2, tr
        assert world.tracks.view().x.shape == (2, 5)


def test_left_commitment_returns_right_once_the_right_is_clear():
    # turn_preference "right": an ownship that committed left only because its right was
    # blocked goes back right as soon as a right heading is clear; one that committed right
    # stays right even when the left opens up.
    from airspace_sim.scenarios import load

    avoid = World(load("demo")).policy
    assert avoid.preference == "right"
    cand = np.radians([[10.0, -10.0, 20.0, -20.0]] * 3)  # (n, C): left +, right -
    band = np.array(
        [
            [True, True, False, False],  # committed left, right now clear
            [True, False, False, False],  # committed left, right still blocked
            [True, False, False, True],
        ]
    )  # committed right, nearest clear is left
    side = np.array([1.0, 1.0, -1.0])
    psi = np.zeros(3)
    conflict = np.ones(3, dtype=bool)
    from airspace_sim.avoidance.bands import first_clear_from_band

    out, new_side = avoid._commit(psi, conflict, side, cand, first_clear_from_band(cand, band))
    np.testing.assert_array_equal(new_side, [-1.0, 1.0, -1.0])
    np.testing.assert_allclose(out, np.radians([-10.0, 10.0, -20.0]))


def test_demo_scenario_keeps_separation():
    # Before the rule above, ring06 and ring07 of the demo turned into each other (NMAC,
    # min separation 1.8e-12 m, extra path 245%).
    from airspace_sim.scenarios import load

    m = World(load("demo")).run()
    assert m["los_events"] == 0 and m["nmac_events"] == 0, m
    assert m["min_separation_m"] > 3000.0


@pytest.mark.parametrize(
    "off_route_s, clear", [(0.0, False), (10.0, False), (15.0, True), (30.0, True), (300.0, True)]
)
def test_resume_margin_shrinks_over_resume_decay_s(off_route_s, clear):
    # An intruder keeps a constant 6000 m (same velocity). Clear radius r_safe·(1 + margin +
    # extra) with r_safe 3000, margin 0.1 and extra = 1.5·(1 − off/30): 7800 m at 0 s,
    # 6300 m at 10 s (blocked), 5550 m at 15 s (clear), 3300 m from 30 s on.
    from airspace_sim.scenarios import load
    from airspace_sim.world.control import Encounters
    from airspace_sim.world.policy import AvoidancePolicy

    sc = load(
        "dense_random",
        ["resolver.resume_decay_s=30.0", "resolver.lookahead=120.0", "resolver.margin=0.1"],
    )
    avoid = AvoidancePolicy(sc, 1.0, np.ones(2, bool), np.ones(2, bool))
    assert (avoid.resume_margin, avoid.margin, avoid.r_safe) == (1.5, 0.1, 3000.0)
    avoid.off_route_s = np.array([off_route_s, 0.0])
    enc = Encounters(
        np.array([0]),
        np.array([[0]]),
        np.array([[[0.0, 6000.0]]]),
        np.zeros((1, 1, 2)),
        np.array([[True]]),
    )
    velocities = np.array([[200.0, 0.0], [200.0, 0.0]])
    got = avoid._resume_clear(enc, velocities, np.zeros(1), np.full(2, np.radians(3.0)))
    assert got.tolist() == [clear]


@pytest.mark.parametrize(
    "off_route_s, clear", [(0.0, False), (15.0, False), (20.0, True), (300.0, True)]
)
def test_resume_margin_stops_at_resume_margin_floor(off_route_s, clear):
    # As above with resume_margin_floor 0.5: extra = 0.5 + 1.0·(1 − off/30), a clear radius
    # of 7800 m at 0 s, 6300 m at 15 s (blocked at 6000 m), 5800 m at 20 s (clear) and
    # 4800 m from 30 s on; an intruder at 4500 m is blocked however long the decay.
    from airspace_sim.scenarios import load
    from airspace_sim.world.control import Encounters
    from airspace_sim.world.policy import AvoidancePolicy

    sc = load(
        "dense_random",
        [
            "resolver.resume_decay_s=30.0",
            "resolver.lookahead=120.0",
            "resolver.resume_margin_floor=0.5",
            "resolver.margin=0.1",
        ],
    )
    avoid = AvoidancePolicy(sc, 1.0, np.ones(2, bool), np.ones(2, bool))
    avoid.off_route_s = np.array([off_route_s, 0.0])
    velocities = np.array([[200.0, 0.0], [200.0, 0.0]])
    got = []
    for distance in (6000.0, 4500.0):
        enc = Encounters(
            np.array([0]),
            np.array([[0]]),
            np.array([[[0.0, distance]]]),
            np.zeros((1, 1, 2)),
            np.array([[True]]),
        )
        ok = avoid._resume_clear(enc, velocities, np.zeros(1), np.full(2, np.radians(3.0)))
        got.append(bool(ok[0]))
    assert got == [clear, False]


def test_dense_random_traffic_reaches_its_routes():
    # Before resume_decay_s and the shorter look-ahead, 40 of 60 aircraft were still flying
    # after 600 s, many 100 km past the sector edge (extra path ~600%, seed 0).
    from airspace_sim.scenarios import load

    world = World(load("dense_random"), seed=0)
    m = world.run()
    assert m["nmac_events"] == 0, m
    assert m["extra_path_pct"] < 40.0, m
    assert world.active.sum() <= 10  # the rest reached the far edge of the sector
    assert (world.progress() > 0).all()  # nobody ends farther from its goal than it started


def test_bands_probabilistic_gets_the_tracks_mode_predictions():
    from airspace_sim.scenarios import load

    world = World(
        load(
            "demo",
            [
                'resolver.kind="bands-probabilistic"',
                "resolver.probability_horizon_s=30.0",
                "resolver.probability_samples=3",
            ],
        )
    )
    seen = []
    resolve = world.policy.resolver.resolve

    def spy(*args, **kw):
        seen.append(kw.get("mode_predictions"))
        return resolve(*args, **kw)

    world.policy.resolver.resolve = spy
    world.run(20)
    assert seen and all(p is not None for p in seen)
    from airspace_sim.world.policy import mode_predictions

    view = world.tracks.view()
    enc = world.policy._encounters
    t = np.array([10.0, 20.0, 30.0])
    xs, Ps, mu = mode_predictions(
        world.tracks, view, enc, world.positions, world.velocities, 1.0, t
    )
    n_own, K = enc.valid.shape
    assert xs.shape == (n_own, K, 3, 3, 2) and Ps.shape == (n_own, K, 3, 3, 2, 2)
    np.testing.assert_allclose(mu[enc.valid].sum(axis=-1), 1.0)
    # mode 0 is constant velocity: intruder x + v·t from its mode-0 posterior, minus the
    # ownship flying straight (closed form)
    t = np.array([10.0, 20.0, 30.0])
    view = world.tracks.view()
    o, k = np.argwhere(enc.valid)[0]
    row, own = enc.rows[o, k], enc.owners[o]
    # the slot is the track of that ownship, at that relative position
    assert view.owner[row] == own
    np.testing.assert_allclose(view.x[row, (0, 2)] - world.positions[own], enc.rel_position[o, k])
    xm, _ = world.tracks.tracker.imm.modes(view.slots[row : row + 1])
    x0 = xm[0, 0]
    expect = (
        np.array([x0[0], x0[2]])[None]
        + t[:, None] * np.array([x0[1], x0[3]])[None]
        - world.positions[own]
        - t[:, None] * world.velocities[own]
    )
    np.testing.assert_allclose(xs[o, k, 0], expect, rtol=1e-9, atol=1e-6)
    assert np.all(np.diff(Ps[o, k, 0, :, 0, 0]) > 0)  # uncertainty grows ahead


def test_off_route_time_stays_zero_for_aircraft_that_never_leave_their_route():
    # route autopilots give ~1e-16 rad/s from atan2 on a straight leg: that must not count
    # as turning back (it used to let off_route_s grow and eat the resume clearance)
    from airspace_sim.scenarios import from_dict

    aircraft = [
        {
            "id": f"a{i}",
            "position": [0.0, 20000.0 * i],
            "heading_deg": 33.0 + 50 * i,
            "speed": 230.0,
            "autopilot": "route",
            "waypoints": [
                [
                    300000.0 * math.cos(math.radians(33.0 + 50 * i)),
                    20000.0 * i + 300000.0 * math.sin(math.radians(33.0 + 50 * i)),
                ]
            ],
        }
        for i in range(4)
    ]
    world = World(from_dict({"name": "apart", "aircraft": aircraft, "sensor": {"range": 5000.0}}))
    assert world.policy.overrides
    for _ in range(60):
        world.step()
        assert np.all(world.policy.off_route_s == 0.0)


def test_extra_path_pct_is_nan_without_planned_paths():
    from airspace_sim.scenarios import load

    m = World(load("dense_random", ['traffic.autopilot="markov"', "traffic.count=6"])).run(20)
    assert math.isnan(m["extra_path_pct"]) and m["extra_path_m"] == 0.0
