"""The commands and motion kernels (world/flight.py, the route autopilot's commands and
capture) against the numpy statements they replace, bit for bit (signed zeros included),
and a world stepped by them against the same world stepped by the numpy path."""

import json

import numpy as np
import pytest
from numba import njit

from airspace_sim.geometry import wrap_angle
from airspace_sim.scenarios import load
from airspace_sim.world import World, flight
from airspace_sim.world.autopilots import FlightState, RouteAutopilot


def _bits(a):
    a = np.ascontiguousarray(a)
    return a.view({8: np.uint64, 1: np.uint8}[a.dtype.itemsize])


@njit(cache=True)
def _wrap_all(a, out):
    for i in range(a.size):
        out[i] = flight.wrap(a[i])


def test_wrap_is_numpys_wrap_angle_bit_for_bit():
    rng = np.random.default_rng(0)
    pi = np.pi
    special = [0.0, -0.0, pi, -pi, 2 * pi, -2 * pi, 3 * pi, -3 * pi, np.nextafter(pi, 0)]
    special += [np.nextafter(-pi, 0), 1e-300, -1e-300, 1e17, -1e17, np.inf, np.nan]
    a = np.concatenate([special, rng.uniform(-20, 20, 5000), rng.normal(0, 1e-8, 500)])
    a = np.concatenate([a, a + pi, a - pi])
    got = np.empty_like(a)
    with np.errstate(invalid="ignore"):
        _wrap_all(a, got)
        want = wrap_angle(a)
    assert np.array_equal(_bits(got), _bits(want))


def test_turn_commands_match_where_clip_and_inactive_bit_for_bit():
    rng = np.random.default_rng(1)
    n = 400
    max_rate = np.radians(rng.choice([0.0, 1.5, 3.0], n))
    rate = rng.uniform(-0.1, 0.1, n)
    rate[rng.random(n) < 0.3] = rng.choice([0.0, -0.0, np.nan], n)[:1]
    rate[:5] = [0.0, -0.0, np.nan, 1.0, -1.0]
    max_rate[:5] = 0.0
    hr = rng.uniform(-0.1, 0.1, n)
    hr[rng.random(n) < 0.2] = np.nan
    agent = (rng.random(n) < 0.5) & np.isfinite(hr)
    active = rng.random(n) < 0.8
    agent[:5], active[:5] = False, True
    want = np.clip(np.where(agent, hr, rate), -max_rate, max_rate)
    want[~active] = 0.0
    got = np.empty(n)
    flight.turn_commands(rate, hr, agent, max_rate, active, got)
    assert np.isnan(want).any()  # a NaN rate of an active aircraft is kept, as numpy's clip
    assert np.array_equal(_bits(got), _bits(want))


def _numpy_motion(rate, headings, speeds, active, dt):
    """World._motion's numpy statement (before the kernels)."""
    turn = rate * dt
    mid = headings + 0.5 * turn
    y = np.pi * (turn / (2.0 * np.pi))
    y[y == 0.0] = np.finfo(float).eps
    chord = speeds * (np.sin(y) / y)
    v = np.empty((rate.size, 2))
    np.multiply(chord, np.cos(mid), out=v[:, 0])
    np.multiply(chord, np.sin(mid), out=v[:, 1])
    v[~active] = 0.0
    return turn, v, wrap_angle(headings + turn), np.where(active, speeds * dt, 0.0)


@pytest.mark.parametrize("dt", [1.0, 0.25])
def test_motion_kernels_match_the_numpy_motion_bit_for_bit(dt):
    rng = np.random.default_rng(2)
    n = 500
    rate = rng.uniform(-0.06, 0.06, n)
    rate[rng.random(n) < 0.2] = 0.0
    rate[rng.random(n) < 0.1] = -0.0
    headings = wrap_angle(rng.uniform(-4, 4, n))
    speeds = rng.uniform(0, 300, n)
    active = rng.random(n) < 0.8
    want = _numpy_motion(rate, headings, speeds, active, dt)
    turn, mid, y = np.empty(n), np.empty(n), np.empty(n)
    flight.arc_terms(rate, headings, dt, turn, mid, y)
    v, new_h, flown = np.empty((n, 2)), np.empty(n), np.empty(n)
    flight.chords(speeds, np.sin(y), y, np.cos(mid), np.sin(mid), active, headings, turn, dt,
                  v, new_h, flown)  # fmt: skip
    for g, w in zip((turn, v, new_h, flown), want):
        assert np.array_equal(_bits(g), _bits(w))
    vel = np.empty((n, 2))
    flight.velocity_rows(speeds, np.cos(headings), np.sin(headings), active, vel)
    want_v = np.stack([speeds * np.cos(headings), speeds * np.sin(headings)], axis=1)
    want_v[~active] = 0.0
    assert np.array_equal(_bits(vel), _bits(want_v))


def test_pair_flags():
    flag = np.ones(10, bool)
    flight.pair_flags(np.array([1, 2], np.int64), np.array([5, 2], np.int64), flag)
    assert flag.tolist() == [i in (1, 2, 5) for i in range(10)]
    flight.pair_flags(np.zeros(0, np.int64), np.zeros(0, np.int64), flag)
    assert not flag.any()


def _route(seed, k=16):
    from airspace_sim.world.autopilots import AutopilotContext

    class Spec:
        def __init__(self, pos, hdg, wps):
            self.position, self.heading_deg, self.waypoints = pos, hdg, wps

    rng = np.random.default_rng(seed)
    specs = []
    for a in range(k):
        nw = 0 if a == 0 else int(rng.integers(1, 5))
        specs.append(
            Spec(
                tuple(rng.uniform(-20000, 20000, 2)),
                rng.uniform(-180, 180),
                [tuple(rng.uniform(-20000, 20000, 2)) for _ in range(nw)],
            )
        )
    start = np.array([s.position for s in specs])
    ctx = AutopilotContext(dt=1.0, preset=None, keys=np.zeros(k, np.uint64), start_positions=start)
    members = np.arange(k)
    return RouteAutopilot(members, specs, ctx), RouteAutopilot(members, specs, ctx), start


def test_route_commands_and_capture_match_the_numpy_statements_bit_for_bit():
    fast, ref, pos = _route(5)
    k = pos.shape[0]
    rng = np.random.default_rng(6)
    heading = rng.uniform(-np.pi, np.pi, k)
    speeds = rng.uniform(150, 300, k)
    lim = np.radians(rng.choice([0.0, 3.0, 6.0], k))
    captured = 0
    for step in range(600):
        state = FlightState(pos, heading, speeds, lim, 1.0, step)
        rate, desired = fast.commands(state)
        want_d = ref.desired_heading(state)
        h, m = heading, lim
        want_r = np.clip(wrap_angle(want_d - h) / 1.0, -m, m)
        assert np.array_equal(_bits(desired), _bits(want_d))
        assert np.array_equal(_bits(rate), _bits(want_r))
        assert fast.turn_rate(state) is rate  # asked twice per state: computed once
        heading = wrap_angle(heading + rate + rng.normal(0, 0.05, k))
        pos = pos + speeds[:, None] * np.stack([np.cos(heading), np.sin(heading)], axis=1)
        after = FlightState(pos, heading, speeds, lim, 1.0, step)
        got_done = fast.after_step(after)
        want_done = ref.after_step_reference(after)
        captured += int((fast.index > 0).sum())
        assert np.array_equal(fast.index, ref.index)
        assert np.array_equal(got_done, want_done)
    assert captured and fast.done.any()


@pytest.mark.parametrize("name,overrides", [("ring", ["traffic.count=8"]), ("demo", [])])
def test_world_on_the_kernels_matches_the_numpy_motion(name, overrides):
    """The numpy motion (kept for recorded traffic) flies a world without recorded traffic
    exactly as the kernels do: the same positions, headings and velocities every step."""
    sc = load(name, overrides)
    a, b = World(sc, seed=3), World(sc, seed=3)
    b._one_route = None  # the per-group autopilot loop
    b._motion = b._motion_kinematic  # the numpy statement of the motion phase
    rng = np.random.default_rng(0)
    for _ in range(150):
        turn = rng.uniform(-1, 1, a.n) * a.max_turn_rate
        hr = np.where(a.controlled & (rng.random(a.n) < 0.7), turn, np.nan)
        a.step(hr)
        b.step(hr)
        for x, y in ((a.positions, b.positions), (a.headings, b.headings),
                     (a.velocities, b.velocities), (a.turn_rates, b.turn_rates)):  # fmt: skip
            assert np.array_equal(_bits(x), _bits(y))
    assert json.dumps(a.metrics(), default=str) == json.dumps(b.metrics(), default=str)


def test_agent_masks_match_the_numpy_masks():
    rng = np.random.default_rng(8)
    n = 300
    hr = rng.uniform(-0.1, 0.1, n)
    hr[rng.random(n) < 0.3] = np.nan
    controlled, avoid, moved = (rng.random((3, n)) < 0.5).astype(bool)
    agent, flies = np.empty(n, bool), np.empty(n, bool)
    assert not flight.agent_masks(hr, controlled, avoid, moved, agent, flies)
    want_agent = controlled & np.isfinite(hr)
    assert np.array_equal(agent, want_agent)
    assert np.array_equal(flies, avoid & ~moved & ~want_agent)
    hr[17] = -np.inf
    assert flight.agent_masks(hr, controlled, avoid, moved, agent, flies)


def test_a_subclass_desired_heading_is_still_flown():
    """RouteAutopilot.turn_rate uses the fused commands only for the class's own desired
    heading; a subclass that overrides it is steered toward its own."""

    class North(RouteAutopilot):
        def desired_heading(self, state):
            return np.full(self.members.size, np.pi / 2)

    fast, _, pos = _route(9, k=6)
    ap = North.__new__(North)
    ap.__dict__.update(fast.__dict__)
    state = FlightState(pos, np.zeros(6), np.full(6, 200.0), np.full(6, 0.05), 1.0, 0)
    assert np.array_equal(ap.turn_rate(state), np.full(6, 0.05))
