"""Safety metrics of World.metrics() (world/metrics.py) and the risk ratio (world/risk.py),
against closed forms on hand-made scenes and brute-force scalar re-computations."""

import math

import numpy as np
import pytest

from airspace_sim.scenarios import from_dict
from airspace_sim.scenarios.schema import (
    AircraftSpec,
    ResolverSpec,
    Scenario,
    SensorSpec,
    Separation,
    TrackerSpec,
)
from airspace_sim.tracking.keymap import KeyMap
from airspace_sim.world import World
from airspace_sim.world.bodies import LOS, NMAC, RANGE
from airspace_sim.world.metrics import (
    DMOD_M,
    HMD_M,
    TAU_MOD_S,
    WorldMetrics,
    pair_reach,
    pair_reaches,
)
from airspace_sim.world.risk import risk_ratio

FT = 0.3048


def scene(aircraft, resolver="none", duration=200.0, tracker="truth", lookahead=120.0):
    return Scenario(
        name="t",
        seed=0,
        dt=1.0,
        duration=duration,
        separation=Separation(r_safe=3000.0),
        sensor=SensorSpec(range=40000.0, sigma=50.0),
        tracker=TrackerSpec(kind=tracker),
        resolver=ResolverSpec(kind=resolver, lookahead=lookahead),
        aircraft=aircraft,
    )


def test_thresholds_are_do365_horizontal_values():
    assert DMOD_M == pytest.approx(4000 * FT) and HMD_M == pytest.approx(4000 * FT)
    assert TAU_MOD_S == 35.0


# ---------------------------------------------------------------- well clear
@pytest.mark.parametrize("offset", [0.0, 600.0, 1200.0, 1300.0, 2500.0])
def test_well_clear_violation_of_offset_head_on_pair_matches_closed_form(offset):
    # x(t) = 40000 − c·t along track, lateral offset b, closing speed c = 400 m/s, no turns.
    # τ_mod = (x² + b² − D²)/(c x) ≤ τ ⇔ x ≤ x_on = (τc + √(τ²c² − 4(b² − D²)))/2 (b ≤ HMD*),
    # and the violation lasts while x ≥ −√(D² − b²) (inside DMOD) — or, for b > DMOD, never.
    b, c, D, tau = offset, 400.0, DMOD_M, TAU_MOD_S
    sc = scene(
        [
            AircraftSpec(id="w", position=(-20000.0, 0.0), heading_deg=0.0, speed=200.0),
            AircraftSpec(id="e", position=(20000.0, b), heading_deg=180.0, speed=200.0),
        ]
    )
    m = World(sc).run()
    k = np.arange(sc.n_steps + 1)
    x = 40000.0 - c * k
    if b <= HMD_M and b <= D:
        x_on = (tau * c + math.sqrt(tau**2 * c**2 - 4 * (b**2 - D**2))) / 2
        expected = int(np.count_nonzero((x <= x_on) & (x >= -math.sqrt(D**2 - b**2))))
        assert expected > 20
    else:
        expected = 0
    assert m["wcv_duration_s"] == expected * 1.0
    assert m["wcv_events"] == m["wcv_pairs"] == (1 if expected else 0)


def _wcv_scalar(s, v, D=DMOD_M, H=HMD_M, T=TAU_MOD_S):
    """DAIDALUS WCV_TAUMOD.horizontal_WCV, written out scalar by scalar."""
    sx, sy = s
    vx, vy = v
    r2 = sx * sx + sy * sy
    if math.sqrt(r2) <= D:
        return True
    sdotv = sx * vx + sy * vy
    if sdotv >= 0:
        return False
    taumod = (D * D - r2) / sdotv
    t = -sdotv / (vx * vx + vy * vy)
    hmd = math.hypot(sx + t * vx, sy + t * vy)
    return 0 <= taumod <= T and hmd <= H


def test_well_clear_of_random_states_matches_scalar_definition():
    rng = np.random.default_rng(3)
    n = 40
    pos = rng.uniform(-8000, 8000, (n, 2))
    vel = rng.uniform(-250, 250, (n, 2))
    m = WorldMetrics(n, 3000.0, 152.4, 1.0)
    none = {t: np.zeros(0, np.int64) for t in (LOS, NMAC, RANGE)}
    began = {t: np.zeros((0, 2), np.int64) for t in (LOS, NMAC, RANGE)}
    m.contacts(pos, none, began)
    m.conflicts(np.zeros(n, bool))
    m.safety(0.0, pos, vel, np.ones(n, bool), np.zeros(n, bool), 120.0)
    expected = sum(
        _wcv_scalar(pos[j] - pos[i], vel[j] - vel[i]) for i in range(n) for j in range(i + 1, n)
    )
    assert 10 < expected < n * (n - 1) // 2
    assert m.wcv_events == expected


def _predicted_scalar(s, v, r_safe, lookahead):
    ww = v @ v
    t = min(max(-(s @ v) / ww, 0.0), lookahead) if ww > 0 else 0.0
    return math.hypot(*(s + t * v)) < r_safe


@pytest.mark.parametrize("look", [10.0, 60.0])
def test_pair_scan_over_many_grid_cells_matches_brute_force(look):
    # slow aircraft and a short look-ahead: cells ~2-3 km wide over a 30 km square, so
    # pairs straddle cells; every flag must match the scalar definitions over all pairs.
    # Well clear's reach is the larger with a 10 s look-ahead, the prediction's with 60 s
    rng = np.random.default_rng(5)
    n, r_safe = 300, 300.0
    pos = rng.uniform(-15000, 15000, (n, 2))
    vel = rng.uniform(-14, 14, (n, 2))
    following = rng.random(n) < 0.2
    active = rng.random(n) < 0.9
    wcv_reach, pred_reach = pair_reaches(np.hypot(*vel.T).max(), DMOD_M, TAU_MOD_S, r_safe, look)
    assert max(wcv_reach, pred_reach) < 3000 and (wcv_reach > pred_reach) == (look == 10.0)
    assert pair_reach(np.hypot(*vel.T).max(), DMOD_M, TAU_MOD_S, r_safe, look) == max(
        wcv_reach, pred_reach
    )
    m, wcv, pred = safety_and_brute_force(pos, vel, active, following, r_safe, look)
    assert len(wcv) > 20 and len(pred) > 5
    assert (
        m.wcv_events
        == m.wcv_pair_steps
        == len(wcv)
        == m.report(1, 0.0, np.zeros(n), np.zeros(n, bool))["wcv_pairs"]
    )
    assert set(m._wcv_prev.tolist()) == wcv
    assert len(m._predicted) == len(pred) and (m._predicted.get(sorted(pred)) >= 0).all()


@pytest.mark.parametrize("follow", [False, True])
def test_pair_scan_flags_pairs_at_the_edge_of_the_reach(follow):
    # head-on pairs of the fastest aircraft at the farthest distances each test can flag
    # (inside its reach by the reach's slack only), ∓ 2 m: a predicted conflict at
    # d = r_safe + look·2v, a well-clear violation at the positive root of
    # d² − τ·2v·d − DMOD² = 0 (τ_mod = τ*, HMD 0); and pairs on DMOD. The nearer pair of
    # each edge is flagged, the farther not. 44 aircraft, so the scan uses the grid; both
    # sets must be those of the scalar definitions over all pairs. With ``follow`` one
    # aircraft of each pair follows the policy: its pairs are never predicted, and their
    # well clear is scanned on the grid of well clear's own reach (the aircraft that do
    # not follow, on the prediction's)
    v, r_safe, look = 230.0, 3000.0, 120.0
    pred_edge = r_safe + look * 2 * v
    wcv_edge = 0.5 * (TAU_MOD_S * 2 * v + math.sqrt((TAU_MOD_S * 2 * v) ** 2 + 4 * DMOD_M**2))
    apart = [pred_edge - 2.0, pred_edge + 2.0, wcv_edge - 2.0, wcv_edge + 2.0]
    apart += [DMOD_M, DMOD_M + 1e-9, 1e4]
    pos, vel = [], []
    for k, d in enumerate(apart):
        y = 3e5 * k
        pos += [(0.0, y), (d, y)]
        vel += [(v, 0.0), (-v, 0.0)]
    rng = np.random.default_rng(11)
    for _ in range(30):  # traffic far from the pairs above, to get past the one-cell case
        pos.append((rng.uniform(5e5, 9e5), rng.uniform(0, 2e6)))
        vel.append(tuple(rng.uniform(-v, v, 2) / np.sqrt(2)))
    pos, vel = np.array(pos), np.array(vel)
    n = len(pos)
    wcv_reach, pred_reach = pair_reaches(np.hypot(*vel.T).max(), DMOD_M, TAU_MOD_S, r_safe, look)
    assert pred_edge < pred_reach < pred_edge + 100.0 and wcv_edge < wcv_reach < wcv_edge + 2
    active, following = np.ones(n, bool), np.zeros(n, bool)
    if follow:
        following[1 : 2 * len(apart) : 2] = True
        following[-8:] = True  # and some of the far traffic
    m, wcv, pred = safety_and_brute_force(pos, vel, active, following, r_safe, look)
    if follow:
        assert not pred & {2 * k * n + 2 * k + 1 for k in range(len(apart))}
    else:
        assert 0 * n + 1 in pred and 2 * n + 3 not in pred
    assert 4 * n + 5 in wcv and 6 * n + 7 not in wcv
    assert {8 * n + 9, 10 * n + 11, 12 * n + 13} <= wcv
    assert len(m._predicted) == len(pred) and (m._predicted.get(sorted(pred)) >= 0).all()
    assert set(m._wcv_prev.tolist()) == wcv


def test_metrics_of_a_sparse_2000_aircraft_world_hold_no_all_pairs_array():
    # 2000 aircraft over 1000 km: a few thousand pairs in the 40 km range out of ~2 million
    rng = np.random.default_rng(7)
    xy = rng.uniform(0.0, 1e6, (2000, 2))
    heading = rng.uniform(0.0, 360.0, 2000)
    craft = [
        AircraftSpec(id=f"a{k}", position=tuple(p), heading_deg=float(h), speed=230.0)
        for k, (p, h) in enumerate(zip(xy, heading))
    ]
    sc = scene(craft, duration=3.0, lookahead=45.0)
    w = World(sc)
    in_range = []
    while not w.done:
        w.step()
        in_range.append(w.airspace.pair_arrays(RANGE)[0].size)
    n = w.n
    bound = 8 * (n + max(in_range))
    assert bound < n * (n - 1) // 2 // 20
    m = w.metrics_acc
    held = [v for v in vars(m).values() if isinstance(v, np.ndarray)]
    for v in vars(m).values():
        if isinstance(v, KeyMap):
            held += [a for a in vars(v).values() if isinstance(a, np.ndarray)]
        if isinstance(v, tuple):
            held += [a for a in v if isinstance(a, np.ndarray)]
    assert held and max(a.size for a in held) <= bound
    assert w.metrics()["wcv_pairs"] == m.wcv_events  # nothing left violation in 3 s


# ----------------------------------------------------------- induced losses
def _feed(m, t, pos, vel, following, los_now, los_began):
    n = len(pos)
    keys = np.array(sorted(i * n + j for i, j in los_now), np.int64)
    pairs = {LOS: keys, NMAC: np.zeros(0, np.int64), RANGE: keys}
    began = {
        LOS: np.array(los_began, np.int64).reshape(-1, 2),
        NMAC: np.zeros((0, 2), np.int64),
        RANGE: np.zeros((0, 2), np.int64),
    }
    m.contacts(np.asarray(pos, float), pairs, began)
    m.conflicts(np.zeros(n, bool))
    m.safety(t, np.asarray(pos, float), np.asarray(vel, float), np.ones(n, bool), following, 60.0)


def test_induced_loss_is_one_no_straight_line_prediction_saw_coming():
    # 0 and 1 fly parallel 5 km apart (never in conflict on straight lines); 2 flies
    # head-on at 0 (in conflict from the start). 0 then manoeuvres toward 1 and loses
    # separation with it (induced); 0 and 2 also lose separation (not induced).
    m = WorldMetrics(3, 3000.0, 152.4, 1.0)
    vel = [(200.0, 0.0), (200.0, 0.0), (-200.0, 0.0)]
    calm = np.zeros(3, bool)
    turning = np.array([True, False, False])
    _feed(m, 0.0, [(0, 0), (0, 5000), (10000, 0)], vel, calm, [], [])
    _feed(m, 1.0, [(200, 500), (200, 5000), (9800, 0)], vel, turning, [], [])
    _feed(m, 2.0, [(400, 2500), (400, 5000), (9600, 0)], vel, turning, [(0, 1)], [(0, 1)])
    assert m.induced_keys == {0 * 3 + 1}
    _feed(
        m, 3.0, [(600, 2500), (600, 5000), (2000, 2500)], vel, turning, [(0, 1), (0, 2)], [(0, 2)]
    )
    assert m.induced_keys == {1}


def _brute_force_induced(frames, n, r_safe, lookahead):
    """Induced LoS pairs from recorded (positions, velocities, active, following) frames."""
    predicted, in_los, induced = set(), set(), set()
    for k, (p, v, act, fol) in enumerate(frames):
        for i in range(n):
            for j in range(i + 1, n):
                if not (act[i] and act[j]):
                    continue
                s, w = p[j] - p[i], v[j] - v[i]
                now = math.hypot(*s) < r_safe
                if now and (i, j) not in in_los and k > 0 and (i, j) not in predicted:
                    induced.add((i, j))
                if now:
                    in_los.add((i, j))
                else:
                    in_los.discard((i, j))
                if not fol[i] and not fol[j]:
                    ww = w @ w
                    t = min(max(-(s @ w) / ww, 0.0), lookahead) if ww > 0 else 0.0
                    if math.hypot(*(s + t * w)) < r_safe:
                        predicted.add((i, j))
    return induced


def test_induced_losses_of_a_dense_run_match_brute_force():
    sc = from_dict(
        {
            "name": "dense",
            "seed": 0,
            "dt": 1.0,
            "duration": 150.0,
            "separation": {"r_safe": 3000.0},
            "sensor": {"range": 40000.0, "sigma": 50.0},
            "tracker": {"kind": "truth"},
            "resolver": {"kind": "bands", "lookahead": 60.0},
            "traffic": {"pattern": "random", "count": 14, "sector": 30000.0},
        }
    )
    w = World(sc)
    frames = []

    def grab():
        frames.append(
            (w.positions.copy(), w.velocities.copy(), w.active.copy(), w.policy.following.copy())
        )

    grab()
    while not w.done:
        w.step()
        grab()
    m = w.metrics()
    bf = _brute_force_induced(frames, w.n, w.r_safe, w.lookahead)
    assert m["induced_los_pairs"] == len(bf)
    assert 0 < len(bf) < m["los_pairs"]  # the scene has both kinds


# -------------------------------------------------------------- alert rate
def test_alerts_flight_hours_and_first_alert_match_recorded_flags():
    sc = scene(
        [
            AircraftSpec(id="w", position=(-20000.0, 0.0), heading_deg=0.0, speed=230.0),
            AircraftSpec(id="e", position=(20000.0, 0.0), heading_deg=180.0, speed=230.0),
            AircraftSpec(id="q", position=(0.0, 30000.0), heading_deg=0.0, speed=230.0),
        ],
        resolver="bands",
        duration=150.0,
    )
    w = World(sc)
    flags = [w.conflict.copy()]
    flying = 0
    while not w.done:
        flying += int(w.active.sum())
        w.step()
        flags.append(w.conflict.copy())
    flags = np.array(flags)
    prev = np.vstack([np.zeros((1, 3), bool), flags[:-1]])
    alerts = int((flags & ~prev).sum())
    first = float(np.flatnonzero(flags.any(axis=1))[0]) * sc.dt
    m = w.metrics()
    assert alerts >= 2 and m["alerts"] == alerts
    assert m["flight_hours"] == pytest.approx(flying * sc.dt / 3600.0)
    assert m["alerts_per_flight_hour"] == pytest.approx(alerts / (flying * sc.dt / 3600.0))
    assert m["first_alert_s"] == first
    # head-on from 40 km at 460 m/s closing is inside the 120 s look-ahead from the start:
    # the first alert waits only for the tracks' confirmation (resolver.confirm_s)
    assert 0.0 < first <= sc.resolver.confirm_s + 2 * sc.dt


def test_no_alert_gives_nan_first_alert():
    sc = scene([AircraftSpec(id="a", position=(0.0, 0.0), heading_deg=0.0, speed=200.0)])
    m = World(sc).run()
    assert m["alerts"] == 0 and math.isnan(m["first_alert_s"])
    assert m["alerts_per_flight_hour"] == 0.0


# ------------------------------------------------------------------ arrivals
def test_arrival_delay_of_undisturbed_routes_is_the_capture_slack():
    # captured once within one step's travel of the last waypoint: leg L at v m/s, dt 1 s,
    # arrives at step k = ceil(L/v − 1); delay k − L/v.
    legs = {"a": (10100.0, 200.0), "b": (7300.0, 150.0)}
    craft = [
        AircraftSpec(
            id=name,
            position=(0.0, 20000.0 * i),
            heading_deg=0.0,
            speed=v,
            autopilot="route",
            waypoints=[(L, 20000.0 * i)],
        )
        for i, (name, (L, v)) in enumerate(legs.items())
    ]
    craft.append(  # too far to arrive in 200 s
        AircraftSpec(
            id="far",
            position=(0.0, -20000.0),
            heading_deg=0.0,
            speed=200.0,
            autopilot="route",
            waypoints=[(90000.0, -20000.0)],
        )
    )
    m = World(scene(craft)).run()
    delays = [math.ceil(L / v - 1) - L / v for L, v in legs.values()]
    assert m["arrived"] == 2 and m["not_arrived"] == 1
    assert m["arrival_delay_mean_s"] == pytest.approx(np.mean(delays), abs=1e-9)
    assert m["arrival_delay_max_s"] == pytest.approx(max(delays), abs=1e-9)


def test_arrival_delay_of_an_avoidance_detour_is_the_extra_path_over_speed():
    v = 230.0
    craft = [
        AircraftSpec(
            id="w",
            position=(-20000.0, 0.0),
            heading_deg=0.0,
            speed=v,
            autopilot="route",
            waypoints=[(20000.0, 0.0)],
        ),
        AircraftSpec(
            id="e",
            position=(20000.0, 0.0),
            heading_deg=180.0,
            speed=v,
            autopilot="route",
            waypoints=[(-20000.0, 0.0)],
        ),
    ]
    m = World(scene(craft, resolver="bands", duration=400.0)).run()
    assert m["arrived"] == 2 and m["not_arrived"] == 0 and m["los_pairs"] == 0
    # constant speed, flying every step until it arrives: arrival time = flown / v and the
    # planned straight time = plan / v, so delay = (flown − plan)/v = extra path / v
    mean_extra_s = m["extra_path_m"] / 2 / v
    assert mean_extra_s > 0.5
    assert m["arrival_delay_mean_s"] == pytest.approx(mean_extra_s, abs=1e-9)


def test_retired_route_aircraft_neither_arrives_nor_counts_as_flying():
    # the env retires agents whose episode ended (NMAC, truncation): they left the world
    # without finishing their plan
    craft = [
        AircraftSpec(
            id=name,
            position=(0.0, 20000.0 * k),
            heading_deg=0.0,
            speed=200.0,
            autopilot="route",
            waypoints=[(10100.0, 20000.0 * k)],
        )
        for k, name in enumerate("ab")
    ]
    w = World(scene(craft))
    w.run(5)
    w.retire([w.index("b")])
    m = w.run()
    assert m["arrived"] == 1 and m["not_arrived"] == 0
    assert m["arrival_delay_mean_s"] == pytest.approx(math.ceil(10100.0 / 200.0 - 1) - 50.5)


def test_no_plan_no_arrival_stats():
    sc = scene(
        [AircraftSpec(id="m", position=(0, 0), heading_deg=0, speed=200, autopilot="markov")]
    )
    m = World(sc).run()
    assert m["arrived"] == m["not_arrived"] == 0
    assert math.isnan(m["arrival_delay_mean_s"])


# ---------------------------------------------------------------- risk ratio
def test_risk_ratio_of_head_on_pairs():
    # exactly head-on: unequipped miss distance 0 < 152.4 m → one NMAC per seed; equipped 0
    craft = [
        AircraftSpec(id="w", position=(-20000.0, 0.0), heading_deg=0.0, speed=230.0),
        AircraftSpec(id="e", position=(20000.0, 0.0), heading_deg=180.0, speed=230.0),
    ]
    out = risk_ratio(scene(craft, resolver="bands", duration=120.0), [0, 1])
    assert out["nmac_unequipped"] == 2 and out["nmac_equipped"] == 0
    assert out["risk_ratio"] == 0.0 and out["runs"] == 2
    assert out["los_pairs_unequipped"] == 2


def test_risk_ratio_undefined_without_unequipped_nmac():
    craft = [
        AircraftSpec(id="a", position=(0.0, 0.0), heading_deg=0.0, speed=230.0),
        AircraftSpec(id="b", position=(0.0, 10000.0), heading_deg=0.0, speed=230.0),
    ]
    out = risk_ratio(scene(craft, resolver="bands", duration=30.0), [0])
    assert out["nmac_unequipped"] == 0 and math.isnan(out["risk_ratio"])


def safety_and_brute_force(pos, vel, active, following, r_safe, look):
    """One :meth:`WorldMetrics.safety` call on (N, 2) positions and velocities, and the
    pair keys i·N + j of the well-clear violations and predicted conflicts by the scalar
    definitions over all pairs: ``(metrics, wcv set, predicted set)``."""
    n = pos.shape[0]
    m = WorldMetrics(n, r_safe, 152.4, 1.0)
    none = {t: np.zeros(0, np.int64) for t in (LOS, NMAC, RANGE)}
    began = {t: np.zeros((0, 2), np.int64) for t in (LOS, NMAC, RANGE)}
    m.contacts(pos, none, began)
    m.conflicts(np.zeros(n, bool))
    m.safety(0.0, pos, vel, active, following, look)
    wcv, pred = set(), set()
    for i in range(n):
        for j in range(i + 1, n):
            if not (active[i] and active[j]):
                continue
            s, v = pos[j] - pos[i], vel[j] - vel[i]
            if _wcv_scalar(s, v):
                wcv.add(i * n + j)
            if not following[i] and not following[j] and _predicted_scalar(s, v, r_safe, look):
                pred.add(i * n + j)
    return m, wcv, pred
