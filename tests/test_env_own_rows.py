"""The env's own-block kernel (env/spaces.py encode_own_rows) against the numpy statement
of the same layout (OWN_NAMES), on random world arrays with every special case: no
waypoint ahead, no turn limit, non-finite advice, clipped route commands, conflicts."""

import numpy as np

from airspace_sim.env import spaces as sp
from airspace_sim.geometry import wrap_angle


def _numpy_own(
    idx,
    speeds,
    rates,
    max_rate,
    per_step,
    advice,
    cross,
    dist,
    conflict,
    los,
    heading,
    bearing,
    r_safe,
    sensor_range,
):
    heading, advice, dist, max_rate, per_step = (
        heading[idx],
        advice[idx],
        dist[idx],
        max_rate[idx],
        per_step[idx],
    )
    has_wp = np.isfinite(dist)
    rel_b = wrap_angle(bearing[idx] - heading)
    dist = np.where(has_wp, dist, 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        rate = np.where(max_rate > 0, rates[idx] / max_rate, 0.0)
        adv = np.where((per_step > 0) & np.isfinite(advice), advice / per_step, 0.0)
        route = np.where(has_wp & (per_step > 0), rel_b / per_step, 0.0)
    route = np.clip(route, -1.0, 1.0)
    c = conflict[idx]
    return np.stack(
        [
            speeds[idx] / sp.V_REF,
            np.sin(heading),
            np.cos(heading),
            rate,
            cross[idx] / (10 * r_safe),
            np.where(has_wp, np.sin(rel_b), 0.0),
            np.where(has_wp, np.cos(rel_b), 1.0),
            np.where(has_wp, dist / (2 * sensor_range), 0.0),
            has_wp.astype(float),
            adv,
            c.astype(float),
            los[idx].astype(float),
            route,
            np.where(c, adv, route),
        ],
        axis=1,
    )


def test_own_rows_match_the_numpy_statement_bit_for_bit():
    rng = np.random.default_rng(4)
    n, dt, r_safe, sensor_range = 60, 1.0, 3000.0, 40000.0
    speeds = rng.uniform(100, 300, n)
    max_rate = np.radians(rng.choice([0.0, 1.5, 3.0], n))
    rates = rng.uniform(-1, 1, n) * max_rate
    per_step = max_rate * dt
    advice = rng.uniform(-0.06, 0.06, n)
    advice[rng.random(n) < 0.1] = np.nan
    cross = rng.uniform(-20000, 20000, n)
    dist = rng.uniform(0, 90000, n)
    dist[rng.random(n) < 0.2] = np.nan
    conflict, los = rng.random(n) < 0.4, rng.random(n) < 0.2
    heading, bearing = rng.uniform(-np.pi, np.pi, n), rng.uniform(-np.pi, np.pi, n)
    idx = rng.permutation(n)[:45]
    want = _numpy_own(
        idx,
        speeds,
        rates,
        max_rate,
        per_step,
        advice,
        cross,
        dist,
        conflict,
        los,
        heading,
        bearing,
        r_safe,
        sensor_range,
    )
    h = heading[idx]
    rel_b = wrap_angle(bearing[idx] - h)
    out = np.full((idx.size, 20), -7.0)
    sp.encode_own_rows(
        idx,
        speeds,
        rates,
        max_rate,
        per_step,
        advice,
        cross,
        dist,
        conflict,
        los,
        np.sin(h),
        np.cos(h),
        rel_b,
        np.sin(rel_b),
        np.cos(rel_b),
        10 * r_safe,
        2 * sensor_range,
        out,
    )
    assert out[:, :14].tobytes() == want.tobytes()
    assert (out[:, 14:] == -7.0).all()  # the intruder block is not touched
    # the cases occur: no waypoint, no turn limit, non-finite advice, a clipped command
    assert (~np.isfinite(dist[idx])).any() and (max_rate[idx] == 0).any()
    assert (~np.isfinite(advice[idx])).any() and (np.abs(want[:, 12]) == 1.0).any()
