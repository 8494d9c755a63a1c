"""Recorded aircraft in the world and the replay's measurements, on flights the tests make.

Oracles: closed-form straight-line and turning trajectories (positions, LoS windows, CPA
times), brute-force counts of the steps inside r_safe, and the resolver against no resolver.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from airspace_sim.errors import UserError
from airspace_sim.recorded.analysis import ReplayStats
from airspace_sim.recorded.autopilot import Recording
from airspace_sim.recorded.flights import Flight, turn_rates
from airspace_sim.scenarios import AircraftSpec, from_dict
from airspace_sim.world import World

V = 200.0  # m/s


def _line(fid, p0, heading_deg, t_s, alt_m=10000.0):
    """A straight flight at V from p0 (m) at t_s[0] along heading_deg (CCW from east)."""
    t = np.asarray(t_s, float)
    h = math.radians(heading_deg)
    d = V * (t - t[0])
    x, y = p0[0] + d * math.cos(h), p0[1] + d * math.sin(h)
    vx, vy = np.full(t.size, V * math.cos(h)), np.full(t.size, V * math.sin(h))
    return Flight(fid, fid, "", t, x, y, vx, vy, turn_rates(t, vx, vy), np.full(t.size, alt_m))


def _spec(f: Flight, avoid=True):
    return AircraftSpec(
        id=f.id,
        position=(float(f.x_m[0]), float(f.y_m[0])),
        heading_deg=math.degrees(math.atan2(f.vy[0], f.vx[0])),
        speed=float(f.speed[0]),
        autopilot="recorded",
        avoid=avoid,
        recording=Recording(f, 0.0),
    )


def _crossing(dz_m=200.0):
    """A flies east through the origin at t=150 s; B, recorded from t=20 s, flies north
    through it at t=150 s."""
    a = _line("A", (-30000.0, 0.0), 0.0, np.arange(0.0, 301.0, 10.0))
    b = _line("B", (0.0, -26000.0), 90.0, np.arange(20.0, 321.0, 10.0), 10000.0 + dz_m)
    return a, b


def _world(flights, duration=330.0, extra=(), **sc):
    scenario = from_dict({"name": "t", "duration": duration, **sc})
    return World(scenario, seed=3, aircraft=[_spec(f) for f in flights] + list(extra))


def _run(world, stats=None):
    if stats is not None:
        stats.observe()
    while not world.done:
        world.step()
        if stats is not None:
            stats.observe()
    return world


def test_recorded_aircraft_fly_their_recordings_enter_and_leave():
    a, b = _crossing()
    w = _world([a, b])
    assert w.active.tolist() == [True, False]  # B's recording starts at 20 s
    seen = []
    while not w.done:
        w.step()
        t = w.time
        for i, f in enumerate((a, b)):
            inside = f.start_s <= t <= f.end_s
            assert w.active[i] == inside, (t, i)
            if inside:
                x, y, vx, vy = f.sample(t)
                assert math.hypot(w.positions[i, 0] - x, w.positions[i, 1] - y) < 1e-6
                assert math.hypot(w.velocities[i, 0] - vx, w.velocities[i, 1] - vy) < 1e-6
        seen.append(w.active.copy())
    assert w.step_count == 330 and not np.array(seen)[-1].any()


def test_a_gap_takes_the_aircraft_out_and_back():
    t = np.concatenate([np.arange(0.0, 101.0, 10.0), np.arange(200.0, 301.0, 10.0)])
    c = _line("C", (0.0, 0.0), 30.0, t)
    a = _line("A", (50000.0, 0.0), 180.0, np.arange(0.0, 301.0, 10.0))
    w = _world([c, a], duration=300.0)
    out = []
    while not w.done:
        w.step()
        out.append((w.time, bool(w.active[0])))
        if w.active[0]:
            x, y, *_ = c.sample(w.time)
            assert math.hypot(w.positions[0, 0] - x, w.positions[0, 1] - y) < 1e-6
    absent = [tt for tt, on in out if not on]
    assert absent == [float(k) for k in range(101, 200)]


def test_losses_alerts_and_their_lead_time_between_real_aircraft():
    a, b = _crossing(dz_m=200.0)  # 656 ft apart
    w = _world([a, b])
    stats = ReplayStats(w)
    r = _run(w, stats) and stats.report()
    # brute force: steps t at which |A(t) − B(t)| = V·√2·|t − 150| < r_safe
    inside = [t for t in range(0, 331) if V * math.sqrt(2) * abs(t - 150) < 3000.0]
    assert r["los_s"] == len(inside) and r["los_pairs"] == r["los_episodes"] == 1
    assert r["los3d_pairs"] == 1  # 656 ft < 1000 ft
    assert r["los_alerted"] == 1 and r["los_missed"] == 0 and r["alerts_false"] == 0
    # the CPA enters the 120 s look-ahead at ~19 s; B's track is confirmed ~26 s
    assert 100.0 <= r["lead_time_median_s"] <= 121.0
    assert 0.0 < r["track_position_rmse_m"] < 60.0  # σ = 50 m, straight flights
    assert r["straight_s"] > 0 and r["straight_flagged"] < 0.05 and r["turning_s"] == 0
    assert r["real_aircraft"] == 2 and r["max_simultaneous"] == 2


def test_vertical_separation_counts_only_close_altitudes():
    a, b = _crossing(dz_m=400.0)  # 1312 ft apart
    w = _world([a, b])
    stats = ReplayStats(w)
    r = _run(w, stats) and stats.report()
    assert r["los_pairs"] == 1 and r["los3d_pairs"] == 0
    a, b = _crossing(dz_m=400.0)
    w = _world([a, b])
    stats = ReplayStats(w, vertical_ft=2000.0)
    assert (_run(w, stats) and stats.report())["los3d_pairs"] == 1


def _turning(fid, omega_deg, turn_from=60.0, turn_s=60.0, n=300, dt=2.0):
    """Straight east, a coordinated turn at omega_deg for turn_s, straight again."""
    t = np.arange(0.0, n * dt, dt)
    w = math.radians(omega_deg)
    tt = np.clip(t - turn_from, 0.0, turn_s)
    h = w * tt
    # position: integral of V·(cos h, sin h)
    x = np.where(tt > 0, V * np.sin(h) / w, 0.0) + V * (np.minimum(t, turn_from))
    y = np.where(tt > 0, V * (1 - np.cos(h)) / w, 0.0)
    after = np.maximum(t - turn_from - turn_s, 0.0)
    x = x + V * math.cos(w * turn_s) * after - 20000.0
    y = y + V * math.sin(w * turn_s) * after
    vx, vy = V * np.cos(h), V * np.sin(h)
    return Flight(fid, fid, "", t, x, y, vx, vy, turn_rates(t, vx, vy), np.full(t.size, 1e4))


def test_mode_identification_against_the_recorded_turn_rate():
    turner = _turning("T", -3.0)  # a right turn at the realistic preset's rate
    watcher = _line("W", (-25000.0, 10000.0), 0.0, np.arange(0.0, 600.0, 10.0), 5000.0)
    w = _world([turner, watcher], duration=580.0)
    stats = ReplayStats(w)
    r = _run(w, stats) and stats.report()
    assert r["mode_rule"] == "mode"
    # brute force: the seconds at which the recording turns at ≥ 1°/s (the watcher's track
    # of the turner is confirmed throughout)
    rates = np.degrees(np.abs(turner.turn_rate_at(np.arange(0.0, 581.0))))
    assert r["turning_s"] == np.count_nonzero(rates >= 1.0) == 61
    assert r["turning_flagged"] >= 0.6  # flagged as a right turn
    assert r["straight_flagged"] <= 0.05


def test_a_simulated_ownship_avoids_real_traffic():
    intruder = _line("R", (40000.0, 0.0), 180.0, np.arange(0.0, 301.0, 10.0))
    own = AircraftSpec(id="own", position=(-40000.0, 0.0), heading_deg=0.0, speed=V)
    results = {}
    for kind in ("none", "bands"):
        w = _world([intruder], duration=250.0, extra=[own], resolver={"kind": kind})
        _run(w)
        results[kind] = w.metrics()
        # the recorded aircraft is never steered
        x, y, *_ = intruder.sample(w.time)
        assert math.hypot(w.positions[0, 0] - x, w.positions[0, 1] - y) < 1e-6
    assert results["none"]["los_events"] == 1
    assert results["bands"]["los_events"] == 0
    assert results["bands"]["min_separation_m"] >= 3000.0


def test_recorded_aircraft_never_fly_the_advice_beside_an_agent():
    a, b = _crossing()
    agent = AircraftSpec(
        id="rl", position=(0.0, 60000.0), heading_deg=90.0, speed=V, controlled=True
    )
    w = _world([a, b], extra=[agent])
    nan = np.full(w.n, np.nan)
    conflicts = 0
    while not w.done:
        w.step(nan)  # the agent leaves every step to the built-in pilot
        conflicts += int(w.conflict[:2].any())
        assert not w.policy.following[:2].any(), w.time
    assert conflicts > 0  # the recorded pair was advised, and did not follow it
    assert w.metrics()["avoidance_turn_deg"] == 0.0


def test_a_retired_recorded_aircraft_stays_out():
    a, b = _crossing()
    w = _world([a, b])
    for _ in range(40):  # both recorded now
        w.step()
    assert w.active.all()
    w.retire([1])
    while not w.done:
        w.step()
        assert not w.active[1], w.time
        assert w.active[0] == (w.time <= a.end_s)
    assert w.retired.tolist() == [False, True]


def test_same_seed_same_replay():
    reports = []
    for _ in range(2):
        a, b = _crossing()
        w = _world([a, b])
        stats = ReplayStats(w)
        reports.append((_run(w, stats) and stats.report(), w.metrics()))
    assert json.dumps(reports[0], default=str) == json.dumps(reports[1], default=str)


def test_recorded_autopilot_needs_a_recording():
    sc = from_dict({"name": "t"})
    spec = AircraftSpec(id="x", position=(0.0, 0.0), heading_deg=0.0, speed=V, autopilot="recorded")
    with pytest.raises(UserError, match="'x': autopilot 'recorded' needs a recording"):
        World(sc, aircraft=[spec])


def test_a_pickled_replay_world_continues_bit_for_bit():
    import pickle

    a, b = _crossing()
    w = _world([a, b], duration=200.0)
    for _ in range(15):  # B not in yet
        w.step()
    copy = pickle.loads(pickle.dumps(w))
    _run(w)
    _run(copy)
    assert np.array_equal(w.positions, copy.positions)
    assert json.dumps(w.metrics()) == json.dumps(copy.metrics())
