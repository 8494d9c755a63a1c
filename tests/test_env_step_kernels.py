"""The env step's fused kernels against the numpy statements they replace, bit for bit
(signed zeros included): the reward terms (env/rewards.py step_terms against severity,
step_bound, nmac_value and the column expressions), the observation finish (NaN -> 0, clip,
float32) and the route autopilot's route_state (against route_geometry and progress)."""

import numpy as np
import pytest

from airspace_sim.env import rewards as rw
from airspace_sim.env import spaces as sp
from airspace_sim.world.autopilots import AutopilotContext, RouteAutopilot


def _bits(a):
    a = np.ascontiguousarray(a)
    return a.view(np.uint64 if a.dtype == np.float64 else np.uint32)


def _numpy_terms(idx, wts, positions, li, lj, r_safe, d_nmac, nmac, conflict, turns, rates,
                 max_rate, speeds, dt, covered, before, planned, done, active, steps_left):  # fmt: skip
    """The env step's numpy statement of the terms (before the fused kernel)."""
    out = np.full(positions.shape[0], np.inf)
    if len(li):
        d = np.hypot(*(positions[li] - positions[lj]).T)
        np.minimum.at(out, li, d)
        np.minimum.at(out, lj, d)
    nearest = out[idx]
    L = planned[idx]
    has_route = L > 0
    Ls = np.where(has_route, L, 1.0)
    travel = np.where(has_route, speeds[idx] * dt / Ls, 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        turn = np.where(turns[idx], rates[idx] / max_rate[idx], 0.0)
    nm = nmac[idx]
    cols = {}
    cols["los"] = wts["los"] * -rw.severity(nearest, r_safe, d_nmac)
    if nm.any():
        c_max = rw.step_bound(wts, travel)
        value = np.where(nm, rw.nmac_value(wts, steps_left, c_max), 0)
    else:
        value = np.zeros(idx.size)
    cols["nmac"] = wts["nmac"] * value
    cols["conflict"] = wts["conflict"] * -conflict[idx].astype(float)
    cols["heading_change"] = wts["heading_change"] * -(turn**2)
    along = (covered - before)[idx] / Ls
    cols["progress"] = wts["progress"] * np.where(has_route, along, 0.0)
    cols["path"] = wts["path"] * np.where(has_route, along - travel, 0.0)
    cols["arrival"] = wts["arrival"] * done[idx].astype(float)
    weighted = np.stack([cols[t] for t in rw.TERMS], axis=1)
    return weighted, nearest, nm | done[idx] | ~active[idx]


@pytest.mark.parametrize("case", range(6))
def test_step_terms_match_the_numpy_statement_bit_for_bit(case):
    rng = np.random.default_rng(case)
    n = 40
    positions = rng.uniform(-5000, 5000, (n, 2))
    pairs = np.array([(i, j) for i in range(n) for j in range(i + 1, n)])
    pick = pairs[rng.random(len(pairs)) < (0.0 if case == 0 else 0.02)]
    li, lj = pick[:, 0].copy(), pick[:, 1].copy()
    nmac = np.zeros(n, bool) if case in (0, 1) else rng.random(n) < 0.2
    max_rate = np.radians(rng.choice([0.0, 3.0], n))
    rates = rng.uniform(-1, 1, n) * max_rate
    planned = np.where(rng.random(n) < 0.3, 0.0, rng.uniform(1e4, 1e5, n))
    before = rng.uniform(0, 1e4, n)
    covered = before + rng.uniform(-50, 300, n)
    wts = rw.merge_weights(None if case % 2 else {"conflict": 0.3, "los": 0.0})
    idx = rng.permutation(n)[: 25 + case]
    args = (
        positions, li, lj, 3000.0, 150.0, nmac, rng.random(n) < 0.4, max_rate > 0, rates,
        max_rate, rng.uniform(100, 300, n), 1.0, covered, before, planned,
        rng.random(n) < 0.1, rng.random(n) < 0.9, int(rng.integers(-3, 400)),
    )  # fmt: skip
    want, want_near, want_ended = _numpy_terms(idx, wts, *args)
    got = np.empty((idx.size, len(rw.TERMS)))
    near, ended = np.empty(idx.size), np.empty(idx.size, bool)
    weights = np.array([wts[t] for t in rw.TERMS])
    rw.step_terms(idx, weights, *args, got, near, ended)
    assert np.array_equal(_bits(got), _bits(want))
    assert np.array_equal(_bits(near), _bits(want_near))
    assert np.array_equal(ended, want_ended)
    if case >= 2:  # the NMAC column is exercised
        assert (got[:, 1] < 0).any()


def test_finish_matches_numpy_clip_and_cast_bit_for_bit():
    layout = sp.ObservationLayout(3, 3, 40000.0, 3000.0, 120.0)
    low, high = layout.bounds()
    rng = np.random.default_rng(7)
    obs = rng.uniform(-3, 3, (9, layout.size))
    special = np.array([np.nan, np.inf, -np.inf, 0.0, -0.0, 1.0, -1.0, 1e-40])
    obs.flat[rng.integers(0, obs.size, 200)] = rng.choice(special, 200)
    obs[0] = -0.0  # signed zeros against every bound
    obs[1] = 0.0
    want = obs.copy()
    want[np.isnan(want)] = 0.0
    want = np.clip(want, low, high).astype(np.float32)
    before = obs.copy()
    got = sp.finish_in_place(layout, obs)
    assert got.dtype == np.float32
    assert np.array_equal(_bits(got), _bits(want))
    assert np.array_equal(_bits(obs), _bits(before))


def _route_autopilot(rng, k=12):
    class Spec:
        def __init__(self, pos, hdg, wps):
            self.position, self.heading_deg, self.waypoints = pos, hdg, wps

    specs = []
    for a in range(k):
        nw = 0 if a == 0 else int(rng.integers(1, 4))
        wps = [tuple(rng.uniform(-30000, 30000, 2)) for _ in range(nw)]
        if a == 1:
            wps = [(0.0, 0.0), (0.0, 0.0)]  # a zero-length leg
        specs.append(Spec(tuple(rng.uniform(-30000, 30000, 2)), rng.uniform(-180, 180), wps))
    start = np.array([s.position for s in specs])
    ctx = AutopilotContext(dt=1.0, preset=None, keys=np.zeros(k, np.uint64), start_positions=start)
    return RouteAutopilot(np.arange(k), specs, ctx), start


def test_route_state_matches_route_geometry_and_progress_bit_for_bit():
    from airspace_sim.world.autopilots import FlightState

    rng = np.random.default_rng(3)
    ap, pos = _route_autopilot(rng)
    pos = pos.copy()
    heading = rng.uniform(-np.pi, np.pi, pos.shape[0])
    speeds = np.full(pos.shape[0], 250.0)
    seen_done = False
    for step in range(400):
        state = FlightState(pos, heading, speeds, np.full(pos.shape[0], 0.05), 1.0, step)
        got = ap.route_state(state)
        want = ap.route_geometry(state) + (ap.progress(state),)
        for g, w in zip(got, want):
            assert g.dtype == w.dtype and g.shape == w.shape
            assert np.array_equal(g.view(np.uint8), w.view(np.uint8))
        seen_done |= bool(got[1].any())
        # fly toward the target with some noise, so that waypoints get captured
        h = ap.desired_heading(state) + rng.normal(0, 0.2, pos.shape[0])
        heading = np.where(np.isfinite(h), h, heading)
        pos = pos + 250.0 * np.stack([np.cos(heading), np.sin(heading)], axis=1)
        ap.after_step(FlightState(pos, heading, speeds, np.full(pos.shape[0], 0.05), 1.0, step))
    assert seen_done


@pytest.mark.parametrize("case", range(4))
def test_intruders_into_matches_the_batch_encoding_bit_for_bit(case):
    rng = np.random.default_rng(10 + case)
    A, T = 5, (0, 3, 40, 60)[case]
    x = rng.normal(0, 10000, (T, 5))
    x[:, [1, 3]] = rng.normal(0, 200, (T, 2))
    if T:
        x[rng.random(T) < 0.15, rng.integers(0, 4)] = np.nan  # ignored tracks
        x[1] = x[0]  # a tie in range: by track order
    B = rng.normal(size=(T, 5, 5))
    P = B @ B.transpose(0, 2, 1) * 1e4
    mu = rng.dirichlet([1, 1, 1], T)
    slot = rng.integers(0, A - 1, T)  # the last ownship has no track
    if T:
        slot[1] = slot[0]
    own_pos = rng.normal(0, 1000, (A, 2))
    own_vel = rng.normal(0, 200, (A, 2))
    hd = rng.uniform(-np.pi, np.pi, A)
    lay = sp.ObservationLayout(3, 3, 40000.0, 3000.0, 120.0)
    want = sp.encode_intruders_batch(lay, slot, own_pos, own_vel, hd, x, P, mu)
    obs = np.full((A, lay.size), 7.0)  # the own block is left alone, the rest overwritten
    sp.encode_intruders_into(lay, slot, own_pos, own_vel, hd, x, P, mu, obs)
    assert np.all(obs[:, : lay.own_size] == 7.0)
    got = obs[:, lay.own_size :].reshape(A, 3, -1)
    assert np.array_equal(_bits(got), _bits(want))
    if T >= 40:
        assert (got[:, :, 0] == 1).sum() == 3 * (A - 1)  # K rows kept per tracked ownship


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_fractions_and_turn_rates_match_clip_and_scatter_bit_for_bit(dtype):
    rng = np.random.default_rng(20)
    raw = rng.uniform(-3, 3, 300).astype(dtype)
    raw[:6] = [-0.0, 0.0, 1.0, -1.0, 2.0, -2.0]
    out = np.empty(raw.size)
    assert sp.fractions_into(raw, out)
    want = np.clip(raw.astype(np.float64), -1.0, 1.0)
    assert np.array_equal(_bits(out), _bits(want))
    for bad in (np.nan, np.inf, -np.inf):
        raw[7] = bad
        assert not sp.fractions_into(raw, np.empty(raw.size))
    n = 40
    idx = rng.permutation(n)[:25]
    frac, max_rate = want[:25].copy(), np.radians(rng.choice([0.0, 3.0], n))
    frac[3] = np.nan  # this agent leaves the step to the built-in pilot
    rates = np.full(n, 5.0)
    sp.turn_rates_into(frac, idx, max_rate, rates)
    want_rates = np.full(n, np.nan)
    want_rates[idx] = frac * max_rate[idx]
    assert np.array_equal(_bits(rates), _bits(want_rates))


def test_half_precision_actions_take_the_one_by_one_path_with_the_same_values():
    """numba has no float16: such actions are decoded one by one, to the same fractions."""
    import airspace_sim.env as aenv

    env = aenv.make("ring4")
    env.reset(seed=0)
    acts = {a: np.array([v], np.float16) for a, v in zip(env.agents, [-3.0, -0.0, 0.5, 1.5])}
    frac = env._decode(list(env.agents), acts)
    assert frac.tolist() == [-1.0, -0.0, 0.5, 1.0] and np.signbit(frac[1])
    wide = {a: v.astype(np.float32) for a, v in acts.items()}
    assert np.array_equal(_bits(env._decode(list(env.agents), wide)), _bits(frac))


def test_relative_bearings_are_numpys_wrap_angle_bit_for_bit():
    from airspace_sim.geometry import wrap_angle
    from airspace_sim.world.flight import relative_bearings

    rng = np.random.default_rng(30)
    n = 500
    bearing = rng.uniform(-np.pi, np.pi, n)
    bearing[:4] = [0.0, -0.0, np.pi, -np.pi]
    idx = rng.permutation(n)[:400]
    heading = rng.uniform(-np.pi, np.pi, idx.size)
    heading[:8] = [0.0, -0.0, np.pi, -np.pi, -np.pi, np.pi, 0.0, -0.0]
    got = np.empty(idx.size)
    relative_bearings(bearing, idx, heading, got)
    assert np.array_equal(_bits(got), _bits(wrap_angle(bearing[idx] - heading)))
