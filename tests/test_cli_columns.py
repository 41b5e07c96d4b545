"""Every refusal that names a line names its column too (path:line:col); a refusal about
a whole block or row points at its first character. And: diff refuses a correction above --max-correction, a calibrated volume beyond
100 m is refused."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from click.testing import CliRunner

from postproc.cli import main
from postproc.errors import EXIT_CALIBRATION, EXIT_SAFETY, first_column

ROOT = Path(__file__).resolve().parents[1]
STATIC = str(ROOT / "calibrations" / "s500_static.json")
POCKET = str(ROOT / "samples" / "pocket.nc")
FANUC = str(ROOT / "samples" / "fanuc_drill.nc")
PLACE = re.compile(r"^postproc: error: (?P<path>.+?):(?P<line>\d+):(?P<col>\d+): ", re.MULTILINE)


def run(*args, **kwargs):
    return CliRunner().invoke(main, [str(a) for a in args], **kwargs)


def refusals(tmp_path):
    """(name, args, stdin) of runs refused at a line of a file."""
    table = tmp_path / "tools.tbl"
    table.write_text("T1 P1 Z100\nT2 P2 Znan\n")
    offset_program = tmp_path / "far.nc"
    offset_program.write_text("G21 G90\n  G0 X10 Y10 Z10\n  G1 X5000 F100\nM2\n")
    csv = tmp_path / "points.csv"
    csv.write_text("X,Y,Z,dx,dy,dz\n10,20,30,0.001,0,0\n10,20,abc,0,0,0\n")
    return [
        ("cycle tilt", ["correct", FANUC, "-c", STATIC, "--dialect", "fanuc", "--offset", "G54=X100,Y100,Z100",
                        "--tool-length", "1=100", "--home", "G28=X0,Y0,Z300", "--cycles", "keep",
                        "-o", tmp_path / "o.nc"], None),
        ("outside the volume", ["correct", offset_program, "-c", STATIC, "-o", tmp_path / "o.nc"], None),
        ("tool table", ["correct", POCKET, "-c", STATIC, "--tool-table", table, "-o", tmp_path / "o.nc"], None),
        ("missing offset, piped", ["correct", "-", "-c", STATIC, "-o", tmp_path / "o.nc"],
         "G21 G90\nG55 G0 X10 Y10 Z10\nM2\n"),
        ("verify cycle tilt", ["verify", FANUC, "-c", STATIC, "--machine", STATIC, "--dialect", "fanuc",
                               "--offset", "G54=X100,Y100,Z100", "--tool-length", "1=100",
                               "--home", "G28=X0,Y0,Z300", "--cycles", "keep"], None),
        ("fit bad cell", ["fit", csv, "-o", tmp_path / "cal.json"], None),
    ]


def test_line_refusals_carry_the_column(tmp_path):
    for name, args, stdin in refusals(tmp_path):
        result = run(*args, input=stdin)
        assert result.exit_code not in (0, 1), (name, result.output)
        m = PLACE.search(result.output)
        assert m, (name, result.output)
        if m["path"] != "<stdin>":
            expected = first_column(m["path"], int(m["line"]))
            assert 1 <= int(m["col"]) <= max(expected or 1, 200), (name, result.output)
    assert not (tmp_path / "o.nc").exists()


def test_a_block_refusal_points_at_the_blocks_first_character(tmp_path):
    program = tmp_path / "far.nc"
    program.write_text("G21 G90\n  G0 X10 Y10 Z10\n   G1 X5000 F100\nM2\n")
    result = run("correct", program, "-c", STATIC, "-o", tmp_path / "o.nc")
    assert f"{program}:3:4: " in result.output, result.output


def test_first_column():
    import tempfile

    with tempfile.NamedTemporaryFile("w", suffix=".nc", delete=False) as fh:
        fh.write("G0 X1\n\t  G1 X2\n\nX3")
    assert [first_column(fh.name, n) for n in (1, 2, 3, 4, 5)] == [1, 4, 1, 1, None]
    Path(fh.name).unlink()
    assert first_column("/nonexistent/file", 1) is None


@pytest.mark.parametrize("tool", ["T1 P1 Znan", "T1 Zinf", "T1 Z-1e999", "T1.5 Z3", "T1 Q", "P1 Z3"])
def test_bad_tool_tables_are_refused_at_their_field(tmp_path, tool):
    table = tmp_path / "t.tbl"
    table.write_text(tool + "\n")
    result = run("correct", POCKET, "-c", STATIC, "--tool-table", table, "-o", tmp_path / "o.nc")
    assert result.exit_code == 3, result.output
    assert PLACE.search(result.output), result.output
    assert "internal error" not in result.output


def _moved(tmp_path, dx: float):
    a, b = tmp_path / "a.nc", tmp_path / "b.nc"
    a.write_text("G21 G90\nG0 X10 Y10 Z10\nG1 X20 Y20 F100\nM2\n")
    b.write_text(f"G21 G90\nG0 X10 Y10 Z10\nG1 X{20 + dx:.4f} Y20 F100\nM2\n")
    return a, b


def test_diff_refuses_a_correction_above_max_correction(tmp_path):
    a, b = _moved(tmp_path, 10.0)
    result = run("diff", a, b)
    assert result.exit_code == EXIT_SAFETY, result.output
    assert "dX +10000.00" in result.output  # the report first
    assert f"postproc: error: {b}:3:1: block moved by 10.0000 mm" in result.output
    assert "--max-correction 1 mm" in result.output
    as_json = run("diff", a, b, "--json")
    assert as_json.exit_code == EXIT_SAFETY
    assert run("diff", a, b, "--max-correction", "20").exit_code == 0


def test_diff_accepts_a_correction_within_max_correction(tmp_path):
    a, b = _moved(tmp_path, 0.5)
    assert run("diff", a, b).exit_code == 0
    assert run("diff", a, b, "--max-correction", "0.1").exit_code == EXIT_SAFETY


@pytest.mark.parametrize("volume", [[[-1e308] * 3, [1e308] * 3], [[0, 0, 0], [315, 315, 1e6]],
                                    [[-100_001, 0, 0], [315, 315, 315]]])
def test_a_calibrated_volume_beyond_100_m_is_refused(tmp_path, volume):
    data = json.loads(Path(STATIC).read_text())
    data["volume_mm"] = volume
    cal = tmp_path / "cal.json"
    cal.write_text(json.dumps(data))
    result = run("correct", POCKET, "-c", cal, "-o", tmp_path / "o.nc")
    assert result.exit_code == EXIT_CALIBRATION, result.output
    assert "reaches beyond 100 m" in result.output
    assert not (tmp_path / "o.nc").exists()


def test_a_calibrated_volume_of_100_m_is_taken():
    from postproc.engine.identity import IdentityEngine

    assert IdentityEngine([[-1e5] * 3, [1e5] * 3]).volume_mm[1, 0] == 1e5


@pytest.mark.parametrize("line", ["G0 X١٢ Y10 Z10", "G0 X[١+1] Y10 Z10", "#1=١\nG0 X#1 Y10 Z10",
                                  "N١ G0 X1 Y10 Z10"])
def test_digits_of_other_scripts_are_refused_not_read_as_numbers(tmp_path, line):
    """rs274 refuses 'X١٢' (bad number format); Python's \\d and str.isdigit() took it as 12."""
    src = tmp_path / "u.nc"
    src.write_text(f"G21 G90\n{line}\nM2\n", encoding="utf-8")
    result = run("correct", src, "-c", STATIC, "--offset", "G54=X100,Y100,Z100", "-o", tmp_path / "o.nc")
    assert result.exit_code == 3, result.output
    assert PLACE.search(result.output), result.output
    assert not (tmp_path / "o.nc").exists()


def test_a_number_too_large_for_a_float_is_refused_at_its_word(tmp_path):
    src = tmp_path / "huge.nc"
    src.write_text("G21 G90\nG0 X" + "9" * 400 + " Y10 Z10 (a comment: read word by word)\nM2\n")
    result = run("correct", src, "-c", STATIC, "--offset", "G54=X100,Y100,Z100", "-o", tmp_path / "o.nc")
    assert result.exit_code == 3, result.output
    assert f"{src}:2:4: X value 999999999999... is beyond 1e+09: no machine moves that far" in result.output
