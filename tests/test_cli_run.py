"""The ``airspace-sim run`` command: user errors as one line (subprocess), runs, frames, summary."""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from airspace_sim.commands import run as run_cmd

REPO = Path(__file__).resolve().parent.parent

try:
    from airspace_sim.world import World  # noqa: F401

    world_ready = True
except ImportError:
    world_ready = False
renderer_ready = importlib.util.find_spec("airspace_sim.rendering.renderer") is not None
needs_world = pytest.mark.skipif(not world_ready, reason="airspace_sim.world.World not written yet")


def cli(*args, cwd=None, env=None, timeout=120):
    """Run ``python -m airspace_sim`` in a subprocess; returns the CompletedProcess."""
    full_env = {**os.environ, "AIRSPACE_SIM_PLUGINS": "", **(env or {})}
    return subprocess.run(
        [sys.executable, "-m", "airspace_sim", *args],
        cwd=cwd or REPO,
        env=full_env,
        capture_output=True,
        text=True,
        timeout=timeout,
    )


class Result:
    def __init__(self, returncode, stdout, stderr):
        self.returncode, self.stdout, self.stderr = returncode, stdout, stderr


def main_in_process(capsys, *args):
    """The same entry point in this process (faster: imports and JIT once per session)."""
    from airspace_sim.cli import main

    capsys.readouterr()
    rc = main(list(args))
    out, err = capsys.readouterr()
    return Result(rc, out, err)


def assert_one_line_error(proc, *needles):
    assert proc.returncode == 2, (proc.returncode, proc.stderr)
    err = proc.stderr.strip()
    assert "Traceback" not in proc.stderr
    assert len(err.splitlines()) == 1, err
    assert err.startswith("airspace-sim run: error: "), err
    for needle in needles:
        assert needle in err, (needle, err)
    return err


# --------------------------------------------------------------------------- user errors


def test_unknown_scenario(tmp_path):
    assert_one_line_error(cli("run", "nope", cwd=tmp_path), "unknown scenario 'nope'", "head_on")


def test_bad_set_subprocess(tmp_path):
    assert_one_line_error(
        cli("run", "head_on", "--set", "traffic.count=abc", cwd=tmp_path),
        "--set traffic.count:",
        "non-negative integer",
        "'abc'",
    )


@pytest.mark.parametrize(
    "override, needles",
    [
        ("traffic.count=-3", ["--set traffic.count:", "-3"]),
        ("trafic.count=3", ["--set trafic:", "unknown key", "did you mean 'traffic'"]),
        ("traffic.count", ["--set traffic.count:", "key=value"]),
        ("resolver.kind=nope", ["--set resolver.kind:", "resolver", "'nope'"]),
        ("tracker.kind=nope", ["--set tracker.kind:", "tracker", "'nope'"]),
        ("sensor.kind=nope", ["'nope'"]),
    ],
)
def test_bad_set(tmp_path, monkeypatch, capsys, override, needles):
    monkeypatch.chdir(tmp_path)
    assert_one_line_error(
        main_in_process(capsys, "run", "head_on", "--steps", "1", "--set", override), *needles
    )


BAD_FILES = {
    "unknown_key.toml": (
        'name = "x"\n[sensor]\nsigam = 3.0\n',
        ["sensor.sigam", "unknown key", "3"],
    ),
    "wrong_type.toml": ('name = "x"\n[traffic]\ncount = "many"\n', ["traffic.count", "'many'"]),
    "out_of_range.toml": (
        'name = "x"\n[traffic]\ncount = -3\n',
        ["traffic.count: expected a non-negative integer up to 100000, got -3"],
    ),
    "malformed.toml": ('name = "x"\n[traffic\ncount = 3\n', ["invalid TOML at line 2, column"]),
}


def test_bad_scenario_file_subprocess(tmp_path):
    text, needles = BAD_FILES["malformed.toml"]
    (tmp_path / "malformed.toml").write_text(text)
    err = assert_one_line_error(cli("run", "malformed.toml", cwd=tmp_path), *needles)
    assert "error: malformed.toml: " in err


@pytest.mark.parametrize("filename", sorted(BAD_FILES))
def test_bad_scenario_file(tmp_path, monkeypatch, capsys, filename):
    monkeypatch.chdir(tmp_path)
    text, needles = BAD_FILES[filename]
    (tmp_path / filename).write_text(text)
    err = assert_one_line_error(main_in_process(capsys, "run", filename), *needles)
    assert f"error: {filename}: " in err  # the file is named (relative to the working folder)


def test_missing_file(tmp_path):
    assert_one_line_error(
        cli("run", "missing.toml", cwd=tmp_path), "missing.toml", "no such scenario file"
    )


def test_gif_needs_render(tmp_path):
    assert_one_line_error(cli("run", "head_on", "--gif", cwd=tmp_path), "--gif needs --render")


@needs_world
@pytest.mark.skipif(
    importlib.util.find_spec("imageio_ffmpeg") is not None, reason="ffmpeg is installed"
)
def test_mp4_without_ffmpeg_is_one_line(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    proc = main_in_process(capsys, "run", "head_on", "--steps", "1", "--render", "out", "--mp4")
    assert_one_line_error(proc, "--render out", "mp4 video needs", "imageio-ffmpeg")


@pytest.mark.parametrize(
    "args,needle",
    [
        (["--steps", "0"], "--steps: expected a positive integer, got 0"),
        (["--steps", "2.5"], "--steps: expected a positive integer, got '2.5'"),
        (
            ["--seed", "-1"],
            "--seed: expected a seed from 0 to 2**63-1 = 9223372036854775807, got -1",
        ),
        (["--every", "x"], "--every: expected a positive integer, got 'x'"),
        (["--fps", "0"], "--fps: expected a positive number, got '0'"),
        (["--fps", "nan"], "--fps: expected a positive number, got 'nan'"),
        (["--size", "10x10"], "--size: expected at least 64x64 pixels, got '10x10'"),
        (["--size", "wide"], "--size: expected WIDTHxHEIGHT in pixels, e.g. 800x800, got 'wide'"),
    ],
)
def test_bad_option_values_name_the_option(capsys, args, needle):
    from airspace_sim.cli import build_parser

    with pytest.raises(SystemExit) as exc:
        build_parser().parse_args(["run", "head_on", *args])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0] == f"airspace-sim run: error: argument {needle} (see airspace-sim run --help)"


def test_option_types_accept_good_values():
    from airspace_sim.commands import _args

    assert _args.positive_int("3") == 3 and _args.non_negative_int("0") == 0
    assert _args.positive_float("2.5") == 2.5 and _args.frame_size("320X200") == (320, 200)


def test_render_into_a_file_is_one_line(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "taken").write_text("x")
    proc = main_in_process(capsys, "run", "head_on", "--steps", "1", "--render", "taken/out")
    assert_one_line_error(proc, "--render taken/out", "cannot create folder")


def test_list(tmp_path):
    proc = cli("run", "--list", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    names = [line.split()[0] for line in proc.stdout.splitlines()]
    assert {"head_on", "ring", "paper_encounter", "demo"} <= set(names)


# --------------------------------------------------------------------------- helpers


def test_jsonable_and_table():
    metrics = {
        "los": np.int64(3),
        "min_sep": np.float64(1234.5678),
        "nan": float("nan"),
        "per": {"a": np.array([1.0, 2.0])},
        "flag": np.bool_(True),
    }
    out = run_cmd.jsonable(metrics)
    assert out == {
        "los": 3,
        "min_sep": 1234.5678,
        "nan": None,
        "per": {"a": [1.0, 2.0]},
        "flag": True,
    }
    json.dumps(out, allow_nan=False)
    table = run_cmd.format_table(
        {
            "scenario": "x",
            "seed": 1,
            "steps": 5,
            "simulated_time": 5.0,
            "wall_time": 0.1,
            "steps_per_second": 50.0,
            "metrics": out,
        }
    )
    lines = table.splitlines()
    assert any(line.split() == ["per.a", "[1,", "2]"] for line in lines), table
    assert any(line.split() == ["min_sep", "1235"] for line in lines), table


def test_track_owners_default_and_choice():
    from types import SimpleNamespace

    from airspace_sim.errors import UserError

    ids = ["markov1", "markov2", "ownship", "ring00"]
    snap = SimpleNamespace(  # the fields of a Snapshot it reads
        ids=ids, controlled=np.zeros(4, bool), avoid=np.array([False, False, True, True])
    )
    assert run_cmd.track_owners(snap, None) == ["ownship"]  # first aircraft that tracks
    assert run_cmd.track_owners(snap, "all") == "all"
    assert run_cmd.track_owners(snap, "ring00, markov1") == ["ring00", "markov1"]
    with pytest.raises(UserError, match="--owners: no aircraft 'nope'"):
        run_cmd.track_owners(snap, "ring00,nope")
    snap.controlled[3] = True
    assert run_cmd.track_owners(snap, None) is None  # the renderer's default: the agents
    snap.controlled[3] = False
    snap.avoid[:] = False
    assert run_cmd.track_owners(snap, None) is None


# --------------------------------------------------------------------------- real runs


def _summary_without_timing(path):
    s = json.loads(Path(path).read_text())
    for key in ("wall_time", "steps_per_second"):
        s.pop(key)
    return s


@needs_world
@pytest.mark.skipif(not renderer_ready, reason="airspace_sim.rendering not written yet")
def test_run_renders_frames_gif_and_summary(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "frames"
    proc = main_in_process(
        capsys,
        "run",
        "demo",
        "--steps",
        "6",
        "--every",
        "2",
        "--render",
        str(out),
        "--gif",
        "--size",
        "200x160",
        "--json",
        str(tmp_path / "s.json"),
    )
    assert proc.returncode == 0, proc.stderr
    import imageio.v3 as iio

    pngs = sorted(out.glob("frame_*.png"))
    assert [p.name for p in pngs] == [f"frame_{k:05d}.png" for k in range(4)]  # t=0, 2, 4, 6
    for p in pngs:
        img = iio.imread(p)
        assert img.shape == (160, 200, 3) and img.dtype == np.uint8
        assert img.reshape(-1, 3).std(axis=0).max() > 5.0, f"{p.name} is blank"
    assert not np.array_equal(iio.imread(pngs[0]), iio.imread(pngs[-1])), "frames do not change"
    gif = iio.imread(out / "run.gif", index=None)
    assert gif.shape[0] == 4
    summary = json.loads((out / "summary.json").read_text())
    assert summary["scenario"] == "demo" and summary["seed"] == 7 and summary["steps"] == 6
    assert summary["frames"] == 4 and summary["simulated_time"] == pytest.approx(6.0)
    assert isinstance(summary["metrics"], dict) and summary["metrics"]
    assert json.loads((tmp_path / "s.json").read_text()) == summary
    assert "metric" in proc.stdout and "demo" in proc.stdout


def _run_json(capsys, path, *args):
    proc = main_in_process(capsys, "run", *args, "--json", str(path), "--quiet")
    assert proc.returncode == 0, proc.stderr
    return _summary_without_timing(path)


@needs_world
def test_run_is_reproducible_and_seed_matters(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    args = ["dense_random", "--steps", "5", "--set", "traffic.count=12"]
    sa = _run_json(capsys, tmp_path / "a.json", *args, "--seed", "5")
    sb = _run_json(capsys, tmp_path / "b.json", *args, "--seed", "5")
    sc = _run_json(capsys, tmp_path / "c.json", *args, "--seed", "6")
    assert sa == sb
    assert sa["seed"] == 5 and sa["overrides"] == ["traffic.count=12"] and sa["steps"] == 5
    assert sa["simulated_time"] == pytest.approx(5.0)
    assert sa["metrics"]["aircraft"] == 12
    assert sa != sc


@needs_world
def test_run_stops_when_everybody_left(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    # the head-on pair reaches its last waypoints (60 km away at 230 m/s) after ~261 s
    s = _run_json(
        capsys, tmp_path / "s.json", "head_on", "--steps", "1000", "--set", "resolver.kind=none"
    )
    assert s["all_left"] and s["steps"] < 1000


@needs_world
def test_checkpoint_resume_matches_uninterrupted_run(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    ckpt = tmp_path / "run.pkl"
    common = ["--set", "traffic.count=8"]
    whole = _run_json(capsys, tmp_path / "whole.json", "dense_random", "--steps", "8", *common)
    first = _run_json(
        capsys,
        tmp_path / "first.json",
        "dense_random",
        "--steps",
        "3",
        *common,
        "--checkpoint",
        str(ckpt),
    )
    assert first["steps"] == 3 and ckpt.is_file()
    second = _run_json(capsys, tmp_path / "second.json", "--resume", str(ckpt), "--steps", "5")
    assert second["total_steps"] == 8 and second["steps"] == 5
    assert second["metrics"] == whole["metrics"]
    assert second["simulated_time"] == pytest.approx(whole["simulated_time"])
    assert second["overrides"] == ["traffic.count=8"]


RING6 = ["ring", "--set", "traffic.count=6", "--set", "traffic.radius=10000.0"]
RING6 += ["--set", "resolver.kind=none"]


@needs_world
def test_checkpoint_stores_the_world_and_resumes_it_bit_for_bit(tmp_path, monkeypatch, capsys):
    # Saved at 43 s, in the middle of the ring's LoS and NMAC episodes (pairs overlapping,
    # tracks alive); resumed through the separations until every aircraft has left. Oracles: the uninterrupted run's summary and its final world.
    from test_pickle import world_state

    from airspace_sim.commands.run import load_checkpoint

    monkeypatch.chdir(tmp_path)
    whole_ckpt, part = tmp_path / "whole.ckpt", tmp_path / "part.ckpt"
    whole = _run_json(
        capsys, tmp_path / "w.json", *RING6, "--steps", "100", "--checkpoint", str(whole_ckpt)
    )
    first = _run_json(
        capsys, tmp_path / "a.json", *RING6, "--steps", "43", "--checkpoint", str(part)
    )
    assert first["metrics"]["los_events"] > 0

    # the checkpoint holds the world at step 43: loading it takes no step
    def no_stepping(self, *args, **kwargs):
        raise AssertionError("load_checkpoint stepped the world (a replay)")

    with monkeypatch.context() as m:
        m.setattr(World, "step", no_stepping)
        saved, meta = load_checkpoint(part)
    assert saved.step_count == 43 and saved.in_los.any() and len(saved.tracks) > 0
    assert meta["total_steps"] == 43 and meta["overrides"] == RING6[2::2]

    rest = _run_json(
        capsys,
        tmp_path / "b.json",
        "--resume",
        str(part),
        "--steps",
        "57",
        "--checkpoint",
        str(part),
    )
    assert whole["all_left"] and 43 < whole["steps"] < 100  # everybody left: both stop there
    assert rest["steps"] == whole["steps"] - 43 and rest["total_steps"] == whole["steps"]
    assert rest["metrics"] == whole["metrics"]
    assert rest["simulated_time"] == whole["simulated_time"]
    final_whole, _ = load_checkpoint(whole_ckpt)
    final_rest, _ = load_checkpoint(part)
    assert world_state(final_rest) == world_state(final_whole)


def test_checkpoint_does_not_overwrite_other_files(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "notes.txt").write_text("precious")
    assert_one_line_error(
        main_in_process(capsys, "run", "head_on", "--checkpoint", "notes.txt"),
        "--checkpoint notes.txt: exists and is not an airspace-sim checkpoint",
    )
    assert (tmp_path / "notes.txt").read_text() == "precious"
    assert_one_line_error(
        main_in_process(capsys, "run", "head_on", "--checkpoint-every", "3"),
        "--checkpoint-every needs --checkpoint PATH",
    )


# --------------------------------------------------------------------------- bench-world


def test_bench_world_report_with_a_fake_benchmark(monkeypatch, capsys, tmp_path):
    import types

    calls = []

    def fake_bench_world(n_aircraft, steps, trackers):
        calls.append((n_aircraft, steps, trackers))
        # time per step ∝ N (without trackers) or N^1.5 (with); the IMM a fifth of it
        ms = 1e-2 * n_aircraft * (n_aircraft**0.5 if trackers else 1.0)
        out = {
            "ms_per_step": ms,
            "cpu_ms_per_step": ms / 2.0,
            "steps_per_s": 1000.0 / ms,
            "mean_tracks": 50.0 * n_aircraft,
        }
        if trackers:
            out["imm"] = {"ms_per_step": ms / 5.0, "cpu_ms_per_step": ms / 8.0, "kernel": "loops"}
            out["ratio"], out["cpu_ratio"] = 5.0, 4.0
        return out

    monkeypatch.setitem(
        sys.modules,
        "airspace_sim.world.benchmark",
        types.SimpleNamespace(bench_world=fake_bench_world),
    )
    proc = main_in_process(
        capsys,
        "bench-world",
        "--steps",
        "7",
        "--trackers",
        "both",
        "--json",
        str(tmp_path / "b.json"),
    )
    assert proc.returncode == 0, proc.stderr
    sizes = [100, 1000, 3000]
    assert calls == [(n, 7, False) for n in sizes] + [(n, 7, True) for n in sizes]
    assert (
        "trackers off: 100 → 1000 aircraft (×10): time per step ×10.00, growth exponent 1.00"
        in proc.stdout
    )
    assert (
        "trackers on: 100 → 1000 aircraft (×10): time per step ×31.62, growth exponent 1.50"
        in proc.stdout
    )
    # with trackers: world ms, the bare IMM's ms and their ratio on the size's line
    line = next(ln for ln in proc.stdout.splitlines() if ln.split()[:2] == ["1000", "on"])
    assert line.split()[2:9] == ["50000", "316.23", "63.25", "5.00", "158.11", "39.53", "4.00"]
    data = json.loads((tmp_path / "b.json").read_text())
    assert [r["aircraft"] for r in data["results"]] == sizes + sizes
    assert data["results"][4]["imm_ms_per_step"] == pytest.approx(316.227766 / 5)
    assert data["growth"][0]["exponent"] == pytest.approx(1.0)


@pytest.mark.skipif(
    importlib.util.find_spec("airspace_sim.world.benchmark") is None,
    reason="airspace_sim.world.benchmark not written yet",
)
def test_bench_world_real_smoke(capsys, tmp_path):
    proc = main_in_process(
        capsys,
        "bench-world",
        "--sizes",
        "4",
        "8",
        "--steps",
        "2",
        "--trackers",
        "both",
        "--json",
        str(tmp_path / "b.json"),
    )
    assert proc.returncode == 0, proc.stderr
    data = json.loads((tmp_path / "b.json").read_text())
    assert [(r["aircraft"], r["trackers"]) for r in data["results"]] == [
        (4, False),
        (8, False),
        (4, True),
        (8, True),
    ]
    assert all(r["ms_per_step"] > 0 for r in data["results"])
    on = [r for r in data["results"] if r["trackers"]]
    assert all(r["imm_ms_per_step"] > 0 and r["ratio"] > 0 for r in on)
    assert len(data["growth"]) == 2 and "growth exponent" in proc.stdout


@needs_world
def test_periodic_checkpoint_resumes_the_rest_of_the_run(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    from airspace_sim.commands.run import load_checkpoint, save_checkpoint

    ckpt = tmp_path / "run.pkl"
    saved = []

    def spy(path, world, meta):  # Ctrl-C right after the first periodic save
        save_checkpoint(path, world, meta)
        saved.append((world.step_count, dict(meta)))
        if len(saved) == 1:
            raise KeyboardInterrupt

    monkeypatch.setattr(run_cmd, "save_checkpoint", spy)
    proc = main_in_process(
        capsys,
        "run",
        "head_on",
        "--steps",
        "9",
        "--checkpoint",
        str(ckpt),
        "--checkpoint-every",
        "4",
        "--quiet",
    )
    assert proc.returncode == 130 and "interrupted" in proc.stderr
    meta = {
        "scenario": "head_on",
        "source": saved[0][1]["source"],
        "seed": 0,
        "overrides": [],
        "total_steps": 9,
    }
    assert saved == [(4, meta), (4, meta)]  # the periodic save, then the one on Ctrl-C
    monkeypatch.undo()
    monkeypatch.chdir(tmp_path)
    world, meta = load_checkpoint(ckpt)
    assert world.step_count == 4
    rest = _run_json(capsys, tmp_path / "rest.json", "--resume", str(ckpt))  # the remaining 5
    whole = _run_json(capsys, tmp_path / "whole.json", "head_on", "--steps", "9")
    assert rest["steps"] == 5 and rest["total_steps"] == 9
    assert rest["metrics"] == whole["metrics"]
