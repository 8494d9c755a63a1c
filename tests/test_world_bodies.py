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
from airspace_sim.world.bodies import LOS, NMAC, RANGE, Airspace


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
