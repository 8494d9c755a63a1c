"""Sweeps: grid parsing, rows equal to the worlds run directly, any worker count, resume, CLI."""

import math
import os

import numpy as np
import pyarrow.parquet as pq
import pytest
from _tables import same_rows
from scipy import stats

from airspace_sim import cli
from airspace_sim.errors import UserError
from airspace_sim.experiments import LocalBackend
from airspace_sim.experiments.summary import format_summary, mean_ci, summarize
from airspace_sim.experiments.sweep import (
    grid_keys,
    parse_axis,
    parse_seeds,
    plan,
    run_sweep,
    split_top_level,
)
from airspace_sim.scenarios import load
from airspace_sim.world import World

STEPS = 40
THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")
GRID = ["resolver.kind=bands,none", "sensor.sigma=30,80.5"]
SET = ["duration=60"]


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    out = tmp_path_factory.mktemp("ref") / "ref.parquet"
    return run_sweep("head_on", GRID, "0-2", out, SET, steps=STEPS, progress=False)


def test_split_and_parse_axis():
    assert split_top_level("1,[2,3],{a=1,b=2},'x,y'") == ["1", "[2,3]", "{a=1,b=2}", "'x,y'"]
    a = parse_axis("traffic.count,traffic.radius=[8,20000],[16,20000.5]")
    assert a.keys == ("traffic.count", "traffic.radius")
    assert a.values == (("8", "20000"), ("16", "20000.5"))
    assert parse_axis("resolver.kind=bands, seed").values == (("bands",), ("seed",))


@pytest.mark.parametrize(
    "item,needle",
    [
        ("traffic.count", "expected KEY=V1,V2"),
        ("traffic.count=1,,2", "empty value"),
        ("traffic.count=1,1", "repeated"),
        ("seed=1,2", "--seeds"),
        ("a,b=[1],[2,3]", "array of 2"),
        ("bad key!=1", "malformed key"),
    ],
)
def test_bad_axis_is_one_line_user_error(item, needle):
    with pytest.raises(UserError, match=needle) as e:
        parse_axis(item)
    assert "\n" not in str(e.value)


def test_parse_seeds():
    assert parse_seeds("0-3") == [0, 1, 2, 3]
    assert parse_seeds("5") == [5]
    assert parse_seeds("0-1,7,9-10") == [0, 1, 7, 9, 10]
    for bad in ("-1", "3-1", "x", "1,1", str(2**63), "0-99999999"):
        with pytest.raises(UserError, match="--seeds"):
            parse_seeds(bad)


def test_plan_is_the_product_in_order():
    runs = plan([parse_axis("a=1,2"), parse_axis("b=x,y,z")], [4, 5])
    assert len(runs) == 12
    assert [r.cell for r in runs] == [c for c in range(6) for _ in (4, 5)]
    assert runs[2].settings == (("a", "1"), ("b", "y")) and runs[3].seed == 5
    assert len({r.key for r in runs}) == 12


def test_rows_are_the_worlds_run_directly(reference):
    t = reference
    assert t.num_rows == 12
    assert t.column_names[:4] == ["settings", "resolver.kind", "sensor.sigma", "seed"]
    assert grid_keys(t) == ["resolver.kind", "sensor.sigma"]
    assert str(t.schema.field("sensor.sigma").type) == "double"
    rows = t.to_pylist()
    # order: the grid's product (last axis fastest), then seeds
    assert [(r["resolver.kind"], r["sensor.sigma"], r["seed"]) for r in rows[:4]] == [
        ("bands", 30.0, 0),
        ("bands", 30.0, 1),
        ("bands", 30.0, 2),
        ("bands", 80.5, 0),
    ]
    for r in rows[::5]:  # brute-force oracle: the same world, built and run by hand
        sc = load(
            "head_on",
            [*SET, f"resolver.kind={r['resolver.kind']}", f"sensor.sigma={r['sensor.sigma']}"],
        )
        m = World(sc, seed=r["seed"]).run(STEPS)
        assert set(m) <= set(r)
        for k, v in m.items():
            assert r[k] == v or (v != v and r[k] != r[k]), k
    assert len({r["track_rmse_m"] for r in rows}) > 1  # seeds and settings matter


def test_two_workers_and_resume_give_the_same_rows(tmp_path, reference, monkeypatch):
    for var in THREAD_VARS:  # unset, as for most users: the workers' "1" must not leak here
        monkeypatch.delenv(var, raising=False)
    environ = dict(os.environ)
    two = run_sweep(
        "head_on", GRID, "0-2", tmp_path / "k2.parquet", SET, steps=STEPS, workers=2, progress=False
    )
    assert dict(os.environ) == environ  # the parent's environment is unchanged
    assert same_rows(two, reference)
    assert same_rows(pq.read_table(tmp_path / "k2.parquet"), reference)
    # an interrupted sweep (fewer seeds, one resolver) resumed with the full grid
    out = tmp_path / "resumed.parquet"
    part = run_sweep(
        "head_on",
        ["resolver.kind=none", GRID[1]],
        "1",
        out,
        SET,
        steps=STEPS,
        progress=False,
    )
    assert part.num_rows == 2
    parts = out.with_name(out.name + ".parts")
    before = {p.name: p.stat().st_mtime_ns for p in parts.glob("part-*.parquet")}
    resumed = run_sweep("head_on", GRID, "0-2", out, SET, steps=STEPS, progress=False)
    assert same_rows(resumed, reference)
    after = {p.name: p.stat().st_mtime_ns for p in parts.glob("part-*.parquet")}
    assert all(after[n] == t for n, t in before.items())  # finished runs not run again
    assert len(after) == 12


def test_workers_get_one_thread_each_or_the_users_setting(monkeypatch):
    for var in THREAD_VARS:
        monkeypatch.delenv(var, raising=False)
    monkeypatch.setenv("OMP_NUM_THREADS", "3")  # the user's choice is passed on
    environ = dict(os.environ)
    with LocalBackend(2) as backend:
        seen = dict(backend.imap(os.getenv, [(v,) for v in THREAD_VARS]))
    assert [seen[i] for i in range(len(THREAD_VARS))] == ["3", "1", "1", "1"]
    assert dict(os.environ) == environ


def test_resume_with_another_scenario_setting_is_refused(tmp_path):
    out = tmp_path / "r.parquet"
    run_sweep("head_on", [], "0", out, SET, steps=3, progress=False)
    with pytest.raises(UserError, match="overrides"):
        run_sweep("head_on", [], "0", out, ["duration=61"], steps=3, progress=False)


def test_resume_with_a_changed_recording_is_refused(tmp_path):
    """The manifest holds the SHA-256 of the [recorded] file: the same scenario text over
    a changed recording is other rows, refused with the manifest's one line."""
    pytest.importorskip("pandas")
    pytest.importorskip("pyproj")
    from test_replay import _crossing
    from test_replay_files import _write_csv

    a, b = _crossing()
    _write_csv(tmp_path / "f.csv", [a, b])
    (tmp_path / "rec.toml").write_text(
        'name = "rec"\nduration = 100\n[recorded]\nfile = "f.csv"\nvelocity = "positions"\n'
    )
    out = tmp_path / "r.parquet"
    first = run_sweep(tmp_path / "rec.toml", [], "0", out, steps=3, progress=False)
    assert first.num_rows == 1 and first.column("aircraft").to_pylist() == [2]
    again = run_sweep(tmp_path / "rec.toml", [], "0-1", out, steps=3, progress=False)
    assert again.num_rows == 2  # unchanged recording: resumes
    _write_csv(tmp_path / "f.csv", [a])  # one flight fewer
    with pytest.raises(UserError) as info:
        run_sweep(tmp_path / "rec.toml", [], "0-1", out, steps=3, progress=False)
    msg = str(info.value)
    assert "\n" not in msg and "made with a different recorded_sha256" in msg, msg
    assert f"use another --out or delete {out}.parts" in msg


def test_bad_grid_value_is_named_before_any_work(tmp_path):
    out = tmp_path / "bad.parquet"
    with pytest.raises(UserError, match=r"^--grid traffic.count=-3") as e:
        run_sweep("ring", ["traffic.count=8,-3"], "0", out, progress=False)
    assert "\n" not in str(e.value)
    assert not out.with_name(out.name + ".parts").exists()
    with pytest.raises(UserError, match="radius"):  # traffic-level check (ring too small)
        run_sweep("ring", ["traffic.count=8,500"], "0", out, progress=False)


def test_summary_interval_is_students_t(reference):
    rows = summarize(reference, ["resolver.kind", "sensor.sigma"], ["track_rmse_m"])
    assert len(rows) == 4 and all(r["runs"] == 3 for r in rows)
    vals = [r["track_rmse_m"] for r in reference.to_pylist()[:3]]
    lo, hi = stats.t.interval(0.95, 2, loc=np.mean(vals), scale=stats.sem(vals))
    assert math.isclose(rows[0]["track_rmse_m"], np.mean(vals))
    assert math.isclose(rows[0]["track_rmse_m_ci"], (hi - lo) / 2)
    assert mean_ci([1.0, math.inf, 3.0])[2] == 2 and math.isnan(mean_ci([2.0])[1])
    text = format_summary(rows, ["resolver.kind", "sensor.sigma"], markdown=True)
    assert text.startswith("| resolver.kind | sensor.sigma | runs | track_rmse_m (95% CI) |")


def test_cli_sweep_summary_and_plot(tmp_path, capsys):
    out = tmp_path / "c.parquet"
    code = cli.main(
        [
            "sweep",
            "head_on",
            "--grid",
            "resolver.kind=bands,none",
            "--grid",
            "sensor.sigma=30,60",
            "--seeds",
            "0-1",
            "--set",
            "duration=60",
            "--steps",
            "5",
            "--out",
            str(out),
            "--plot",
            "min_separation_m",
            "--x",
            "sensor.sigma",
            "--hue",
            "resolver.kind",
            "--summary-md",
            str(tmp_path / "s.md"),
            "--no-progress",
        ]
    )
    text = capsys.readouterr().out
    assert code == 0, text
    assert "los_events (95% CI)" in text and "8 rows" in text
    png = tmp_path / "c-min_separation_m.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert (tmp_path / "s.md").read_text().startswith("| resolver.kind | sensor.sigma |")


@pytest.mark.parametrize(
    "args,needle",
    [
        (["--grid", "traffic.count=x"], "--grid traffic.count=x"),
        (["--seeds", "3-1"], "--seeds"),
        (["--plot", "los_events"], "--x"),
        (["--plot", "los_events", "--x", "nope", "--grid", "sensor.sigma=30"], "--x: 'nope'"),
        (["--address", "127.0.0.1:1"], "--address"),
        (["--summary-md", "/nonexistent/dir/s.md"], "--summary-md"),
        (["--grid", "sensor.sigma=30", "--set", "sensor.sigma=40"], "give it once"),
    ],
)
def test_bad_cli_input_is_one_line_exit_2(tmp_path, capsys, args, needle):
    out = tmp_path / "x.parquet"
    code = cli.main(["sweep", "head_on", "--steps", "2", "--out", str(out), "--no-progress", *args])
    err = capsys.readouterr().err
    assert code == 2, err
    assert needle in err and len(err.strip().splitlines()) == 1, err
    assert not out.exists()


def test_ray_backend_without_ray_says_what_to_install(monkeypatch):
    import sys

    from airspace_sim.experiments import make_backend

    monkeypatch.setitem(sys.modules, "ray", None)  # import ray -> ImportError
    with pytest.raises(UserError, match=r"pip install 'airspace-sim\[ray\]'"):
        make_backend("ray", 2)
    with pytest.raises(UserError, match="--backend"):
        make_backend("dask", 2)


def test_grid_and_set_of_one_key_is_refused(tmp_path):
    with pytest.raises(UserError, match="give it once"):
        run_sweep(
            "head_on",
            ["aircraft[0].speed=200,210"],
            "0",
            tmp_path / "x.parquet",
            ["aircraft[0].speed=220"],
            steps=2,
            progress=False,
        )
