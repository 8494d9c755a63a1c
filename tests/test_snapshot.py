"""World snapshots: typed, read-only copies; predictions and pairs against independent oracles."""

import numpy as np
import pytest

from airspace_sim.scenarios import load
from airspace_sim.world import World
from airspace_sim.world.snapshot import Snapshot, Tracks, snapshot


def rk4_turn(x, t_end, n=2000):
    """Position after flying state ``[x, vx, y, vy, Ω]`` as a coordinated turn for ``t_end``
    s, integrated numerically (RK4 on p' = v, v' = Ω × v): an oracle independent of the
    closed form."""
    w = x[4]

    def f(s):
        return np.array([s[2], s[3], -w * s[3], w * s[2]])

    s = np.array([x[0], x[2], x[1], x[3]], float)
    h = t_end / n
    for _ in range(n):
        k1 = f(s)
        k2 = f(s + h / 2 * k1)
        k3 = f(s + h / 2 * k2)
        k4 = f(s + h * k3)
        s = s + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return s[:2]


def test_fields_shapes_and_values_match_the_world():
    world = World(load("dense_random", ["traffic.count=12"]), seed=1)
    world.run(10)
    s = world.snapshot()
    assert isinstance(s, Snapshot) and isinstance(s.tracks, Tracks)
    n, p = world.n, len(world.tracks)
    assert p > 0 and s.n == n and len(s.tracks) == p
    assert s.ids == tuple(world.ids)
    for name in ("positions", "velocities", "headings", "speeds", "turn_rates", "max_turn_rate"):
        np.testing.assert_array_equal(getattr(s, name), getattr(world, name), err_msg=name)
    for name in ("active", "controlled", "avoid", "in_los", "nmac", "conflict", "advice"):
        np.testing.assert_array_equal(getattr(s, name), getattr(world, name), err_msg=name)
    np.testing.assert_array_equal(s.true_modes, world.modes)
    for name in ("owner", "intruder", "x", "P", "mu", "misses", "age"):
        np.testing.assert_array_equal(getattr(s.tracks, name), getattr(world.tracks.view(), name))
    assert s.tracks.x.shape == (p, 5) and s.tracks.P.shape == (p, 5, 5)
    assert s.tracks.mu.shape == (p, 3) and s.mode_names == ("straight", "left", "right")
    assert s.predicted.shape == (p, 6, 2)
    assert s.time == world.time and s.step == world.step_count == 10 and s.dt == world.dt
    assert s.r_safe == world.r_safe == world.scenario.separation.r_safe
    assert s.lookahead == world.scenario.resolver.lookahead
    assert snapshot(world, prediction_points=3).predicted.shape == (p, 3, 2)


def test_snapshot_is_a_read_only_copy():
    world = World(load("demo"))
    world.run(20)
    s = world.snapshot()
    before = s.positions.copy(), s.tracks.x.copy()
    for a in (s.positions, s.headings, s.active, s.tracks.x, s.tracks.owner, s.predicted):
        assert not a.flags.writeable
    with pytest.raises(ValueError):
        s.tracks.x[0, 0] = 0.0
    assert not np.shares_memory(s.positions, world.positions)
    world.run(5)  # the world goes on; the snapshot does not
    np.testing.assert_array_equal(s.positions, before[0])
    np.testing.assert_array_equal(s.tracks.x, before[1])
    assert s.step == 20


def test_predicted_positions_fly_the_estimated_turn():
    world = World(load("demo"))
    world.run(40)
    s = world.snapshot()
    assert len(s.tracks) > 3
    times = s.lookahead * np.arange(1, 7) / 6
    turning = 0
    for row in range(0, len(s.tracks), max(1, len(s.tracks) // 6)):
        x = s.tracks.x[row]
        turning += abs(x[4]) > 1e-4
        for k, t in enumerate(times):
            np.testing.assert_allclose(s.predicted[row, k], rk4_turn(x, t), atol=1e-3)
    assert turning  # the check covers turning tracks, not only straight ones


def test_pairs_are_the_aircraft_closer_than_the_distances():
    world = World(load("head_on", ["resolver.kind=none"]))
    seen = 0
    while not world.done and seen < 3:
        world.step()
        s = world.snapshot()
        d = np.hypot(*(s.positions[:, None] - s.positions[None, :]).transpose(2, 0, 1))
        i, j = np.triu_indices(s.n, 1)
        on = s.active[i] & s.active[j]
        los = {(a, b) for a, b, m in zip(i, j, on & (d[i, j] < s.r_safe)) if m}
        nmac = {(a, b) for a, b, m in zip(i, j, on & (d[i, j] < s.nmac_distance)) if m}
        assert {tuple(p) for p in s.los_pairs} == los
        assert {tuple(p) for p in s.nmac_pairs} == nmac
        seen += bool(nmac)
    assert seen  # the head-on pair did collide
