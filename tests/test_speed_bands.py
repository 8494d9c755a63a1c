"""Speed as a second control ("bands-flown-speed", avoidance/speed_bands.py): the choice of
speed per candidate against a loop oracle, the resolver against the closed-form straight CPA
and against "bands-flown" when no speed change is allowed, the world flying the advised speed
within its limits, the protocol's capability check, and bad scenario values."""

import dataclasses
import math
import pickle

import numpy as np
import pytest
from _flight import K1

from airspace_sim import registry
from airspace_sim.avoidance.bands import CLEAR_TOLERANCE
from airspace_sim.avoidance.flown_bands import FlownBandsResolver
from airspace_sim.avoidance.speed_bands import SpeedFlownBandsResolver, speed_choice, speed_grid
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

RATE = math.radians(3.0)


def test_registered():
    cls = registry.get("resolver", "bands-flown-speed")
    assert cls is SpeedFlownBandsResolver and cls.advises_speed


def test_speed_grid_spans_the_limits():
    grid = speed_grid(np.array([[161.0, 299.0], [200.0, 200.0]]), 2)
    np.testing.assert_allclose(grid[0], [161.0, 195.5, 230.0, 264.5, 299.0])
    np.testing.assert_allclose(grid[1], 200.0)


def _choice_oracle(current_ratio, ratio, grid, current, margin):
    """speed_choice's rule written as a loop (module docstring of speed_bands)."""
    n, c, p = ratio.shape
    got_r, got_s = current_ratio.copy(), np.broadcast_to(current[:, None], (n, c)).copy()
    for i in range(n):
        for j in range(c):
            here = current_ratio[i, j]
            if not np.isfinite(here) or here >= 1.0 - CLEAR_TOLERANCE:
                continue
            clear = [q for q in range(p) if ratio[i, j, q] >= 1.0 - CLEAR_TOLERANCE]
            if clear:
                q = min(clear, key=lambda q: (abs(grid[i, q] - current[i]), q))
            else:
                q = max(range(p), key=lambda q: (ratio[i, j, q], -q))
                if not ratio[i, j, q] > here + margin:
                    continue
            got_r[i, j], got_s[i, j] = ratio[i, j, q], grid[i, q]
    return got_r, got_s


@pytest.mark.parametrize("seed", range(4))
def test_speed_choice_matches_the_loop_oracle(seed):
    rng = np.random.default_rng(seed)
    n, c, p = 30, 7, 5
    current = rng.uniform(180, 260, n)
    grid = speed_grid(np.stack([current * 0.8, current * 1.2], axis=1), 2)
    ratio = rng.uniform(0.3, 1.3, (n, c, p))
    current_ratio = rng.uniform(0.3, 1.3, (n, c))
    current_ratio[0, :2] = -np.inf  # unusable candidates stay so
    got = speed_choice(current_ratio, ratio, grid, current, 0.05)
    want = _choice_oracle(current_ratio, ratio, grid, current, 0.05)
    np.testing.assert_array_equal(got[0], want[0])
    np.testing.assert_array_equal(got[1], want[1])


def _random_scene(seed, n=80, k=5):
    rng = np.random.default_rng(seed)
    vo = rng.normal(size=(n, 2))
    vo *= rng.uniform(180, 260, (n, 1)) / np.linalg.norm(vo, axis=1, keepdims=True)
    r = rng.uniform(-15000, 15000, (n, k, 2))
    vi = rng.normal(size=(n, k, 2))
    vi *= rng.uniform(180, 260, (n, k, 1)) / np.linalg.norm(vi, axis=-1, keepdims=True)
    valid = (rng.random((n, k)) < 0.85) & (np.hypot(r[..., 0], r[..., 1]) > 3300.0)
    side = np.where(np.arange(n) % 3 == 0, 1.0, -1.0)
    side[np.arange(n) % 5 == 0] = 0.0
    return vo, r, vi - vo[:, None], valid, np.full(n, math.pi / 2), side


@pytest.mark.parametrize("seed", [0, 1])
def test_without_a_speed_range_it_is_bands_flown(seed):
    """Equal speed limits (heading only): every output of "bands-flown", the advised speed
    the current one."""
    vo, r, v, valid, mx, side = _random_scene(seed)
    n = vo.shape[0]
    here = np.hypot(vo[:, 0], vo[:, 1])
    base = FlownBandsResolver(FlownBandsResolver.Params(**K1)).resolve(
        vo, r, v, valid, mx, turn_rate=np.full(n, RATE), committed_side=side
    )
    out = SpeedFlownBandsResolver(SpeedFlownBandsResolver.Params(**K1)).resolve(
        vo,
        r,
        v,
        valid,
        mx,
        turn_rate=np.full(n, RATE),
        committed_side=side,
        speed_limits=np.stack([here, here], axis=1),
        max_acceleration=np.full(n, 0.5),
    )
    for name in ("heading_change", "conflict", "candidates", "min_ratio", "first_clear"):
        np.testing.assert_array_equal(getattr(out, name), getattr(base, name), err_msg=name)
    np.testing.assert_allclose(out.speed_target, here, rtol=1e-15)


@pytest.mark.parametrize("seed", [0, 1])
def test_speed_when_boxed_changes_speed_only_for_ownships_with_no_heading_clear(seed):
    """With ``speed_when_boxed`` a row with some heading clear as flown at its current speed
    is "bands-flown"'s row at the current speed; a row with none is the row of the resolver
    that always judges other speeds."""
    vo, r, v, valid, mx, side = _random_scene(seed, n=200, k=8)
    n = vo.shape[0]
    here = np.hypot(vo[:, 0], vo[:, 1])
    common = dict(turn_rate=np.full(n, RATE), committed_side=side)
    base = FlownBandsResolver(FlownBandsResolver.Params(**K1)).resolve(
        vo, r, v, valid, mx, **common
    )
    speed = dict(speed_limits=np.stack([0.8 * here, 1.2 * here], 1), max_acceleration=np.ones(n))

    def run(**knobs):
        params = SpeedFlownBandsResolver.Params(**K1, **knobs)
        return SpeedFlownBandsResolver(params).resolve(vo, r, v, valid, mx, **common, **speed)

    always, boxed_only = run(), run(speed_when_boxed=True)
    usable = ~np.isnan(base.candidates)
    boxed = base.conflict & ~np.any(usable & (base.min_ratio >= 1.0 - CLEAR_TOLERANCE), axis=1)
    assert 0 < boxed.sum() < base.conflict.sum()
    np.testing.assert_array_equal(boxed_only.heading_change[~boxed], base.heading_change[~boxed])
    np.testing.assert_array_equal(boxed_only.speed_target[~boxed], here[~boxed])
    np.testing.assert_array_equal(boxed_only.heading_change[boxed], always.heading_change[boxed])
    np.testing.assert_array_equal(boxed_only.speed_target[boxed], always.speed_target[boxed])
    assert np.any(boxed_only.speed_target[boxed] != here[boxed])


def _straight_ratio(vo_new, r, vi, lookahead):
    """Closed-form minimum distance / radius over [0, lookahead] of straight relative motion."""
    v = vi - vo_new
    t = np.clip(-(r @ v) / max(v @ v, 1e-300), 0.0, lookahead)
    return np.linalg.norm(r + t * v)


def test_a_speed_change_alone_clears_a_crossing_when_no_turn_is_allowed():
    """A 90° crossing, no heading change allowed (only ψ = 0), speed and heading taken at
    once: the advised speed is the grid speed nearest the current one whose closed-form CPA
    over the look-ahead clears r_safe·(1 + margin)."""
    p = SpeedFlownBandsResolver.Params(lookahead_s=120.0, speed_steps=6)
    vo = np.array([[230.0, 0.0]])
    r = np.array([[[26320.0, -26320.0]]])
    vi = np.array([0.0, 230.0])
    limits = np.array([[161.0, 299.0]])
    out = SpeedFlownBandsResolver(p).resolve(
        vo,
        r,
        (vi - vo)[:, None],
        np.ones((1, 1), bool),
        np.zeros(1),
        turn_rate=np.full(1, np.inf),
        committed_side=np.zeros(1),
        speed_limits=limits,
        max_acceleration=np.full(1, np.inf),
    )
    radius = p.r_safe * (1.0 + p.margin)
    grid = speed_grid(limits, p.speed_steps)[0]
    clear = [s for s in grid if _straight_ratio(np.array([s, 0.0]), r[0, 0], vi, 120.0) >= radius]
    want = min(clear, key=lambda s: abs(s - 230.0))
    assert out.conflict[0] and out.heading_change[0] == 0.0
    assert want != 230.0 and out.speed_target[0] == pytest.approx(want)


def test_protocol_refuses_advises_speed_without_its_keywords():
    from airspace_sim.parts import Resolver, check

    class NoSpeedArgs(FlownBandsResolver):
        advises_speed = True

        def resolve(self, own_velocity, rel_position, rel_velocity, valid, mx, **kw):
            return super().resolve(own_velocity, rel_position, rel_velocity, valid, mx)

    check("resolver", NoSpeedArgs, "ok-with-kwargs")  # **kw accepts them

    class Strict(Resolver):
        advises_speed = True

        def resolve(
            self,
            own_velocity,
            rel_position,
            rel_velocity,
            valid,
            mx,
            *,
            mode_predictions=None,
            turn_rate=None,
        ):
            return None

    with pytest.raises(UserError, match=r"with advises_speed, resolve\(\) must accept"):
        check("resolver", Strict, "strict")
    Strict.advises_speed = False
    check("resolver", Strict, "strict")  # without the flag the world never passes them


def _crossing(kind, speed_range=0.3, accel=2.0):
    """An ownship east at 230 m/s that may change speed, and a non-cooperative intruder
    north at 230 m/s, both reaching the origin at t ≈ 130 s."""
    return Scenario(
        name="t",
        seed=0,
        dt=1.0,
        duration=400.0,
        separation=Separation(r_safe=3000.0),
        sensor=SensorSpec(**{"range": 40000.0, "sigma": 50.0}),
        tracker=TrackerSpec(kind="imm"),
        resolver=ResolverSpec(kind=kind, lookahead=120.0),
        aircraft=[
            AircraftSpec(
                id="own",
                position=(-30000.0, 0.0),
                heading_deg=0.0,
                speed=230.0,
                autopilot="route",
                waypoints=[(40000.0, 0.0)],
                speed_range=speed_range,
                max_acceleration=accel,
            ),
            AircraftSpec(
                id="intruder",
                position=(0.0, -30000.0),
                heading_deg=90.0,
                speed=230.0,
                autopilot="route",
                waypoints=[(0.0, 40000.0)],
                avoid=False,
            ),
        ],
    )


def _fly(world, steps=None):
    speeds = []
    while not world.done and (steps is None or steps):
        world.step()
        speeds.append(world.speeds.copy())
        steps = None if steps is None else steps - 1
    return np.array(speeds)


def test_world_flies_the_advised_speed_within_its_limits():
    world = World(_crossing("bands-flown-speed"), seed=0)
    assert world.speed_controlled.tolist() == [True, False]
    speeds = _fly(world)
    own = speeds[:, 0]
    assert own.min() < 230.0 - 20.0  # it slowed down for the intruder ...
    assert own.min() >= 161.0 - 1e-9 and own.max() <= 299.0 + 1e-9  # ... within 230 ± 30 %
    steps = np.diff(np.concatenate([[230.0], own]))
    assert np.abs(steps).max() <= 2.0 * world.dt + 1e-9  # at 2 m/s² or less
    assert own[-1] == 230.0  # back to its own speed on its route
    np.testing.assert_array_equal(speeds[:, 1], 230.0)  # the intruder may not change speed
    m = world.metrics()
    assert m["los_pairs"] == 0 and m["min_separation_m"] > 3000.0
    # the delay is against its own speed: the slowed stretch costs time, not less
    assert m["arrival_delay_mean_s"] > 1.0


def test_world_without_a_speed_range_is_bands_flown_bit_for_bit():
    a = World(_crossing("bands-flown-speed", speed_range=0.0), seed=0)
    b = World(_crossing("bands-flown"), seed=0)
    assert not a.speed_controlled.any()
    _fly(a), _fly(b)
    np.testing.assert_array_equal(a.positions, b.positions)
    assert a.metrics() == b.metrics()


def test_a_world_pickled_while_slowed_continues_identically():
    world = World(_crossing("bands-flown-speed"), seed=0)
    speeds = _fly(world, steps=40)
    assert speeds[-1, 0] < 230.0
    copy = pickle.loads(pickle.dumps(world))
    _fly(world), _fly(copy)
    np.testing.assert_array_equal(world.positions, copy.positions)
    np.testing.assert_array_equal(world.speeds, copy.speeds)
    assert world.metrics() == copy.metrics()


def test_world_unpickles_a_checkpoint_from_before_speed_advice():
    world = World(_crossing("bands-flown"), seed=0)
    state = dict(world.__dict__)
    for key in ("nominal_speeds", "speed_range", "max_acceleration", "speed_controlled"):
        del state[key]
    policy = dict(world.policy.__dict__)
    for key in ("speed_target", "speed_limits", "max_acceleration"):
        del policy[key]
    world.policy.__dict__.clear()
    world.policy.__setstate__(policy)
    restored = World.__new__(World)
    restored.__setstate__(state)
    assert not restored.speed_controlled.any()
    assert np.isnan(restored.policy.speed_target).all()
    _fly(restored)
    assert restored.metrics()["los_pairs"] == 0


@pytest.mark.parametrize(
    "key, value, needle",
    [
        ("traffic.speed_range", "1.5", "traffic.speed_range"),
        ("traffic.max_acceleration", "0.0", "traffic.max_acceleration"),
        ("traffic.max_acceleration", "nan", "traffic.max_acceleration"),
    ],
)
def test_bad_speed_settings_are_one_line_errors(key, value, needle):
    from airspace_sim.scenarios import load

    with pytest.raises(UserError) as err:
        load("dense_random", [f"{key}={value}"])
    assert needle in str(err.value) and "\n" not in str(err.value)


def test_dense_traffic_with_a_speed_range_flies_it():
    """Generated traffic takes the speed range and acceleration of [traffic]."""
    from airspace_sim.scenarios import load

    sc = load(
        "dense_random",
        [
            "traffic.count=12",
            "duration=120.0",
            "traffic.speed_range=0.1",
            "traffic.max_acceleration=1.0",
            'resolver.kind="bands-flown-speed"',
        ],
    )
    world = World(dataclasses.replace(sc), seed=3)
    assert world.speed_controlled.all()
    nominal = world.nominal_speeds.copy()
    before = world.speeds.copy()
    changed = False
    while not world.done:
        world.step()
        live = world.active
        assert (np.abs(world.speeds - before)[live] <= 1.0 + 1e-9).all()
        assert (world.speeds[live] >= 0.9 * nominal[live] - 1e-9).all()
        assert (world.speeds[live] <= 1.1 * nominal[live] + 1e-9).all()
        changed |= bool((world.speeds != nominal)[live].any())
        before = world.speeds.copy()
    assert changed
