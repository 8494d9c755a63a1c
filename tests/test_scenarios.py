"""Scenario loading, validation, overrides and generated traffic."""

from __future__ import annotations

import dataclasses
import math
import re
import typing

import numpy as np
import pytest

from airspace_sim.errors import UserError
from airspace_sim.scenarios import available, build_aircraft, from_dict, load, loader, schema
from airspace_sim.scenarios.traffic import miss_distance, ring_min_radius

SHIPPED = ["paper_encounter", "head_on", "crossing", "overtaking", "ring", "dense_random", "demo"]


# --------------------------------------------------------------------------- shipped files


def test_all_required_scenarios_are_shipped():
    assert set(SHIPPED) <= set(available())


@pytest.mark.parametrize("name", sorted(set(available()) | set(SHIPPED)))
def test_shipped_scenario_loads_and_builds(name):
    sc = load(name)
    assert sc.name == name
    assert sc.source.endswith(f"{name}.toml")
    aircraft = build_aircraft(sc, np.random.default_rng(sc.seed))
    assert aircraft, "a scenario without aircraft"
    ids = [a.id for a in aircraft]
    assert len(set(ids)) == len(ids)
    assert sc.n_steps >= 1
    # Every aircraft starts separated from every other (no loss of separation at t = 0).
    pos = np.array([a.position for a in aircraft])
    d = np.hypot(*(pos[:, None] - pos[None]).transpose(2, 0, 1))
    np.fill_diagonal(d, np.inf)
    assert d.min() > sc.separation.r_safe


def test_load_by_path_equals_load_by_name():
    sc = load("head_on")
    by_path = load(loader.resolve("head_on"))
    assert dataclasses.replace(by_path, source=sc.source) == sc


def test_paper_encounter_matches_the_paper():
    sc = load("paper_encounter")
    assert sc.dt == pytest.approx(0.1)
    assert sc.separation.r_safe == 3000.0
    assert sc.model == "seed" and sc.tracker.model == "seed"
    v = 285.841
    for seed in range(20):
        own, intruder = build_aircraft(sc, np.random.default_rng(seed))
        assert own.speed == pytest.approx(v)
        assert v <= intruder.speed <= 2 * v
        rel = np.subtract(intruder.position, own.position)
        assert np.hypot(*rel) == pytest.approx(4500.0)

        def vel(a):
            h = math.radians(a.heading_deg)
            return a.speed * np.array([math.cos(h), math.sin(h)])

        d, t_cpa = miss_distance(rel, vel(intruder) - vel(own))
        assert d < 3000.0 and t_cpa > 0
        assert intruder.autopilot == "markov" and not intruder.avoid


# --------------------------------------------------------------------------- schema-derived checks


def test_range_table_names_existing_fields():
    for key in loader.RANGES:
        cls_name, field = key.split(".")
        cls = getattr(schema, cls_name)
        assert field in {f.name for f in dataclasses.fields(cls)}, key


def test_every_schema_field_type_is_supported():
    for cls in (
        schema.Scenario,
        schema.Separation,
        schema.SensorSpec,
        schema.TrackerSpec,
        schema.ResolverSpec,
        schema.AircraftSpec,
        schema.TrafficSpec,
    ):
        for name, tp in typing.get_type_hints(cls, vars(schema)).items():
            assert loader.describe(tp), (cls.__name__, name)


def test_defaults_round_trip():
    sc = from_dict({"name": "x"})
    assert sc == schema.Scenario(name="x")


def _write(tmp_path, text, name="bad.toml"):
    p = tmp_path / name
    p.write_text(text)
    return p


BASE = 'name = "t"\n'
AIRCRAFT = """
[[aircraft]]
id = "a"
position = [0.0, 0.0]
heading_deg = 0.0
speed = 200.0

[[aircraft]]
id = "b"
position = [10000.0, 0.0]
heading_deg = 180.0
speed = {speed}
"""


@pytest.mark.parametrize(
    "text, key, value, expect",
    [
        (BASE + "[traffic]\ncount = -3\n", "traffic.count", "-3", "non-negative integer"),
        (BASE + "[traffic]\ncout = 3\n", "traffic.cout", "3", "unknown key"),
        (BASE + "dt = 'fast'\n", "dt", "'fast'", "a number ≥ 0.001"),
        (BASE + "dt = 0\n", "dt", "0", "a number ≥ 0.001"),
        (
            BASE + "[sensor]\ndetection_probability = 1.5\n",
            "sensor.detection_probability",
            "1.5",
            "[0, 1]",
        ),
        (BASE + "[sensor]\nrange = true\n", "sensor.range", "true", "positive number"),
        (BASE + "[traffic]\npattern = 'spiral'\n", "traffic.pattern", "'spiral'", "one of"),
        (BASE + "model = 'nope'\n", "model", "'nope'", "one of"),
        (BASE + "[separation]\nr_safe = nan\n", "separation.r_safe", "nan", "positive number"),
        (
            BASE + AIRCRAFT.format(speed="-1.0"),
            "aircraft[1].speed",
            "-1.0",
            "a number ≥ 1 up to 1000 (m/s)",
        ),
        (BASE + AIRCRAFT.format(speed='"x"'), "aircraft[1].speed", "'x'", "a number ≥ 1"),
        (
            BASE + AIRCRAFT.format(speed="1.0") + "color = 'red'\n",
            "aircraft[1].color",
            "'red'",
            "unknown key",
        ),
        (BASE + "separation = 5\n", "separation", "5", "table"),
        (BASE + "[resolver]\nsearch_deg = 270\n", "resolver.search_deg", "270", "(0, 180]"),
        (
            BASE + "[resolver]\nturn_preference = 'left'\n",
            "resolver.turn_preference",
            "'left'",
            "one of",
        ),
        (
            BASE + "[[aircraft]]\nid = 'a'\nposition = [0, 0, 0]\nheading_deg = 0\nspeed = 1\n",
            "aircraft[0].position",
            "[0, 0, 0]",
            "list of 2 numbers",
        ),
    ],
)
def test_bad_value_gives_one_line_with_file_key_value(tmp_path, text, key, value, expect):
    path = _write(tmp_path, text)
    with pytest.raises(UserError) as info:
        load(path)
    msg = str(info.value)
    assert "\n" not in msg
    assert msg.startswith(f"{loader.display_path(path)}: {key}: "), msg
    assert value in msg and expect in msg, msg


def test_missing_required_key(tmp_path):
    path = _write(tmp_path, BASE + "[[aircraft]]\nid = 'a'\nposition = [0, 0]\nheading_deg = 0\n")
    with pytest.raises(UserError, match=r"aircraft\[0\]\.speed: missing"):
        load(path)


def test_unknown_key_suggests_the_closest(tmp_path):
    path = _write(tmp_path, BASE + "[sensor]\nsigam = 3\n")
    with pytest.raises(UserError, match="did you mean 'sigma'"):
        load(path)


@pytest.mark.parametrize(
    "text, line, col",
    [
        ('name = "t"\ndt = 1.0\n[traffic\ncount = 3\n', 3, None),
        ('name = "t"\ndt = = 2\n', 2, 6),
        ('name = "t"\nx = [1, 2\n', 3, None),
    ],
)
def test_malformed_toml_names_line_and_column(tmp_path, text, line, col):
    path = _write(tmp_path, text)
    with pytest.raises(UserError) as info:
        load(path)
    msg = str(info.value)
    assert "\n" not in msg
    assert msg.startswith(f"{loader.display_path(path)}: invalid TOML at line {line}, column "), msg
    if col is not None:
        assert f"column {col}:" in msg


@pytest.mark.parametrize(
    "text, key",
    [
        (BASE + "[traffic]\npattern = 'ring'\ncount = 2\ncontrolled = 3\n", "traffic.controlled"),
        (BASE + "dt = 0.3\n[sensor]\nperiod = 1.0\n", "sensor.period"),
        (BASE + "[separation]\nnmac = 4000\n", "separation.nmac"),
        (BASE + "[traffic]\npattern = 'ring'\n", "traffic.count"),
        (BASE + "[traffic]\ncount = 4\n", "traffic.pattern"),
        (BASE + "[traffic]\npattern = 'encounter'\ncount = 1\n", "traffic.pattern"),
        (BASE + AIRCRAFT.format(speed="1.0").replace('id = "b"', 'id = "a"'), "aircraft[1].id"),
    ],
)
def test_cross_field_checks(tmp_path, text, key):
    path = _write(tmp_path, text)
    with pytest.raises(UserError) as info:
        load(path)
    assert str(info.value).startswith(f"{loader.display_path(path)}: {key}: "), info.value


def test_sensor_period_multiple_of_dt_with_float_rounding():
    sc = from_dict({"name": "x", "dt": 0.1, "sensor": {"period": 0.3}})
    assert sc.sensor.period == pytest.approx(0.3)


def test_unknown_scenario_name_lists_known():
    with pytest.raises(UserError, match=r"unknown scenario 'nope' \(known: .*head_on"):
        load("nope")
    with pytest.raises(UserError, match="no such scenario file"):
        load("missing/dir/x.toml")


# --------------------------------------------------------------------------- overrides


def test_overrides_apply_before_validation():
    sc = load(
        "ring",
        [
            "traffic.count=64",
            "traffic.radius=70000",
            "sensor.kind=radar",
            "resolver.params.left_penalty=0.1",
            "duration=10",
        ],
    )
    assert sc.traffic.count == 64 and sc.traffic.radius == 70000.0
    assert isinstance(sc.traffic.radius, float)
    assert sc.resolver.params == {**load("ring").resolver.params, "left_penalty": 0.1}
    assert sc.duration == 10.0
    assert len(build_aircraft(sc, np.random.default_rng(0))) == 64
    # the file itself is untouched
    assert load("ring").traffic.count == 32


def test_override_list_index_and_list_value():
    sc = load("head_on", ["aircraft[1].speed=150", "aircraft[0].waypoints=[[1, 2], [3, 4]]"])
    assert sc.aircraft[1].speed == 150.0
    assert sc.aircraft[0].waypoints == [(1.0, 2.0), (3.0, 4.0)]


@pytest.mark.parametrize(
    "override, start",
    [
        (
            "traffic.count=abc",
            "--set traffic.count: expected a non-negative integer up to 100000, got 'abc'",
        ),
        (
            "traffic.count=-3",
            "--set traffic.count: expected a non-negative integer up to 100000, got -3",
        ),
        ("traffic.cout=3", "--set traffic.cout: unknown key"),
        ("trafic.count=3", "--set trafic: unknown key"),
        (
            "sensor.detection_probability=2",
            "--set sensor.detection_probability: expected a probability",
        ),
        ("aircraft[5].speed=3", "--set aircraft[5].speed: index 5 out of range"),
        ("dt.x=3", "--set dt.x: dt is not a table"),
        ("traffic.count", "--set traffic.count: expected key=value"),
        ("traffic..count=3", "--set traffic..count: malformed key"),
        (
            "separation={r_safe = -1}",
            "--set separation.r_safe: expected a positive number up to 1e+06 (m), got -1",
        ),
    ],
)
def test_bad_override_is_reported_as_set(override, start):
    with pytest.raises(UserError) as info:
        load("head_on", [override])
    msg = str(info.value)
    assert "\n" not in msg
    assert msg.startswith(start), msg


def test_file_error_still_names_file_when_overrides_are_fine(tmp_path):
    path = _write(tmp_path, BASE + "[traffic]\ncount = -3\n")
    with pytest.raises(UserError, match=r"^.*bad\.toml: traffic\.count"):
        load(path, ["dt=2"])


# --------------------------------------------------------------------------- generated traffic


def _ring(count=12, radius=30000.0, r_safe=3000.0, **traffic):
    return from_dict(
        {
            "name": "r",
            "separation": {"r_safe": r_safe},
            "traffic": {"pattern": "ring", "count": count, "radius": radius, **traffic},
        }
    )


def test_ring_geometry_closed_form():
    n, R = 12, 30000.0
    ac = build_aircraft(_ring(n, R), np.random.default_rng(0))
    assert [a.id for a in ac] == [f"ring{i:02d}" for i in range(n)]
    pos = np.array([a.position for a in ac])
    np.testing.assert_allclose(np.hypot(pos[:, 0], pos[:, 1]), R)
    angles = np.unwrap(np.arctan2(pos[:, 1], pos[:, 0]))
    np.testing.assert_allclose(np.diff(angles), 2 * np.pi / n)
    chords = np.hypot(*(pos - np.roll(pos, -1, axis=0)).T)
    np.testing.assert_allclose(chords, 2 * R * math.sin(math.pi / n))
    for a, p in zip(ac, pos, strict=True):
        h = math.radians(a.heading_deg)
        to_centre = -p / np.hypot(*p)
        np.testing.assert_allclose([math.cos(h), math.sin(h)], to_centre, atol=1e-12)
        np.testing.assert_allclose(a.waypoints, [-p], atol=1e-9)
        assert a.autopilot == "route" and a.speed == 230.0


def test_ring_spacing_check_gives_minimum_radius():
    r_min = ring_min_radius(32, 3000.0)
    assert r_min == pytest.approx(3000.0 / math.sin(math.pi / 32))
    build_aircraft(_ring(32, r_min), 0)  # exactly at the limit is fine
    with pytest.raises(UserError) as info:
        build_aircraft(_ring(32, 20000.0), 0)
    msg = str(info.value)
    assert "traffic.radius" in msg and f"{math.ceil(r_min)} m" in msg and "20000" in msg


def test_ring_speed_spread_and_controlled():
    sc = _ring(16, 40000.0, speed=230.0, speed_spread=20.0, controlled=3)
    ac = build_aircraft(sc, np.random.default_rng(1))
    speeds = np.array([a.speed for a in ac])
    assert np.all((speeds >= 210.0) & (speeds <= 250.0)) and speeds.std() > 0
    assert [a.controlled for a in ac] == [True] * 3 + [False] * 13


def _random(count=40, sector=60000.0, r_safe=3000.0, aircraft=()):
    return from_dict(
        {
            "name": "s",
            "separation": {"r_safe": r_safe},
            "aircraft": list(aircraft),
            "traffic": {"pattern": "random", "count": count, "sector": sector},
        }
    )


def test_random_traffic_respects_separation_and_sector():
    hand = {"id": "me", "position": [0.0, 0.0], "heading_deg": 0.0, "speed": 200.0}
    sc = _random(40, 60000.0, aircraft=[hand])
    for seed in range(5):
        ac = build_aircraft(sc, np.random.default_rng(seed))
        assert len(ac) == 41 and ac[0].id == "me"
        pos = np.array([a.position for a in ac])
        d = np.hypot(*(pos[:, None] - pos[None]).transpose(2, 0, 1))
        np.fill_diagonal(d, np.inf)
        assert d.min() > 3000.0
        assert np.all(np.abs(pos) <= 30000.0)
        for a in ac[1:]:
            ((wx, wy),) = a.waypoints
            assert math.isclose(max(abs(wx), abs(wy)), 30000.0)  # on the sector's edge
            assert math.hypot(wx - a.position[0], wy - a.position[1]) >= 30000.0
            h = math.radians(a.heading_deg)
            direction = np.array([wx - a.position[0], wy - a.position[1]])
            np.testing.assert_allclose([math.cos(h), math.sin(h)], direction / np.hypot(*direction))


def test_random_traffic_is_seeded():
    sc = _random()
    a = build_aircraft(sc, np.random.default_rng(3))
    b = build_aircraft(sc, np.random.default_rng(3))
    c = build_aircraft(sc, np.random.default_rng(4))
    assert a == b and a != c


def test_random_traffic_too_dense_is_a_user_error():
    with pytest.raises(UserError, match="cannot place 100 aircraft"):
        build_aircraft(_random(100, 10000.0), 0)


def test_generated_id_clash_is_a_user_error():
    hand = {"id": "ring00", "position": [0.0, 0.0], "heading_deg": 0.0, "speed": 200.0}
    # refused by the loader, before any traffic is generated
    with pytest.raises(UserError, match=r"aircraft\[0\]\.id: .*generated ring.*'ring00'"):
        from_dict(
            {
                "name": "x",
                "aircraft": [hand],
                "traffic": {"pattern": "ring", "count": 4, "radius": 20000.0},
            }
        )


def test_build_does_not_share_hand_placed_objects():
    sc = load("head_on")
    ac = build_aircraft(sc, 0)
    ac[0].waypoints.append((1.0, 1.0))
    ac[0].speed = 1.0
    assert sc.aircraft[0].speed == 230.0 and len(sc.aircraft[0].waypoints) == 1


def test_random_traffic_spawn_clear_s_keeps_every_pair_apart_for_that_long():
    sc = from_dict(
        {
            "name": "x",
            "traffic": {"pattern": "random", "count": 40, "sector": 80000.0, "spawn_clear_s": 90.0},
        }
    )
    aircraft = build_aircraft(sc, np.random.default_rng(3))
    p = np.array([a.position for a in aircraft])
    h = np.radians([a.heading_deg for a in aircraft])
    v = np.array([a.speed for a in aircraft])[:, None] * np.stack([np.cos(h), np.sin(h)], 1)
    # brute force over a fine time grid (the generator uses the closed-form CPA)
    t = np.arange(0.0, 90.0 + 1e-9, 0.05)[:, None, None]
    pos = p[None] + t * v[None]  # (T, N, 2)
    d = np.linalg.norm(pos[:, :, None] - pos[:, None, :], axis=-1)
    i, j = np.triu_indices(len(aircraft), 1)
    assert d[:, i, j].min() > sc.separation.r_safe
    # without it, the same traffic density does start pairs in near-term conflict
    plain = build_aircraft(
        dataclasses.replace(sc, traffic=dataclasses.replace(sc.traffic, spawn_clear_s=0.0)),
        np.random.default_rng(3),
    )
    p0 = np.array([a.position for a in plain])
    h0 = np.radians([a.heading_deg for a in plain])
    v0 = np.array([a.speed for a in plain])[:, None] * np.stack([np.cos(h0), np.sin(h0)], 1)
    pos0 = p0[None] + t * v0[None]
    d0 = np.linalg.norm(pos0[:, :, None] - pos0[:, None, :], axis=-1)
    assert d0[:, i, j].min() < sc.separation.r_safe


def test_random_traffic_spawn_clear_s_impossible_is_a_user_error():
    sc = from_dict(
        {
            "name": "x",
            "traffic": {
                "pattern": "random",
                "count": 60,
                "sector": 30000.0,
                "spawn_clear_s": 600.0,
            },
        }
    )
    with pytest.raises(UserError, match=r"traffic\.spawn_clear_s.*600"):
        build_aircraft(sc, np.random.default_rng(0))


# --------------------------------------------------------------------------- one validation pass

TWO = [
    {"id": "a", "position": [0.0, 0.0], "heading_deg": 0.0, "speed": 200.0},
    {"id": "b", "position": [9000.0, 0.0], "heading_deg": 180.0, "speed": 200.0},
]


def _with(path: str, value):
    """A valid two-aircraft scenario table with ``path`` (dotted, ``aircraft[i].x``) set."""
    import copy

    data = {"name": "v", "aircraft": copy.deepcopy(TWO)}
    *head, last = path.replace("]", "").replace("[", ".").split(".")
    node = data
    for key in head:
        node = node[int(key)] if key.isdigit() else node.setdefault(key, {})
    node[last] = value
    return data


@pytest.mark.parametrize(
    "path,value,expected",
    [
        ("dt", math.nan, "dt: expected a number ≥ 0.001 up to 60 (s), got nan"),
        ("dt", math.inf, "dt: expected a number ≥ 0.001 up to 60 (s), got inf"),
        ("dt", 0.0, "dt: expected a number ≥ 0.001 up to 60 (s), got 0.0"),
        ("dt", 5e-324, "dt: expected a number ≥ 0.001 up to 60 (s), got 5e-324"),
        ("aircraft[1].id", "a", "aircraft[1].id: duplicate aircraft id, got 'a'"),
        (
            "aircraft[0].position",
            [math.inf, 0.0],
            "aircraft[0].position[0]: expected a finite number, got inf",
        ),
        ("aircraft[0].position", [1e200, 0.0], "aircraft[0].position: expected coordinates"),
        ("aircraft[0].speed", -1.0, "aircraft[0].speed: expected a number ≥ 1 up to 1000 (m/s)"),
        ("aircraft[0].speed", 1e308, "aircraft[0].speed: expected a number ≥ 1 up to 1000"),
        ("aircraft[0].max_turn_rate_deg", -1.0, "max_turn_rate_deg: expected a non-negative"),
        ("sensor.sigma", -1.0, "sensor.sigma: expected a non-negative number up to 100000 (m)"),
        ("sensor.sigma", 1e308, "sensor.sigma: expected a non-negative number"),
        ("sensor.detection_probability", 1.5, "expected a probability in [0, 1], got 1.5"),
        ("sensor.period", 0.0, "sensor.period: expected a positive number"),
        ("sensor.period", 1.5, "sensor.period: expected a whole multiple of dt (1 s), got 1.5"),
        ("sensor.params.gain", 2.0, "sensor.params.gain: unknown key, got 2.0 (known: none"),
        ("tracker.params.q", 2.0, "tracker.params.q: unknown key"),
        ("resolver.turn_preference", "left", "expected one of right, nearest, none, got 'left'"),
        (
            "resolver.search_deg",
            0.0,
            "resolver.search_deg: expected a number of degrees in (0, 180]",
        ),
        ("resolver.search_deg", 181.0, "resolver.search_deg: expected a number of degrees"),
        ("resolver.confirm_s", -1.0, "resolver.confirm_s: expected a non-negative number"),
        ("resolver.side_memory_s", -1.0, "resolver.side_memory_s: expected a non-negative"),
        ("resolver.resume_decay_s", 0.0, "resolver.resume_decay_s: expected a positive number"),
        (
            "resolver.resume_margin_floor",
            2.0,
            "resolver.resume_margin_floor: expected at most resolver.resume_margin (1.5), got 2",
        ),
        ("resolver.resume_margin_floor", -0.1, "resolver.resume_margin_floor: expected a"),
        ("resolver.probability_samples", 0, "probability_samples: expected a positive integer"),
        ("resolver.probability_samples", 2**63 - 1, "expected a positive integer up to 1000"),
        ("resolver.lookahead", 1e308, "resolver.lookahead: expected a positive number up to 3600"),
        ("resolver.params.bogus", 1, "resolver.params.bogus: unknown key, got 1 (known: r_safe,"),
        ("resolver.params.left_penalty", "x", "resolver.params.left_penalty: expected a number"),
        ("resolver.params.resolution", -1.0, "resolver.params.resolution: expected a number in"),
        ("traffic.count", 10**9, "traffic.count: expected a non-negative integer up to 100000"),
        ("traffic.sector", 1e308, "traffic.sector: expected a positive number up to"),
    ],
)
def test_every_rule_is_one_line_naming_key_and_value(path, value, expected):
    with pytest.raises(UserError) as info:
        from_dict(_with(path, value), source="v.toml")
    msg = str(info.value)
    assert "\n" not in msg
    assert msg.startswith("v.toml: ") and expected in msg, msg


@pytest.mark.parametrize(
    "kind,params,expected",
    [
        ("bands-probabilistic", {"threshold": "x"}, "threshold: expected a number in (0, 1]"),
        (
            "bands-probabilistic",
            {"threshold": math.nan},
            "threshold: expected a number in (0, 1], got nan",
        ),
        ("bands-probabilistic", {"threshold": -5}, "threshold: expected a number in (0, 1]"),
        ("seed", {"horizon": 0}, "resolver.params.horizon: expected an integer in [1, 1000]"),
        ("seed", {"horizon": 2.5}, "resolver.params.horizon: expected an integer in [1, 1000]"),
        ("none", {"margin": -1.0}, "resolver.params.margin: expected a number in [0, 10]"),
    ],
)
def test_resolver_params_follow_the_resolvers_params(kind, params, expected):
    data = _with("resolver.kind", kind)
    data["resolver"]["params"] = params
    with pytest.raises(UserError, match=re.escape(expected)):
        from_dict(data, source="v.toml")


def test_resolver_params_filled_from_the_scenario_and_overridden():
    from airspace_sim.avoidance.resolvers import SeedResolver, build_resolver

    data = _with("resolver.kind", "seed")
    data["dt"] = 0.5
    data["separation"] = {"r_safe": 2000.0}
    data["resolver"]["params"] = {"horizon": 4}
    sc = from_dict(data)
    res = build_resolver(sc)
    assert isinstance(res, SeedResolver)
    assert res.params == SeedResolver.Params(r_safe=2000.0, dt=0.5, horizon=4)
    assert sc.resolver.params == {"horizon": 4}  # only what the user set, converted
    # an override wins over the scenario value; ints become the declared float
    data["resolver"]["params"] = {"r_safe": 1500}
    res = build_resolver(from_dict(data))
    assert res.params.r_safe == 1500.0 and isinstance(res.params.r_safe, float)
    # a scenario value outside the resolver's own range names the scenario key
    data = _with("resolver.kind", "seed")
    data["dt"] = 59.0
    data["duration"] = 600.0
    data["sensor"] = {"period": 59.0}
    sc = from_dict(data)  # 59 s fits the seed resolver's dt range (0, 60]
    assert build_resolver(sc).params.dt == 59.0


def test_a_scenario_value_outside_a_params_range_names_the_scenario_key():
    from airspace_sim import parts

    @dataclasses.dataclass(frozen=True)
    class Params:
        lookahead_s: float = parts.param(60.0, unit="s", gt=0, le=600)

    filled = {"lookahead_s": "resolver.lookahead"}
    with pytest.raises(loader.Invalid) as info:
        loader._check_params(Params, {"lookahead_s": 3000.0}, "resolver.params", filled)
    assert info.value.path == "resolver.lookahead"
    assert "expected a number in (0, 600] s, got 3000.0 for resolver.params.lookahead_s" in str(
        info.value
    )


def test_validated_params_are_picklable_and_json():
    import json
    import pickle

    data = _with("resolver.kind", "bands")
    data["resolver"]["params"] = {"left_penalty": 0, "model_turn": True}
    sc = from_dict(data)
    assert sc.resolver.params == {"left_penalty": 0.0, "model_turn": True}
    assert pickle.loads(pickle.dumps(sc)) == sc
    json.dumps(dataclasses.asdict(sc))


def test_signed_zero_spread_means_zero():
    data = _with("traffic.pattern", "ring")
    data["traffic"].update(count=4, radius=20000.0, speed_spread=-0.0)
    sc = from_dict(data)
    assert math.copysign(1.0, sc.traffic.speed_spread) == 1.0
    assert len(build_aircraft(sc, 0)) == 6


def test_validate_params_is_generic():
    from airspace_sim import parts

    @dataclasses.dataclass(frozen=True)
    class Params:
        sigma_accel: float | None = parts.param(None, unit="m/s²", ge=0, le=100)
        mode: str = parts.param("a", choices=("a", "b"))

    assert loader.validate_params(Params, {}, "tracker.params") == Params()
    assert loader.validate_params(Params, {"sigma_accel": 2}, "t").sigma_accel == 2.0
    with pytest.raises(
        UserError, match=r"^t\.sigma_accel: expected a number in \[0, 100\] m/s², got 1000000000.0"
    ):
        loader.validate_params(Params, {"sigma_accel": 1e9}, "t")
    with pytest.raises(UserError, match=r"^t\.mode: expected one of a, b, got 'c'"):
        loader.validate_params(Params, {"mode": "c"}, "t")
    with pytest.raises(UserError, match=r"^t\.x: unknown key, got 1 \(known: sigma_accel, mode\)"):
        loader.validate_params(Params, {"x": 1}, "t")


@pytest.mark.parametrize(
    "recorded, expected",
    [
        (
            {"velocity": "bogus"},
            "recorded.velocity: expected one of reported, positions, got 'bogus'",
        ),
        ({"centre_lat_deg": 47.0}, "recorded.centre_lon_deg: expected it with recorded.centre_lat"),
        ({"centre_lon_deg": 8.0}, "recorded.centre_lat_deg: expected it with recorded.centre_lon"),
        ({"centre_lat_deg": 91.0, "centre_lon_deg": 8.0}, "recorded.centre_lat_deg: expected a"),
        ({"max_gap_s": 0.0}, "recorded.max_gap_s: expected a positive number"),
        (
            {"min_altitude_ft": 5000.0, "max_altitude_ft": 1000.0},
            "recorded.max_altitude_ft: expected at least recorded.min_altitude_ft (5000 ft), "
            "got 1000",
        ),
    ],
)
def test_recorded_rules_are_the_loaders(recorded, expected):
    """Every rule of a [recorded] value is the loader's, at load time: the file (which does
    not exist) is never looked at; recorded/scenario.py checks only what needs the file."""
    from airspace_sim.recorded.scenario import load_flights

    data = {"name": "r", "recorded": {"file": "no-such.csv", **recorded}}
    with pytest.raises(UserError) as info:
        from_dict(data, source="r.toml")
    assert str(info.value).startswith("r.toml: ") and expected in str(info.value), info.value
    assert "\n" not in str(info.value)
    ok = from_dict({"name": "r", "recorded": {"file": "no-such.csv", "max_altitude_ft": 5000.0}})
    with pytest.raises(UserError, match=r"recorded\.file: no such file"):
        load_flights(ok.recorded)


def test_a_set_kind_starts_from_the_new_kinds_defaults(tmp_path):
    """--set resolver.kind=... drops the file's resolver.params (written for the file's
    kind); params set by the overrides still apply; the same kind keeps them."""
    path = tmp_path / "s.toml"
    path.write_text(
        '[resolver]\nkind = "bands-flown"\n[resolver.params]\nboxed_best_both = true\n'
        '[traffic]\npattern = "ring"\ncount = 4\nradius = 20000.0\n'
    )
    assert load(path).resolver.params == {"boxed_best_both": True}
    assert load(path, ['resolver.kind="bands-flown"']).resolver.params == {"boxed_best_both": True}
    assert load(path, ['resolver.kind="bands"']).resolver.params == {}
    both = load(path, ["resolver.params.left_penalty=0.1", 'resolver.kind="bands"'])
    assert both.resolver.kind == "bands" and both.resolver.params == {"left_penalty": 0.1}
    with pytest.raises(UserError, match="boxed_best_both: unknown key"):
        load(path, ["resolver.params={boxed_best_both = true}", 'resolver.kind="bands"'])
