"""Recorded traffic from files: the scenario's [recorded] section, the ``replay`` command
and the env's agents, on flights the tests make and write as traffic-style CSV.

Oracles: the frame's inverse (positions back where they were written), the flights'
closed-form geometry (one LoS pair in the crossing), the ids the files hold.
"""

from __future__ import annotations

import argparse
import json
import math

import numpy as np
import pytest
from test_replay import _crossing, _line

from airspace_sim.errors import UserError
from airspace_sim.world import World

pd = pytest.importorskip("pandas")
pytest.importorskip("pyproj")


def _write_csv(path, flights, centre=(47.0, 8.0)):
    """The flights as a traffic-style CSV (lat/lon by the frame's inverse, ISO times)."""
    from airspace_sim.recorded import Frame

    frame = Frame(*centre)
    rows = []
    for f in flights:
        lat, lon = frame.inverse(f.x_m, f.y_m)
        for k in range(len(f)):
            rows.append(
                {
                    "timestamp": pd.Timestamp(1.6e9 + f.t_s[k], unit="s", tz="UTC").isoformat(),
                    "icao24": f.id.lower() * 3,
                    "callsign": f.id,
                    "latitude": lat[k],
                    "longitude": lon[k],
                    "altitude": f.altitude_m[k] / 0.3048,
                    "groundspeed": 0.0,  # unused: velocity from positions
                    "track": 0.0,
                }
            )
    pd.DataFrame(rows).to_csv(path, index=False)


def test_scenario_mixes_recorded_and_simulated_aircraft(tmp_path):
    from airspace_sim.scenarios import load

    a, b = _crossing()
    _write_csv(tmp_path / "f.csv", [a, b])
    (tmp_path / "mix.toml").write_text(
        'name = "mix"\nduration = 100\n'
        '[recorded]\nfile = "f.csv"\ncentre_lat_deg = 47.0\ncentre_lon_deg = 8.0\n'
        'velocity = "positions"\n'
        '[[aircraft]]\nid = "own"\nposition = [0.0, 20000.0]\nheading_deg = -90.0\nspeed = 200.0\n'
    )
    sc = load(tmp_path / "mix.toml")
    w = World(sc)
    assert w.ids == ["own", "aaa-A-0", "bbb-B-0"] and w.moved.tolist() == [False, True, True]
    # the frame is the given centre: A starts 30 km west of it
    assert np.allclose(w.positions[1], (-30000.0, 0.0), atol=1.0)
    (tmp_path / "bad.toml").write_text('name = "b"\n[recorded]\nfile = "f.csv"\nspeed = 3\n')
    with pytest.raises(UserError, match=r"bad\.toml: recorded\.speed: unknown key"):
        load(tmp_path / "bad.toml")
    (tmp_path / "bad2.toml").write_text('name = "b"\n[recorded]\nfile = "nope.csv"\n')
    with pytest.raises(UserError, match=r"recorded\.file: no such file"):
        World(load(tmp_path / "bad2.toml"))


def test_glitches_are_dropped_unless_the_scenario_keeps_them(tmp_path, capsys):
    """A recorded position 1.5 km to the side of a straight track is not flown: the flight
    as the world reads it has one sample fewer, unless ``keep_glitches = true`` (or
    ``replay --keep-glitches``)."""
    from airspace_sim.commands import replay
    from airspace_sim.recorded.scenario import load_flights
    from airspace_sim.scenarios import load

    a, b = _crossing()
    y = a.y_m.copy()
    y[10] += 1500.0
    a = type(a)(a.id, a.icao24, a.callsign, a.t_s, a.x_m, y, a.vx, a.vy, a.turn_rate,
                a.altitude_m)  # fmt: skip
    _write_csv(tmp_path / "f.csv", [a, b])
    lengths = {}
    for keep in ("false", "true"):
        (tmp_path / "g.toml").write_text(
            f'name = "g"\nduration = 100\n[recorded]\nfile = "f.csv"\nkeep_glitches = {keep}\n'
            'velocity = "positions"\n'
        )
        flights = load_flights(load(tmp_path / "g.toml").recorded, str(tmp_path / "g.toml"))
        lengths[keep] = sorted(len(f) for f in flights)
    assert lengths == {"false": [30, 31], "true": [31, 31]}
    parser = argparse.ArgumentParser()
    replay.add_arguments(parser)
    for flag, want in (([], False), (["--keep-glitches"], True)):
        sc = replay.build_scenario(parser.parse_args([str(tmp_path / "f.csv"), *flag]))
        assert sc.recorded.keep_glitches is want


def _cli(capsys, *args):
    from airspace_sim.cli import main

    code = main(["replay", *args])
    out = capsys.readouterr()
    return code, out.out, out.err


def test_cli_replay_reports_json_and_renders(tmp_path, capsys):
    a, b = _crossing()
    _write_csv(tmp_path / "f.csv", [a, b])
    out = tmp_path / "out.json"
    frames = tmp_path / "frames"
    code, stdout, stderr = _cli(
        capsys,
        str(tmp_path / "f.csv"), "--velocity", "positions", "--start", "100", "--duration",
        "80", "--json", str(out), "--render", str(frames), "--every", "40", "--gif",
        "--size", "128x128",
    )  # fmt: skip
    assert code == 0, stderr
    s = json.loads(out.read_text())
    assert s["steps"] == 80 and s["replay"]["los_pairs"] == 1
    assert s["real_time_factor"] > 0 and s["metrics"]["aircraft"] == 2
    assert (frames / "run.gif").is_file() and s["frames"] == 3
    assert "replay.los_pairs" in stdout


def test_cli_replay_bad_file_is_one_line(tmp_path, capsys):
    (tmp_path / "bad.csv").write_text("timestamp,icao24,latitude,longitude,groundspeed,track\n"
                                      "2020-01-01,abc,91.5,8,400,90\n")  # fmt: skip
    code, _, stderr = _cli(capsys, str(tmp_path / "bad.csv"))
    assert code == 2
    assert stderr.strip().count("\n") == 0
    assert "bad.csv: row 1 (line 2), column 'latitude'" in stderr


def _mixed_scenario(tmp_path):
    a, b = _crossing()
    _write_csv(tmp_path / "f.csv", [a, b])
    path = tmp_path / "mix.toml"
    path.write_text(
        'name = "mix"\nduration = 100\n'
        '[recorded]\nfile = "f.csv"\ncentre_lat_deg = 47.0\ncentre_lon_deg = 8.0\n'
        'velocity = "positions"\n'
        '[[aircraft]]\nid = "own"\nposition = [0.0, 20000.0]\nheading_deg = -90.0\nspeed = 200.0\n'
    )
    return path


def test_recorded_traffic_gets_the_recorded_tracker_unless_one_is_named(tmp_path):
    from airspace_sim.dynamics.presets import RECORDED_TRACKER
    from airspace_sim.scenarios import load

    path = _mixed_scenario(tmp_path)
    assert RECORDED_TRACKER == "imm-ct"
    sc = load(path)
    assert sc.tracker.model == RECORDED_TRACKER
    assert World(sc).tracker_preset.name == RECORDED_TRACKER  # what the trackers run
    assert load(path, ['tracker.model="realistic"']).tracker.model == "realistic"
    named = tmp_path / "named.toml"
    named.write_text(path.read_text() + '[tracker]\nmodel = "turn-rate"\n')
    assert load(named).tracker.model == "turn-rate"
    # no recorded file: the simulated traffic's own modes
    assert load(path, ['recorded.file=""']).tracker.model == "realistic"


def test_recorded_aircraft_are_never_env_agents(tmp_path):
    import airspace_sim.env as aenv

    path = _mixed_scenario(tmp_path)
    for agents in ("all", 1, None):
        env = aenv.parallel_env(scenario=str(path), agents=agents)
        assert env.possible_agents == ["own"], agents
    with pytest.raises(UserError, match="'aaa-A-0' is recorded traffic") as info:
        aenv.parallel_env(scenario=str(path), agents=["own", "aaa-A-0"])
    assert "\n" not in str(info.value)
    with pytest.raises(UserError, match="agents: expected an integer"):
        aenv.parallel_env(scenario=str(path), agents=2)  # only one aircraft can be an agent


def test_cli_run_waits_for_recorded_traffic_that_arrives_later(tmp_path, capsys):
    from airspace_sim.cli import main

    # C is recorded 0..100 s and 200..300 s: nobody flies in between, then C comes back
    t = np.concatenate([np.arange(0.0, 101.0, 10.0), np.arange(200.0, 301.0, 10.0)])
    _write_csv(tmp_path / "f.csv", [_line("C", (0.0, 0.0), 30.0, t)])
    (tmp_path / "gap.toml").write_text(
        'name = "gap"\nduration = 300\n'
        '[recorded]\nfile = "f.csv"\ncentre_lat_deg = 47.0\ncentre_lon_deg = 8.0\n'
        'velocity = "positions"\n'
    )
    out, ckpt = tmp_path / "s.json", tmp_path / "run.ckpt"
    args = [str(tmp_path / "gap.toml"), "--json", str(out), "--checkpoint", str(ckpt), "--quiet"]
    code = main(["run", *args])
    assert code == 0, capsys.readouterr().err
    s = json.loads(out.read_text())
    assert s["steps"] == 300 and not s["all_left"]  # the duration, not the gap, ended it
    assert s["metrics"]["flight_hours"] == pytest.approx(201 / 3600, abs=2 / 3600)
    assert s["checkpoint"] == str(ckpt)  # in the file as on the screen


def test_sigterm_ends_a_replay_like_ctrl_c_with_its_outputs_written(tmp_path):
    """A real SIGTERM mid-replay: exit 143 and one line, like ``run``; the steps so far are
    summarised in --json, and the frames and the GIF are written."""
    import os
    import signal
    import subprocess
    import sys
    import time
    from pathlib import Path

    from PIL import Image

    t = np.arange(0.0, 40001.0, 10.0)  # 11 hours: far longer than the test waits
    _write_csv(
        tmp_path / "f.csv", [_line("A", (0.0, 0.0), 0.0, t), _line("B", (0.0, 9000.0), 0.0, t)]
    )
    out, frames = tmp_path / "s.json", tmp_path / "frames"
    proc = subprocess.Popen(
        [sys.executable, "-m", "airspace_sim", "replay", str(tmp_path / "f.csv")]
        + ["--velocity", "positions", "--json", str(out), "--render", str(frames)]
        + ["--every", "20", "--size", "64x64", "--gif", "--quiet"],
        cwd=Path(__file__).resolve().parent.parent,
        env={**os.environ, "AIRSPACE_SIM_PLUGINS": ""},
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + 120
        while len(list(frames.glob("*.png"))) < 3:  # stepping: frames after the first
            assert proc.poll() is None and time.monotonic() < deadline, proc.stderr
            time.sleep(0.05)
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 143, err
    assert err.strip() == "airspace-sim replay: terminated"
    s = json.loads(out.read_text())
    assert s["interrupted"] and 40 <= s["steps"] < 40000, s["steps"]
    assert s["metrics"]["aircraft"] == 2 and s["replay"]["los_pairs"] == 0  # 9 km apart
    pngs = sorted(frames.glob("*.png"))
    assert s["frames"] == len(pngs) >= 3
    with Image.open(frames / "run.gif") as gif:
        assert gif.n_frames == len(pngs)


def test_ownship_benchmark_counts_the_loss_it_avoids(tmp_path, monkeypatch, capsys):
    """docs/benchmarks/ownship_in_real_traffic.py on a recording made here: one slow aircraft
    passes the data's centre when the ownship, crossing through the centre from any side,
    gets there. Without avoidance that is one loss, the intruder in the world from the
    start; with the ring's resolver none, and the ownship still arrives."""
    import sys
    from pathlib import Path

    radius, speed = 20000.0, 230.0
    meet = radius / speed  # s: the ownship at the centre
    span = 2 * radius / speed + 300.0  # the cases' start times are then all 0
    t = np.arange(0.0, span, 10.0)
    slow = _line("S", (0.0, 0.0), 30.0, t)
    # _line flies at 200 m/s; slow it to 50 m/s, at the centre at `meet`
    x = (slow.x_m - slow.x_m[0]) / 4 + 50.0 * math.cos(math.radians(30)) * -meet
    y = (slow.y_m - slow.y_m[0]) / 4 + 50.0 * math.sin(math.radians(30)) * -meet
    from airspace_sim.recorded.flights import Flight, turn_rates

    s = Flight("S", "S", "", t, x, y, slow.vx / 4, slow.vy / 4,
               turn_rates(t, slow.vx, slow.vy), slow.altitude_m)  # fmt: skip
    _write_csv(tmp_path / "f.csv", [s])  # in the frame centred at (47, 8)
    bench = Path(__file__).resolve().parents[1] / "docs" / "benchmarks"
    monkeypatch.syspath_prepend(str(bench))
    sys.modules.pop("ownship_in_real_traffic", None)
    import ownship_in_real_traffic as bench_mod

    out = tmp_path / "rows.jsonl"
    ring = str(bench.parents[1] / "scenarios" / "ring.toml")
    args = ["--file", str(tmp_path / "f.csv"), "--cases", "2", "--radius", str(radius),
            "--offset", "0", "--min-altitude-ft", "0", "--tracker", "imm-ct", "--centre", "47", "8",
            "--kinds", "none", ring, "--out", str(out)]  # fmt: skip
    assert bench_mod.main(args) == 0
    rows = [json.loads(line) for line in out.read_text().splitlines()]
    want = [(0, "none"), (0, ring), (1, "none"), (1, ring)]
    assert [(r["case"], r["kind"]) for r in rows] == want
    for r in rows:
        assert r["start_s"] == 0 and r["arrived"] == 1
        if r["kind"] == "none":
            assert r["los_pairs"] == 1 and r["closest_m"] < 1000.0
            assert r["los_entered_s"] == [0]  # there from the start: not a pop-in
            assert 0.8 * meet - 20 < r["los_at_s"][0] < meet
        else:
            assert r["los_pairs"] == 0 and r["closest_m"] >= 3000.0
    text = capsys.readouterr().out
    assert "none imm-ct: 2 crossings, LoS pairs 2 in 2 (0 within 30 s of the start, 0 with" in text
    assert f"{ring} imm-ct: 2 crossings, LoS pairs 0" in text
