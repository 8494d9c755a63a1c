"""Campaigns: identical for any worker count, resumable without duplicates, CLI errors."""

import pyarrow.parquet as pq
import pytest
from _tables import same_rows

from airspace_sim import cli
from airspace_sim.encounters.campaign import format_summary, run_campaign, summarize
from airspace_sim.errors import UserError

RESOLVERS = "seed,bands"


def _keys(table):
    return list(zip(table.column("resolver").to_pylist(), table.column("encounter").to_pylist()))


def test_workers_do_not_change_results(tmp_path):
    one = run_campaign(
        tmp_path / "k1.parquet", 20, RESOLVERS, workers=1, chunk_size=5, progress=False
    )
    two = run_campaign(
        tmp_path / "k2.parquet", 20, RESOLVERS, workers=2, chunk_size=5, progress=False
    )
    assert one.num_rows == 40
    assert 0 < sum(one.column("n_manoeuvres").to_pylist())
    assert same_rows(one, two)
    assert same_rows(pq.read_table(tmp_path / "k2.parquet"), two)
    assert format_summary(summarize(one)) == format_summary(summarize(two))
    # sorted by (resolver, encounter), no duplicates
    keys = _keys(one)
    assert keys == sorted(keys) and len(set(keys)) == len(keys)


def test_chunking_does_not_change_results(tmp_path):
    a = run_campaign(tmp_path / "a.parquet", 12, "seed", chunk_size=12, progress=False)
    b = run_campaign(tmp_path / "b.parquet", 12, "seed", chunk_size=5, progress=False)
    assert same_rows(a, b)


def test_interrupted_run_resumes_to_the_same_table(tmp_path):
    full = run_campaign(tmp_path / "full.parquet", 20, RESOLVERS, chunk_size=5, progress=False)
    out = tmp_path / "resumed.parquet"
    part = run_campaign(out, 7, RESOLVERS, chunk_size=5, progress=False)  # "interrupted"
    assert part.num_rows == 14
    parts = out.with_name(out.name + ".parts")
    # a crash mid-write leaves only a temporary file, never a half part
    (parts / ".part-seed-0000015-0000019.parquet.999.tmp").write_bytes(b"garbage")
    out.unlink()
    resumed = run_campaign(out, 20, RESOLVERS, chunk_size=5, progress=False)
    assert same_rows(resumed, full)
    keys = _keys(resumed)
    assert len(set(keys)) == len(keys) == 40
    # running again does nothing new and gives the same table
    n_parts = len(list(parts.glob("part-*.parquet")))
    again = run_campaign(out, 20, RESOLVERS, chunk_size=5, progress=False)
    assert same_rows(again, full)
    assert len(list(parts.glob("part-*.parquet"))) == n_parts


def test_resume_with_other_settings_is_refused(tmp_path):
    out = tmp_path / "r.parquet"
    run_campaign(out, 3, "none", seed=1, progress=False)
    with pytest.raises(UserError, match="seed"):
        run_campaign(out, 3, "none", seed=2, progress=False)


def test_world_campaign_rows_and_summary(tmp_path):
    t = run_campaign(tmp_path / "w.parquet", 4, "none,bands,oracle", frame="world", progress=False)
    assert t.num_rows == 12
    rows = {r["resolver"]: r for r in summarize(t)}
    assert rows["oracle"]["los"] <= rows["none"]["los"]
    text = format_summary(list(rows.values()), markdown=True)
    assert "| bands | world | 4 |" in text


@pytest.mark.parametrize(
    "args,needle",
    [
        (["--resolver", "nope"], "unknown resolver 'nope'"),
        (["--runs", "0"], "--runs"),
        (["--workers", "0"], "--workers"),
        (["--frame", "sideways"], "--frame"),
        (["--seed", "-1"], "--seed"),
        (["--seed", str(2**70)], "--seed"),
        (["--summary-md", "/dev/null/folder/s.md"], "--summary-md"),  # a file in the path
        (["--address", "127.0.0.1:6379"], "--address: only with --backend ray"),
    ],
)
def test_bad_cli_input_is_one_line_exit_2(tmp_path, capsys, args, needle):
    code = cli.main(["encounters", "--out", str(tmp_path / "x.parquet"), "--no-progress", *args])
    err = capsys.readouterr().err
    assert code == 2
    assert needle in err
    assert len(err.strip().splitlines()) == 1
    assert not (tmp_path / "x.parquet").exists()


def test_cli_runs_and_prints_summary(tmp_path, capsys):
    code = cli.main(
        [
            "encounters",
            "--runs",
            "3",
            "--resolver",
            "none,seed",
            "--out",
            str(tmp_path / "c.parquet"),
            "--no-progress",
            "--summary-md",
            str(tmp_path / "s.md"),
        ]
    )
    out = capsys.readouterr().out
    assert code == 0
    assert "LoS rate" in out and "seed" in out
    assert (tmp_path / "s.md").read_text().startswith("| resolver |")
