"""Readers, frame, flights and samples of airspace_sim.recorded, on small files the tests write.

Oracles: pyproj's geodesic (distances and azimuths on the ellipsoid), closed-form turns and
circles, and hand-made tables whose cleaning result is known row by row.
"""

from __future__ import annotations

import gzip
import json
import math
import zipfile

import numpy as np
import pytest

pytest.importorskip("pyproj")
pd = pytest.importorskip("pandas")

import pyproj  # noqa: E402

from airspace_sim.errors import UserError  # noqa: E402
from airspace_sim.recorded import Flight, Frame, read, samples, turn_rates  # noqa: E402
from airspace_sim.recorded.flights import FOOT_M, KNOT_MS, course_offset_deg  # noqa: E402

GEOD = pyproj.Geod(ellps="WGS84")
LAT0, LON0 = 46.5, 8.0


def _geodesic_flight(icao="abc123", n=40, dt=10.0, speed_kt=450.0, az0=70.0, t0=1.5e9):
    """Rows of a flight along a geodesic from (LAT0, LON0): timestamp, lat, lon, track."""
    dist = speed_kt * KNOT_MS * dt * np.arange(n)
    lon, lat, back = GEOD.fwd(np.full(n, LON0), np.full(n, LAT0), np.full(n, az0), dist)
    track = (np.asarray(back) + 180.0) % 360.0  # forward azimuth at each point
    return pd.DataFrame(
        {
            "timestamp": pd.to_datetime((t0 + dt * np.arange(n)) * 1e9, utc=True),
            "icao24": icao,
            "callsign": "TST1",
            "latitude": lat,
            "longitude": lon,
            "altitude": 35000.0,
            "groundspeed": speed_kt,
            "track": track,
        }
    )


# ---------------------------------------------------------------------------- frame
def test_frame_distances_and_azimuths_from_the_centre_are_geodesic():
    frame = Frame(LAT0, LON0)
    az = np.array([0.0, 45.0, 90.0, 200.0, 300.0])
    r = np.array([1e3, 5e4, 1.3e5, 2e5, 3e5])
    lon, lat, _ = GEOD.fwd(np.full(5, LON0), np.full(5, LAT0), az, r)
    x, y = frame.forward(lat, lon)
    # azimuthal equidistant: distance and direction from the centre are exact
    np.testing.assert_allclose(np.hypot(x, y), r, rtol=1e-9)
    np.testing.assert_allclose(np.degrees(np.arctan2(x, y)) % 360, az, atol=1e-7)
    lat2, lon2 = frame.inverse(x, y)
    np.testing.assert_allclose(lat2, lat, atol=1e-9)
    np.testing.assert_allclose(lon2, lon, atol=1e-9)


def test_reported_velocity_matches_the_projected_positions_far_from_the_centre(tmp_path):
    # a geodesic flight 200+ km from the frame centre: meridian convergence ~2°, so a
    # constant rotation of the track would be 8 m/s off; the frame's velocity is not
    df = _geodesic_flight(n=30)
    path = tmp_path / "f.csv"
    df.to_csv(path, index=False)
    f = read(path, centre=(LAT0 - 0.3, LON0 - 2.8))[0]
    assert np.hypot(f.x_m[0], f.y_m[0]) > 2e5
    mid_v = np.stack([np.diff(f.x_m), np.diff(f.y_m)], 1) / np.diff(f.t_s)[:, None]
    rep_v = 0.5 * np.stack([f.vx[1:] + f.vx[:-1], f.vy[1:] + f.vy[:-1]], 1)
    np.testing.assert_allclose(rep_v, mid_v, atol=0.05)  # m/s
    np.testing.assert_allclose(f.speed, 450 * KNOT_MS, rtol=2e-3)
    assert course_offset_deg(f) < 0.05


# ---------------------------------------------------------------------------- flights
def test_turn_rates_of_a_constant_turn_through_the_wrap():
    t = np.arange(0.0, 300.0, 5.0)
    w = -math.radians(2.0)  # a right turn
    h = 3.0 + w * t  # crosses ±π
    rate = turn_rates(t, 200 * np.cos(h), 200 * np.sin(h))
    np.testing.assert_allclose(rate, w, atol=1e-12)
    # a gap: no rate across it; one-sided next to it
    t2 = np.concatenate([t[:10], t[10:] + 500])
    h2 = 3.0 + w * t2
    r2 = turn_rates(t2, np.cos(h2), np.sin(h2), max_gap_s=60)
    np.testing.assert_allclose(r2, w, atol=1e-12)  # still exact (one-sided at the edges)


def _circle_flight(dt=10.0, v=200.0, omega_deg=2.0, n=30, gap_at=None):
    omega = math.radians(omega_deg)
    t = dt * np.arange(n, dtype=float)
    if gap_at is not None:
        t[gap_at:] += 300.0
    h = omega * t
    R = v / omega
    x, y = R * np.sin(h), R * (1 - np.cos(h))
    vx, vy = v * np.cos(h), v * np.sin(h)
    return Flight("c", "c", "", t, x, y, vx, vy, turn_rates(t, vx, vy), np.zeros(n)), R, omega, v


def test_hermite_sampling_stays_on_the_arc_where_a_chord_cuts_the_corner():
    f, R, omega, v = _circle_flight()
    tq = np.arange(0.0, f.end_s, 0.5)
    x, y, vx, vy = f.sample(tq)
    h = omega * tq
    err = np.hypot(x - R * np.sin(h), y - R * (1 - np.cos(h)))
    chord_sag = R * (1 - math.cos(omega * 10.0 / 2))  # the linear interpolation's worst
    assert chord_sag > 40.0
    assert err.max() < 0.5
    np.testing.assert_allclose(np.hypot(vx, vy), v, rtol=2e-3)
    np.testing.assert_allclose(f.turn_rate_at(tq), omega, rtol=1e-9)


def test_gaps_are_kept_as_gaps():
    f, *_ = _circle_flight(gap_at=12)
    np.testing.assert_allclose(f.gaps(), [[110.0, 420.0]])
    x, *_ = f.sample([100.0, 115.0, 300.0, 425.0, 1e6, -1.0])
    assert np.isfinite(x[[0, 3]]).all() and np.isnan(x[[1, 2, 4, 5]]).all()


# ---------------------------------------------------------------------------- readers
def test_traffic_csv_units_cleaning_and_flight_split(tmp_path):
    a = _geodesic_flight("aaa111", n=20)
    b = _geodesic_flight("bbb222", n=20, az0=250.0)
    b.loc[5:7, "latitude"] = b.loc[4, "latitude"]  # forward-filled repeats of row 4
    b.loc[5:7, "longitude"] = b.loc[4, "longitude"]
    b["onground"] = False
    b.loc[0:1, "onground"] = True
    a2 = _geodesic_flight("aaa111", n=10, t0=1.5e9 + 20 * 10 + 900)  # 900 s later: new flight
    a2.loc[3, "latitude"] = np.nan  # a row without position
    df = pd.concat([a, b, a2]).sample(frac=1.0, random_state=1)  # rows in any order
    df["timestamp"] = df["timestamp"].astype(str)  # ISO text, as traffic writes CSV
    path = tmp_path / "t.csv"
    df.to_csv(path, index=False)
    fl = read(path)
    assert sorted(fl.ids) == ["aaa111-TST1-0", "aaa111-TST1-1", "bbb222-TST1-0"]
    assert [len(fl[i]) for i in sorted(fl.ids)] == [20, 9, 15]
    assert fl.dropped == {
        "no_position": 1,
        "on_ground": 2,
        "repeated_position": 3,
        "repeated_time": 0,
    }
    f = fl["aaa111-TST1-0"]
    np.testing.assert_allclose(f.altitude_m, 35000 * FOOT_M)
    np.testing.assert_allclose(f.speed, 450 * KNOT_MS, rtol=2e-3)
    np.testing.assert_allclose(np.diff(f.t_s), 10.0)
    assert fl.epoch_s == math.floor(1.5e9)
    # heading CCW from east: track 70° (clockwise from north) is 20° CCW from east
    assert abs(math.degrees(f.heading[0]) - 20.0) < 2.5


def test_parquet_and_json_records_read_like_csv(tmp_path):
    df = _geodesic_flight(n=15)
    df.to_csv(tmp_path / "f.csv", index=False)
    df.to_parquet(tmp_path / "f.parquet")
    records = df.assign(timestamp=(df.timestamp.astype("int64") // 10**6))  # ms, as traffic
    with gzip.open(tmp_path / "f.json.gz", "wt") as fh:
        json.dump(records.to_dict(orient="records"), fh)
    ref = read(tmp_path / "f.csv", centre=(LAT0, LON0))[0]
    for name in ("f.parquet", "f.json.gz"):
        f = read(tmp_path / name, centre=(LAT0, LON0))[0]
        for k in ("t_s", "x_m", "y_m", "vx", "vy", "turn_rate", "altitude_m"):
            np.testing.assert_allclose(getattr(f, k), getattr(ref, k), atol=1e-6, err_msg=k)


def test_opensky_state_vectors(tmp_path):
    df = _geodesic_flight(n=12)
    t = df.timestamp.astype("int64") / 1e9
    sv = pd.DataFrame(
        {
            "time": t.astype(int),
            "icao24": "4b1805",
            "lat": df.latitude,
            "lon": df.longitude,
            "velocity": 450 * KNOT_MS,
            "heading": df.track,
            "vertrate": 0.0,
            "callsign": "SWR123  ",
            "onground": False,
            "baroaltitude": 10668.0,
            "lastposupdate": t,
        }
    )
    sv.loc[6, "lastposupdate"] = sv.loc[5, "lastposupdate"]  # stale position: dropped
    sv.loc[6, ["lat", "lon"]] = sv.loc[5, ["lat", "lon"]].to_numpy()
    path = tmp_path / "states.csv"
    sv.to_csv(path, index=False)
    fl = read(path)
    f = fl[0]
    assert f.id == "4b1805-SWR123-0" and len(f) == 11
    np.testing.assert_allclose(f.altitude_m, 10668.0)
    np.testing.assert_allclose(f.speed, 450 * KNOT_MS, rtol=2e-3)
    assert fl.dropped["repeated_position"] == 1


def test_velocity_from_positions_repairs_a_rotated_track(tmp_path):
    df = _geodesic_flight(n=25)
    df["track"] = (df["track"] + 103.0) % 360  # as in some OpenSky calibration samples
    df.to_csv(tmp_path / "r.csv", index=False)
    bad = read(tmp_path / "r.csv")
    good = read(tmp_path / "r.csv", velocity="positions")
    assert bad.summary()["track_vs_course_deg"] == pytest.approx(103.0, abs=0.5)
    assert good.summary()["track_vs_course_deg"] < 0.05
    np.testing.assert_allclose(good[0].speed, 450 * KNOT_MS, rtol=2e-3)


def test_a_glitch_is_dropped_and_counted(tmp_path):
    """One position moved 1.5 km across a straight track (its reported track unchanged) is
    dropped and counted; ``glitch_m=None`` keeps it; a bad ``glitch_m`` is one line."""
    df = _geodesic_flight(n=30)
    lon, lat, _ = GEOD.fwd(df.longitude[12], df.latitude[12], (df.track[12] + 90.0) % 360, 1500.0)
    df.loc[12, ["longitude", "latitude"]] = [lon, lat]
    df.to_csv(tmp_path / "g.csv", index=False)
    fl = read(tmp_path / "g.csv")
    assert fl.dropped["glitch"] == 1 and len(fl[0]) == 29
    kept = read(tmp_path / "g.csv", glitch_m=None)
    assert "glitch" not in kept.dropped and len(kept[0]) == 30
    assert fl[0].t_s.tolist() == np.delete(kept[0].t_s, 12).tolist()
    clean = _geodesic_flight(n=30)
    clean.to_csv(tmp_path / "c.csv", index=False)
    assert "glitch" not in read(tmp_path / "c.csv").dropped
    with pytest.raises(UserError, match="glitch_m must be a distance > 0 m or None, got -1"):
        read(tmp_path / "c.csv", glitch_m=-1)


@pytest.mark.parametrize(
    "mutate, message",
    [
        (lambda d: d.assign(latitude=d.latitude.astype(object)).replace({d.latitude[2]: "x"}),
         r"t\.csv: row 3 \(line 4\), column 'latitude': not a number: 'x'"),
        (lambda d: d.assign(longitude=[*d.longitude[:4], 200.0, *d.longitude[5:]]),
         r"row 5 \(line 6\), column 'longitude': 200.0 is not in \[-180, 180\]"),
        (lambda d: d.drop(columns=["track"]), r"t\.csv: traffic columns found but no column 'track'"),
        (lambda d: d.rename(columns={"latitude": "y"}), r"t\.csv: no column 'timestamp'"),
        (lambda d: d.assign(timestamp=["soon", *d.timestamp[1:].astype(str)]),
         r"row 1 \(line 2\), column 'timestamp': not a time: 'soon'"),
        (lambda d: d.assign(onground=["maybe", *["False"] * (len(d) - 1)]),
         r"row 1 \(line 2\), column 'onground': not a boolean: 'maybe'"),
    ],
)  # fmt: skip
def test_bad_files_are_one_line_errors_naming_file_row_and_column(tmp_path, mutate, message):
    df = mutate(_geodesic_flight(n=8))
    df.to_csv(tmp_path / "t.csv", index=False)
    with pytest.raises(UserError, match=message) as exc:
        read(tmp_path / "t.csv")
    assert "\n" not in str(exc.value)


def test_unreadable_and_unknown_files(tmp_path):
    with pytest.raises(UserError, match="no such file"):
        read(tmp_path / "none.csv")
    (tmp_path / "x.txt").write_text("a")
    with pytest.raises(UserError, match="unknown file type"):
        read(tmp_path / "x.txt")
    (tmp_path / "x.json").write_text("{not json")
    with pytest.raises(UserError, match=r"x\.json: cannot read as \.json"):
        read(tmp_path / "x.json")


# ---------------------------------------------------------------------------- samples
def test_samples_from_a_wheel_file(tmp_path, monkeypatch):
    df = _geodesic_flight(n=6)
    records = df.assign(timestamp=(df.timestamp.astype("int64") // 10**6))
    payload = gzip.compress(json.dumps(records.to_dict(orient="records")).encode())
    wheel = tmp_path / "traffic-2.8.1-py3-none-any.whl"
    with zipfile.ZipFile(wheel, "w") as z:
        z.writestr("traffic/data/samples/collections/tiny.json.gz", payload)
        z.writestr("traffic/data/samples/calibration/tiny2.json.gz", payload)
    monkeypatch.setattr(samples, "_installed_dir", lambda: None)
    monkeypatch.setenv("AIRSPACE_SIM_CACHE", str(tmp_path / "cache"))
    monkeypatch.setenv("AIRSPACE_SIM_TRAFFIC_WHEEL", str(tmp_path))
    assert samples.names() == ["calibration/tiny2", "collections/tiny"]
    p = samples.path("tiny")
    assert p.is_file() and p.read_bytes() == payload
    assert len(read(p)[0]) == 6
    with pytest.raises(UserError, match="unknown"):
        samples.path("nothing")
    monkeypatch.setenv("AIRSPACE_SIM_TRAFFIC_WHEEL", str(tmp_path / "empty"))
    monkeypatch.setenv("AIRSPACE_SIM_CACHE", str(tmp_path / "c2" / "x"))
    with pytest.raises(UserError, match=r"pip download traffic==2\.8\.1 --no-deps"):
        samples.path("tiny")


def _real_samples():
    return samples.available()


@pytest.mark.skipif(not _real_samples(), reason="traffic 2.8.1 wheel not installed/downloaded")
def test_real_switzerland_collection():
    fl = read(samples.path("collections/switzerland"))
    s = fl.summary()
    assert s["flights"] > 1000 and s["median_spacing_s"] == 10.0
    assert s["track_vs_course_deg"] < 1.0
    assert 50 < fl.dropped["glitch"] < 500  # 136 of its 138 858 positions


def test_a_missing_real_extra_is_one_line(monkeypatch):
    """Without pandas / pyproj (the ``real`` extra) reading is a UserError naming the extra;
    a None entry in sys.modules makes any import of the module fail (Python's documented
    way to block one)."""
    import sys

    from airspace_sim.recorded import _extra

    for module in ("pandas", "pyproj"):
        monkeypatch.setitem(sys.modules, module, None)
        with pytest.raises(UserError, match=rf"needs {module}: pip install 'airspace-sim\[real\]'"):
            _extra.require(module)
