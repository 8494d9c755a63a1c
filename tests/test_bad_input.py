"""Issue 11, as a hostile user tries it: every bad input is exit 2 and one line naming the
file (or option), the key and the value, with no traceback; nothing is silently accepted.

Each row is one case of the issue. Most run in this process (fast); a few go through a
subprocess to show the exit status and the absence of a traceback end to end.
"""

from __future__ import annotations

import dataclasses
import typing
from pathlib import Path

import pytest
from test_cli_run import assert_one_line_error, cli, main_in_process

from airspace_sim.scenarios import loader, schema

REPO = Path(__file__).resolve().parent.parent
HEAD_ON = ["run", "head_on", "--steps", "2", "--quiet"]
RING = ["run", "ring", "--steps", "2", "--quiet"]


def _set(*items):
    return [a for item in items for a in ("--set", item)]


# (id, argv, needles that the one error line must contain)
SET_CASES = [
    ("params-bogus", _set("resolver.params.bogus=1"), ["--set resolver.params.bogus", "unknown key", "got 1"]),
    ("params-threshold-str", _set('resolver.params.threshold="x"'), ["--set resolver.params.threshold", "unknown key", "'x'"]),
    ("params-bad-type", _set('resolver.params.left_penalty="x"'), ["--set resolver.params.left_penalty", "expected a number", "'x'"]),
    ("side-memory-negative", _set("resolver.side_memory_s=-1"), ["--set resolver.side_memory_s", "non-negative", "got -1"]),
    ("margin-nan", _set("resolver.margin=nan"), ["--set resolver.margin", "got nan"]),
    ("margin-negative", _set("resolver.margin=-5"), ["--set resolver.margin", "got -5"]),
    ("dt-denormal", _set("dt=5e-324"), ["--set dt", "≥ 0.001", "got 5e-324"]),
    ("sigma-huge", _set("sensor.sigma=1e308"), ["--set sensor.sigma", "up to 100000", "got 1e+308"]),
    ("sector-huge", _set("traffic.sector=1e308"), ["--set traffic.sector", "got 1e+308"]),
    ("radius-huge", _set("traffic.radius=1e308"), ["--set traffic.radius", "got 1e+308"]),
    ("samples-huge", _set("resolver.probability_samples=9223372036854775807"), ["--set resolver.probability_samples", "up to 1000", "9223372036854775807"]),
    ("lookahead-huge", _set("resolver.lookahead=1e308"), ["--set resolver.lookahead", "up to 3600", "1e+308"]),
    ("count-billion", _set("traffic.count=1000000000"), ["--set traffic.count", "up to 100000", "1000000000"]),
    ("speed-huge", _set("aircraft[0].speed=1e308"), ["--set aircraft[0].speed", "≥ 1 up to 1000 (m/s)", "1e+308"]),
    ("position-huge", _set("aircraft[0].position=[1e300, 0.0]"), ["--set aircraft[0].position", "within ±1e+08 m"]),
    ("heading-huge", _set("aircraft[0].heading_deg=1e300"), ["--set aircraft[0].heading_deg", "360", "1e+300"]),
    ("count-int-overflow", _set("traffic.count=1180591620717411303424"), ["--set traffic.count", "1180591620717411303424"]),
    ("seed-huge", _set("seed=-1"), ["--set seed", "got -1"]),
    ("deep-set", _set("x=" + "[" * 5000 + "]" * 5000), ["--set x", "nested too deeply"]),
    ("key-newline", ["--set", "a\nb=1"], ["--set a\\nb", "malformed key"]),
    ("key-ansi", ["--set", "\x1b[31mred=1"], ["--set \\x1b[31mred", "malformed key"]),
]  # fmt: skip


@pytest.mark.parametrize("argv,needles", [c[1:] for c in SET_CASES], ids=[c[0] for c in SET_CASES])
def test_bad_set_values_are_one_line(capsys, argv, needles):
    err = assert_one_line_error(main_in_process(capsys, *HEAD_ON, *argv), *needles)
    assert "\x1b" not in err


def test_a_track_table_too_big_for_memory_is_refused_before_allocating(capsys, monkeypatch):
    """The track table grows with the pairs in range, known only as the run goes: its growth
    is checked against physical memory before the arrays are allocated. Here the machine is
    made to look 1 MiB large; 40 aircraft of a 40 km ring all in range need more."""
    from airspace_sim import resources
    from airspace_sim.tracking import SlotIMM

    monkeypatch.setattr(resources, "physical_memory_bytes", lambda: 2**20)
    grown = []
    real_grow = SlotIMM._grow
    monkeypatch.setattr(SlotIMM, "_grow", lambda self, c: grown.append(c) or real_grow(self, c))
    argv = _set("traffic.count=40", "traffic.radius=40000", "sensor.range=100000")
    err = assert_one_line_error(
        main_in_process(capsys, *RING, *argv), "track table: growing to", "needs", "GiB"
    )
    assert "of this machine's 0.0 GiB" in err and "traffic.count" in err, err
    # brute force: the refused size is what 40·39 tracks round up to; nothing was allocated
    assert grown and grown[-1] >= 40 * 39


FILE_CASES = [
    ("empty", "", ["empty.toml: empty scenario"]),
    ("whitespace", "  \n\t\n# only a comment\n", ["whitespace.toml: empty scenario"]),
    ("no-aircraft", "aircraft = []\n", ["no-aircraft.toml: aircraft: expected at least one aircraft", "nothing to simulate"]),
    ("only-name", 'name = "x"\n[traffic]\npattern = "none"\n', ["only-name.toml: aircraft:", "got none"]),
    ("deep", "x = " + "[" * 100000 + "]" * 100000 + "\n", ["deep.toml: invalid TOML", "nested too deeply"]),
    ("key-newline", '"a\\nb" = 1\n', ["key-newline.toml: a\\nb: unknown key"]),
    ("key-ansi", '"\\u001b[31mred" = 1\n', ["key-ansi.toml: \\x1b[31mred: unknown key"]),
    ("value-ansi", 'name = "\\u001b[2J"\nseed = "\\u001b[2J"\n', ["value-ansi.toml: seed: expected", "'\\x1b[2J'"]),
    ("speed-spread-negative", '[traffic]\npattern = "ring"\ncount = 2\nspeed_spread = -1.0\n', ["speed-spread-negative.toml: traffic.speed_spread", "got -1.0"]),
]  # fmt: skip


@pytest.mark.parametrize("name,text,needles", FILE_CASES, ids=[c[0] for c in FILE_CASES])
def test_bad_files_are_one_line(tmp_path, monkeypatch, capsys, name, text, needles):
    monkeypatch.chdir(tmp_path)
    Path(f"{name}.toml").write_text(text)
    argv = ["run", f"{name}.toml", "--steps", "2", "--quiet"]
    err = assert_one_line_error(main_in_process(capsys, *argv), *needles)
    assert "\x1b" not in err


def test_signed_zero_spread_means_zero_and_runs(tmp_path, monkeypatch, capsys):
    """``speed_spread = -0.0`` once raised numpy's ``high - low < 0``; it is 0."""
    argv = _set("traffic.speed_spread=-0.0")
    proc = main_in_process(capsys, *RING, *argv)
    assert proc.returncode == 0, proc.stderr
    assert loader.load("ring", ["traffic.speed_spread=-0.0"]).traffic.speed_spread == 0.0


OPTION_CASES = [
    ("fps-nan", [*HEAD_ON, "--fps", "nan"], ["argument --fps: expected a positive number, got 'nan'"]),
    ("fps-huge", [*HEAD_ON, "--fps", "1e9"], ["argument --fps: expected at most 1000"]),
    ("size-huge", [*HEAD_ON, "--size", "100000x100000"], ["argument --size: expected at most 8192 pixels a side"]),
    ("size-area", [*HEAD_ON, "--size", "8192x8192"], ["argument --size:", "16777216 in all"]),
    ("run-seed-negative", [*HEAD_ON, "--seed", "-1"], ["argument --seed: expected a seed", "got -1"]),
    ("run-seed-2**70", [*HEAD_ON, "--seed", str(2**70)], ["argument --seed:", str(2**70)]),
    ("encounters-seed-negative", ["encounters", "--runs", "1", "--seed", "-1"], ["argument --seed:", "got -1"]),
    ("encounters-seed-2**70", ["encounters", "--runs", "1", "--seed", str(2**70)], ["argument --seed:", str(2**70)]),
]  # fmt: skip


@pytest.mark.parametrize(
    "argv,needles", [c[1:] for c in OPTION_CASES], ids=[c[0] for c in OPTION_CASES]
)
def test_bad_options_are_one_line_exit_2(capsys, argv, needles):
    from airspace_sim.cli import main

    capsys.readouterr()
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith(f"airspace-sim {argv[0]}: error: ") and err[0].endswith("--help)")
    for needle in needles:
        assert needle in err[0], err[0]


def test_summary_md_into_an_impossible_place_fails_before_the_campaign(
    tmp_path, monkeypatch, capsys
):
    import airspace_sim.encounters.campaign as campaign

    monkeypatch.chdir(tmp_path)
    Path("afile").write_text("x")
    monkeypatch.setattr(campaign, "run_campaign", lambda *a, **k: pytest.fail("campaign ran"))
    from airspace_sim.cli import main

    capsys.readouterr()
    argv = ["encounters", "--runs", "1", "--out", "o.parquet", "--summary-md", "afile/s.md"]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err == (
        "airspace-sim encounters: error: --summary-md afile/s.md: cannot create folder afile: "
        "a part of the path is a file"
    )
    # a missing folder is not an error: it is made before the campaign runs
    argv[-1] = "new/dir/s.md"
    monkeypatch.setattr(campaign, "run_campaign", lambda *a, **k: (_ for _ in ()).throw(KeyError))
    with pytest.raises(KeyError):
        main(argv)
    assert Path("new/dir").is_dir()


def test_end_to_end_exit_status_and_no_traceback(tmp_path):
    (tmp_path / "empty.toml").write_text("")
    cases = [
        (["run", "empty.toml"], "empty.toml: empty scenario"),
        (["run", "head_on", "--set", "dt=5e-324"], "--set dt: expected a number ≥ 0.001"),
        (["run", "head_on", "--size", "100000x100000"], "argument --size"),
    ]
    for argv, needle in cases:
        proc = cli(*argv, cwd=tmp_path)
        assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
        assert len(proc.stderr.strip().splitlines()) == 1 and needle in proc.stderr, proc.stderr


# --------------------------------------------------------------------------- the range table


def _numeric_fields(cls=schema.Scenario):
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        if (cls.__name__, f.name) in loader.INTERNAL_FIELDS:
            continue
        tp = hints[f.name]
        inner = [a for a in typing.get_args(tp) if dataclasses.is_dataclass(a)]
        if dataclasses.is_dataclass(tp) or inner:
            yield from _numeric_fields(tp if dataclasses.is_dataclass(tp) else inner[0])
        elif tp is not bool and ({float, int} & {tp, *typing.get_args(tp)} or "float" in repr(tp)):
            yield f"{cls.__name__}.{f.name}"


def test_every_numeric_field_has_a_range():
    missing = [k for k in _numeric_fields() if k not in loader.RANGES]
    assert not missing, f"add a range to loader.RANGES for {missing}"


def test_readme_lists_the_ranges():
    readme = (REPO / "scenarios" / "README.md").read_text()
    assert loader.ranges_table() in readme, "regenerate the table: loader.ranges_table()"
