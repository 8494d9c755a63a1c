"""The figures command writes the expected, valid, reasonably sized PNGs."""

import struct

from airspace_sim import cli
from airspace_sim.encounters.figures import FILES

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _png_size(data: bytes):
    assert data[:8] == PNG_SIGNATURE
    assert data[12:16] == b"IHDR"
    return struct.unpack(">II", data[16:24])


def test_figures_command_writes_the_pngs(tmp_path, capsys):
    out = tmp_path / "figs"
    assert cli.main(["figures", "--out", str(out), "--runs", "12"]) == 0
    printed = capsys.readouterr().out.split()
    assert sorted(p.name for p in out.iterdir()) == sorted(FILES)
    assert len(printed) == len(FILES)
    for name in FILES:
        data = (out / name).read_bytes()
        width, height = _png_size(data)
        assert 600 <= width <= 2000 and 400 <= height <= 1500, (name, width, height)
        assert 20_000 < len(data) < 2_000_000, (name, len(data))
        assert data.endswith(b"IEND\xaeB`\x82")


def test_figures_bad_input_is_exit_2(tmp_path, capsys):
    f = tmp_path / "file"
    f.write_text("x")
    assert cli.main(["figures", "--out", str(f)]) == 2
    assert cli.main(["figures", "--out", str(tmp_path / "d"), "--runs", "0"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and all("error" in line for line in err)
