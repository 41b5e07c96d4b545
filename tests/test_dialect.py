"""Dialects, the header every controller reads, and the output's safety.

The LinuxCNC limits are checked against LinuxCNC's own interpreter (``rs274`` from
Debian's linuxcnc-uspace) when it is installed; the values tested without it are the
ones worked out by hand from the source constants named in postproc/gcode/dialect.py.
"""

import math
import os
import re
import shutil
import stat
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from postproc.calfile import save_calibration
from postproc.cli import main
from postproc.engine.identity import IdentityEngine
from postproc.engine.static import StaticEngine
from postproc.errors import EXIT_INPUT, EXIT_SAFETY, EXIT_USAGE, PostprocError
from postproc.gcode import dialect as D
from postproc.gcode import emit
from postproc.gcode.compare import compare_programs, header_setup
from postproc.gcode.path import Setup
from postproc.gcode.pipeline import CorrectOptions, correct_text

ROOT = Path(__file__).parents[1]
CAL = str(ROOT / "calibrations" / "s500_static.json")
RS274 = shutil.which("rs274")
needs_rs274 = pytest.mark.skipif(RS274 is None, reason="LinuxCNC's rs274 is not installed")
SHA = "0123456789abcdef" * 4


def invoke(args):
    return CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)


def rs274(_tmp_path, text: str, tools: str = "T1 P1 Z100 D6\n"):
    """LinuxCNC's rs274 on ``text`` through the tests' shared oracle (one run at a time)."""
    from oracle import run_rs274

    return run_rs274(text, tools=tools)


# -- the arc rules -------------------------------------------------------------------------
def test_linuxcnc_arc_tolerance_by_hand():
    d = D.DIALECTS["linuxcnc"]
    a_mm = 2 * 0.01 * math.sqrt(2)  # CENTER_ARC_RADIUS_TOLERANCE_MM = 0.028284 mm
    assert d.arc_end_radius_tolerance(5.0, "mm") == pytest.approx(a_mm)  # 0.1 % of 5 mm is less
    assert d.arc_end_radius_tolerance(50.0, "mm") == pytest.approx(0.05)  # 0.1 % of 50 mm
    assert d.arc_end_radius_tolerance(1e4, "mm") == pytest.approx(100 * a_mm)  # the cap, 2.83 mm
    # inch programs: 2 * 0.001 * sqrt(2) in = 0.0718 mm
    assert d.arc_end_radius_tolerance(25.4, "inch") == pytest.approx(0.002 * math.sqrt(2) * 25.4)
    assert d.arc_end_radius_tolerance(25.4, 25.4) == d.arc_end_radius_tolerance(25.4, "inch")
    # the relative test divides by the larger radius
    assert d.arc_end_radius_ok(100.0, 100.0999, "mm")  # 0.0999 / 100.0999 < 0.1 %
    assert not d.arc_end_radius_ok(10.0, 10.05, "mm")  # 0.05 mm > 0.028 and 0.5 % > 0.1 %
    assert d.arc_end_radius_ok(10.0, 10.02, "mm")  # under the absolute tolerance


def test_grbl_arc_tolerance_by_hand():
    d = D.DIALECTS["grbl"]
    assert d.arc_end_radius_tolerance(1.0) == pytest.approx(0.005)  # 0.005 mm floor
    assert d.arc_end_radius_tolerance(100.0) == pytest.approx(0.1)  # 0.1 % of the start radius
    assert d.arc_end_radius_tolerance(2000.0) == pytest.approx(0.5)  # 0.5 mm cap
    assert d.arc_end_radius_tolerance(100.0, "inch") == d.arc_end_radius_tolerance(100.0, "mm")  # Grbl works in mm
    assert d.arc_end_radius_ok(100.0, 100.1)
    assert not d.arc_end_radius_ok(100.0, 100.11)


def test_generic_is_the_strictest_of_all():
    g = D.DIALECTS["generic"]
    others = [d for n, d in D.DIALECTS.items() if n != "generic"]
    for r in (0.5, 3.0, 40.0, 700.0, 1e4):
        for units in ("mm", "inch"):
            assert g.arc_end_radius_tolerance(r, units) == min(d.arc_end_radius_tolerance(r, units) for d in others)
    assert g.max_line_chars == min(d.max_line_chars for d in others)
    assert g.uppercase_only
    assert not g.semicolon_comments
    assert set(";,(") <= set(g.comment_forbidden)
    assert set(D.DIALECT_NAMES) == set(D.DIALECTS)


@needs_rs274
def test_linuxcnc_arc_rule_matches_rs274(tmp_path):
    d = D.DIALECTS["linuxcnc"]
    rng = np.random.default_rng(11)
    cases = [(10.0, 0.02), (10.0, 0.05), (100.0, 0.05), (100.0, 0.12), (1e4, 2.8), (1e4, 2.85)]
    cases += [(float(r), float(e)) for r, e in zip(10 ** rng.uniform(0, 4, 6), rng.uniform(0.001, 3.0, 6),
                                                    strict=True)]
    for units, g in (("mm", "G21"), ("inch", "G20")):
        for r, err in cases:
            r_u, err_u = (r, err) if units == "mm" else (r / 25.4, err / 25.4)
            text = f"{g} G17 G90\nG0 X0 Y0\nG2 X{2 * r_u + err_u:.6f} Y0 I{r_u:.6f} J0 F100\nM2\n"
            res = rs274(tmp_path, text)
            accepted = res.ok and "differs" not in res.error
            assert accepted == d.arc_end_radius_ok(r, r + err, units), (units, r, err, res.error[-300:])


# -- output lines ---------------------------------------------------------------------------
def test_linuxcnc_line_length():
    d = D.DIALECTS["linuxcnc"]
    D.check_output_line(d, "(" + "A" * 250 + ")\n")  # 252 characters
    with pytest.raises(PostprocError, match="252"):
        D.check_output_line(d, "(" + "A" * 251 + ")\n", path="p.ngc", lineno=7)
    with pytest.raises(PostprocError):  # a carriage return counts
        D.check_output_line(d, "(" + "A" * 250 + ")\r\n")


@needs_rs274
def test_linuxcnc_line_length_matches_rs274(tmp_path):
    for n, ok in ((252, True), (253, False)):
        res = rs274(tmp_path, "G21\n(" + "A" * (n - 2) + ")\nG0 X1\nM2\n")
        assert res.ok == ok, (n, res.error)
        try:
            D.check_output_line("linuxcnc", "(" + "A" * (n - 2) + ")\n")
            assert ok
        except PostprocError:
            assert not ok


@pytest.mark.parametrize(("dialect", "line", "match"), [
    ("fanuc", "G1 X1 (finish pass)\n", "lower-case"),
    ("fanuc", "G1 X1 (A;B)\n", "';' inside a comment"),
    ("haas", "(PART 1, SIDE 2)\n", "',' inside a comment"),
    ("fanuc", "G1 X1 ; FINISH\n", "does not read ';'"),
    ("generic", "(OUTER (INNER) COMMENT)\n", "nested"),
    ("linuxcnc", "(OUTER (INNER) COMMENT)\n", "nested"),
    ("linuxcnc", "G1 X1 (NOT CLOSED\n", "not closed"),
    ("generic", "(CAFÉ)\n", "ISO code"),
    ("grbl", "G1 " + " ".join(f"X{i}.0000" for i in range(12)) + "\n", "more than Grbl"),
])
def test_lines_a_controller_refuses(dialect, line, match):
    with pytest.raises(PostprocError, match=match) as err:
        D.check_output_line(dialect, line, path="prog.nc", lineno=3)
    assert err.value.path == "prog.nc"
    assert err.value.lineno == 3
    assert err.value.col


@pytest.mark.parametrize("line", ["N10 G1 X1.5 Y-2 F300 (FINISH PASS)\n", "(POSTPROC 1.0 CORRECTED)\r\n", "%\n", "\n"])
def test_lines_every_controller_reads(line):
    for name in D.DIALECT_NAMES:
        D.check_output_line(name, line)
    D.check_output_line("linuxcnc", "g1 x1 (lower case; and a comma, fine here) ; rest\n")
    D.check_output_line("grbl", "(a long comment is not held in Grbl's line buffer " + "x" * 60 + ")\n")


def test_unknown_dialect():
    with pytest.raises(PostprocError, match="unknown dialect"):
        D.get("heidenhain")


# -- the header -----------------------------------------------------------------------------
LONG_NOTE = ("G54 taken as zero unless named; " + "; ".join(f"G5{k}=1{k}0.125,-2{k}.5,3{k}" for k in range(4, 10))
             + "; tools " + ",".join(f"{h}={100 + h / 8:g}" for h in range(1, 40))
             + "; start X10.5,Y-20,Z150; tool vector 0.5,0,-100.25; map zramp; map thermal"
             + "; parametric solver astatic accepting residuals up to 2 mm")


def test_header_lines_fit_every_dialect():
    name = "Kalibrierung (warm), Maschine #3; " + "x" * 200
    old = emit.header_line(name, SHA, 0.001, LONG_NOTE, "\n")
    assert len(old) > 700  # the one-line header LinuxCNC refused
    for dname in D.DIALECT_NAMES:
        rows = emit.header_lines(dname, (name, SHA), 0.001, LONG_NOTE, "\r\n", expanded=True)
        assert len(rows) > 8
        for k, row in enumerate(rows, start=1):
            assert row.endswith("\r\n")
            D.check_output_line(dname, row, "<header>", k)
            assert emit.is_header(row)
        text = "".join(rows)
        assert text == text.upper()
        # a dialect without parenthesis comments (Sinumerik) reads the lines as ";POSTPROC ..."
        mark = "(" if D.DIALECTS[dname].paren_comments else ";"
        assert all(row.startswith(mark) and ";" not in row[1:] for row in rows)
        assert "," not in text
        assert emit.is_header_start(rows[0])
        assert not any(emit.is_header_start(r) for r in rows[1:])
        assert f"{mark}POSTPROC EXPANDED" in text
        assert SHA.upper() in text


def test_header_lines_end_lines_for_every_reader():
    rows = emit.header_lines("generic", ("cal", SHA), 0.001, "", "\r")
    assert all(r.endswith("\r\n") for r in rows)  # "\r" alone ends no line for LinuxCNC or Grbl
    assert all(r.endswith("\n") and not r.endswith("\r\n") for r in emit.header_lines("generic", ("c", SHA), 1, "", ""))


def test_header_carries_the_setup_exactly():
    setup = Setup(offsets={"G54": (100.123456789, 80.0, -40.5), "G55": {"X": 1.0, "Y": 2.0, "Z": 3.0}},
                  tool_lengths={1: 100.0, 12: 87.65432101}, start={"Z": 150.25}, tool_vector=(0.5, 0.0, -100.0))
    rows = emit.header_lines("generic", ("cal", SHA), 0.002, "G54=100.123,80,-40.5", "\n", setup=setup)
    hs = header_setup("".join(rows) + "G0 X1\n")
    assert hs.offsets == {"G54": (100.123456789, 80.0, -40.5), "G55": (1.0, 2.0, 3.0)}
    assert hs.tool_lengths == {1: 100.0, 12: 87.65432101}
    assert hs.start == {"Z": 150.25}
    assert hs.tool_vector == (0.5, 0.0, -100.0)
    # G28/G30 stored positions (--home), exactly
    setup = Setup(home={"G28": {"X": 0.0, "Y": 0.0, "Z": 312.123456789}, "G30": (10.0, 20.0, 30.0)})
    rows = emit.header_lines("fanuc", ("cal", SHA), 0.002, "G28=X0,Y0,Z312.123; G30=X10,Y20,Z30", "\n", setup=setup)
    hs = header_setup("".join(rows))
    assert hs.home == {"G28": {"X": 0.0, "Y": 0.0, "Z": 312.123456789}, "G30": {"X": 10.0, "Y": 20.0, "Z": 30.0}}
    # from the note alone (no Setup): what the note says
    rows = emit.header_lines("fanuc", ("cal", SHA), 0.002, LONG_NOTE, "\n")
    hs = header_setup("%\nO1234 (PART)\n" + "".join(rows) + "G0 X1\n")
    assert hs.offsets["G57"] == (170.125, -27.5, 37.0)
    assert hs.tool_lengths[8] == 101.0
    assert len(hs.tool_lengths) == 39
    assert hs.start == {"X": 10.5, "Y": -20.0, "Z": 150.0}


def test_old_one_line_header_is_still_read():
    old = emit.header_line("s500", SHA, 0.001, "G54=100,80,40; tools 1=100; start X5,Z150", "\n")
    assert emit.is_header(old)
    assert emit.is_header_start(old)
    hs = header_setup(old + "G0 X1\n")
    assert hs.offsets == {"G54": (100.0, 80.0, 40.0)}
    assert hs.tool_lengths == {1: 100.0}
    assert hs.start == {"X": 5.0, "Z": 150.0}
    assert not emit.is_header("(POSTPROCESSED BY CAM)\n")
    assert not emit.is_header("(postproc notes, v2)\n")


def test_corrected_program_is_refused_again_in_either_case():
    eng = IdentityEngine([[-1e3] * 3, [1e3] * 3])
    out, _ = correct_text("G21 G90\nG0 X1 Y2 Z3\nM30\n", eng, Setup(offsets={"G54": (0, 0, 0)}))
    assert out.startswith("(POSTPROC ")
    for text in (out, out.lower(), "%\n" + out):
        with pytest.raises(PostprocError, match="already carries a postproc header"):
            correct_text(text, eng, Setup())


@needs_rs274
def test_rs274_reads_a_corrected_program_with_a_long_setup(tmp_path):
    """The header of a program corrected with many offsets and tools: rs274 accepts it, and
    the old one-line header of the same setup it refuses ('Command too long')."""
    text = (ROOT / "samples" / "g54_g43.ngc").read_text()
    tools = {h: 100.0 + h for h in range(1, 40)}
    tools[1] = 100.0
    offs = {f"G5{k}": (100.0 + k, 80.0, 40.0) for k in range(4, 10)}
    offs["G54"] = (100.0, 80.0, 40.0)
    setup = Setup(offsets=offs, tool_lengths=tools, start={"Z": 250.0})
    eng = StaticEngine(np.eye(3) * 1.0001, [0.01, -0.02, 0.005], [[0, 0, 0], [400, 400, 400]])
    out, _ = correct_text(text, eng, setup, CorrectOptions(dialect="linuxcnc"), calibration_name="s500 static",
                          calibration_sha256=SHA)
    res = rs274(tmp_path, out)
    assert res.ok, res.error[-500:]
    head, _ = emit.split_header(out)
    note = "; ".join(f"{k}={','.join(f'{x:g}' for x in v)}" for k, v in sorted(offs.items()))
    note += "; tools " + ",".join(f"{k}={v:g}" for k, v in sorted(tools.items()))
    old = emit.header_line("s500 static", SHA, 0.001, note, "\n")
    res_old = rs274(tmp_path, out.replace("".join(head), old))
    assert not res_old.ok
    assert "too long" in res_old.error


# -- diff reads the setup from the header ----------------------------------------------------
def test_diff_of_a_g53_program_needs_no_offsets(tmp_path):
    src = ROOT / "samples" / "g54_g43.ngc"
    out = tmp_path / "part.ngc"
    r = invoke(["correct", src, "-c", CAL, "--offset", "G54=X100,Y80,Z40", "--tool-length", "1=100", "-o", out])
    assert r.exit_code == 0, r.output
    plain = compare_programs(src, out).axis_stats()
    given = compare_programs(src, out, Setup(offsets={"G54": (100.0, 80.0, 40.0)}, tool_lengths={1: 100.0}))
    assert plain == given.axis_stats()
    assert max(plain[a]["max_mm"] for a in "XYZ") < 0.5  # not the 99.9 mm of the offsets
    r = invoke(["diff", src, out])
    assert r.exit_code == 0
    assert "(POSTPROC OFFSET G54 X100 Y80 Z40)" in r.output
    shown = [float(v) for v in re.findall(r"[XYZ] max ([\d.]+)", r.output)]
    assert len(shown) == 3
    assert max(shown) < 500.0  # um
    # a file corrected by an earlier version (one-line header) reads the same
    head, body = emit.split_header(out.read_text())
    old = emit.header_line("s500_static", SHA, 0.001, "G54=100,80,40; tools 1=100", "\n")
    (tmp_path / "old.ngc").write_text(body.replace("%\n", "%\n" + old, 1))
    assert compare_programs(src, tmp_path / "old.ngc").axis_stats() == plain


# -- writing outputs -----------------------------------------------------------------------
def test_output_through_a_symlink_keeps_the_link(tmp_path):
    src = tmp_path / "p.nc"
    src.write_text("G21 G90\nG0 X10 Y10 Z10\nG1 X20 F100\nM30\n")
    real = tmp_path / "real" / "p_out.nc"
    real.parent.mkdir()
    real.write_text("old\n")
    os.chmod(real, 0o640)
    link = tmp_path / "link.nc"
    link.symlink_to(real)
    r = invoke(["correct", src, "-c", CAL, "-o", link])
    assert r.exit_code == 0, r.output
    assert link.is_symlink()
    assert os.readlink(link) == str(real)
    assert real.read_text().startswith("(POSTPROC ")
    assert stat.S_IMODE(real.stat().st_mode) == 0o640
    assert sorted(p.name for p in real.parent.iterdir()) == ["p_out.nc"]  # no temporary file left


def test_output_to_dev_null_leaves_the_device(tmp_path):
    src = tmp_path / "p.nc"
    src.write_text("G21 G90\nG0 X10 Y10 Z10\nG1 X20 F100\nM30\n")
    before = os.stat("/dev/null")
    r = invoke(["correct", src, "-c", CAL, "-o", "/dev/null"])
    assert r.exit_code == 0, r.output
    after = os.stat("/dev/null")
    assert stat.S_ISCHR(after.st_mode)
    assert after.st_rdev == before.st_rdev
    assert after.st_ino == before.st_ino


def test_output_into_a_fifo(tmp_path):
    from postproc.fileio import atomic_write_text

    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    reader = subprocess.Popen([sys.executable, "-c", f"import sys; sys.stdout.write(open({str(fifo)!r}).read())"],
                              stdout=subprocess.PIPE, text=True)
    atomic_write_text(fifo, "G0 X1\n")
    assert reader.communicate(timeout=30)[0] == "G0 X1\n"
    assert stat.S_ISFIFO(os.stat(fifo).st_mode)


def test_every_writer_goes_through_output_path():
    # no module writes an output by its own temporary file and rename
    hits = []
    for path in (ROOT / "postproc").rglob("*.py"):
        if path.name == "fileio.py":
            continue
        text = path.read_text(encoding="utf-8")
        if "mkstemp" in text or "os.replace" in text or "os.rename" in text:
            hits.append(str(path.relative_to(ROOT)))
    assert hits == []


# -- refusals and usage ---------------------------------------------------------------------
@pytest.mark.parametrize("content", ["", "\n\n  \r\n"])
def test_empty_program_is_refused(tmp_path, content):
    src = tmp_path / "empty.nc"
    src.write_text(content)
    out = tmp_path / "out.nc"
    r = invoke(["correct", src, "-c", CAL, "-o", out])
    assert r.exit_code == EXIT_INPUT
    assert "empty.nc" in r.output
    assert "program is empty" in r.output
    assert not out.exists()


def test_plot_without_matplotlib_names_the_install_command(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    r = invoke(["check", ROOT / "samples" / "walkthrough_points.csv", "-c", CAL, "--plot", tmp_path / "plots"])
    assert r.exit_code == EXIT_USAGE, r.output
    assert "pip install matplotlib" in r.output
    assert "internal error" not in r.output
    assert not (tmp_path / "plots").exists()
    r = invoke(["verify", ROOT / "samples" / "pocket.nc", "-c", CAL, "--machine",
                ROOT / "calibrations" / "s500.machine.json", "--plot", tmp_path / "dev.png"])
    assert r.exit_code == EXIT_USAGE
    assert "pip install matplotlib" in r.output
    r = invoke(["predict", "bore", ROOT / "samples" / "predict" / "bore_50H7.operation.json", "-n", "10",
                "--plot", tmp_path / "b.png"])
    assert r.exit_code == EXIT_USAGE
    assert "pip install matplotlib" in r.output


def test_check_plot_with_a_file_name_makes_no_directory(tmp_path):
    r = invoke(["check", ROOT / "samples" / "walkthrough_points.csv", "-c", CAL, "--plot", tmp_path / "name.png"])
    assert r.exit_code == EXIT_USAGE
    assert "directory" in r.output
    assert not (tmp_path / "name.png").exists()


def test_dialect_option(tmp_path):
    src = tmp_path / "o1234.nc"
    src.write_text("%\n(PART 1234)\nG21 G90\nG0 X10 Y10 Z10\nG1 X20 F100\nM30\n%\n")
    out = tmp_path / "out.nc"
    r = invoke(["correct", src, "-c", CAL, "--dialect", "fanuc", "-o", out])
    assert r.exit_code == 0, r.output
    for k, line in enumerate(out.read_text().splitlines(keepends=True), start=1):
        D.check_output_line("fanuc", line, str(out), k)
    r = invoke(["correct", src, "-c", CAL, "--dialect", "heidenhain", "-o", out])
    assert r.exit_code == EXIT_USAGE


# -- batch ------------------------------------------------------------------------------------
def test_batch_folder_with_tally(tmp_path):
    folder = tmp_path / "progs"
    folder.mkdir()
    good = "G21 G90\nG0 X10 Y10 Z10\nG1 X20 F100\nM30\n"
    (folder / "a.nc").write_text(good)
    (folder / "O1001").write_text(good)
    (folder / "empty.ngc").write_text("")
    (folder / "notes.pdf").write_text("not a program")
    (folder / ".hidden.nc").write_text(good)
    eng = IdentityEngine([[-1e3] * 3, [1e3] * 3])
    once, _ = correct_text(good, eng, Setup())
    (folder / "twice.tap").write_text(once)
    cal = tmp_path / "identity.json"
    save_calibration(cal, eng, name="identity")
    outdir = tmp_path / "out"
    r = invoke(["correct", folder, "-c", cal, "--output-dir", outdir, "-j", "2"])
    assert r.exit_code == EXIT_SAFETY, r.output  # the worst refusal: already corrected
    assert "4 files: 2 corrected, 2 refused" in r.output
    assert r.output.count("/4]") == 4  # one progress line per file
    assert f"refused (exit {EXIT_INPUT}) {folder / 'empty.ngc'}: the program is empty" in r.output
    assert "program is empty" in r.output
    assert "already carries a postproc header" in r.output
    assert sorted(p.name for p in outdir.iterdir()) == ["O1001", "a.nc"]
    r = invoke(["correct", folder, "-c", cal, "-o", tmp_path / "x.nc"])
    assert r.exit_code == EXIT_USAGE
    r = invoke(["correct", folder, "-c", cal, "--output-dir", folder])
    assert r.exit_code == EXIT_USAGE
    assert "folder of the inputs" in r.output


def test_batch_all_corrected_exits_zero(tmp_path):
    folder = tmp_path / "progs"
    folder.mkdir()
    for k in range(3):
        (folder / f"p{k}.nc").write_text(f"G21 G90\nG0 X{10 + k} Y10 Z10\nG1 X20 F100\nM30\n")
    r = invoke(["correct", folder, "-c", CAL, "--output-dir", tmp_path / "out"])
    assert r.exit_code == 0, r.output
    assert "3 files: 3 corrected, 0 refused" in r.output


def test_the_end_radius_tolerance_at_radius_zero_is_the_least_for_every_rule():
    # the bulk reader lets an arc whose end radius differs by no more than this pass
    # without asking the rule: every rule must accept it, at any radius, in either unit
    import random

    from postproc.gcode import dialect

    rng = random.Random(7)
    for name in dialect.DIALECTS:
        d = dialect.get(name)
        for units in ("mm", "inch"):
            sure = d.arc_end_radius_tolerance(0.0, units)
            assert sure > 0.0
            for _ in range(300):
                r0 = 10 ** rng.uniform(-3, 4)
                err = sure * rng.choice([1.0, rng.random(), 1 - 1e-12])
                for r1 in (r0 + err, max(r0 - err, 0.0)):
                    if abs(r0 - r1) <= sure:  # (as the reader tests it: r0 + err may round past it)
                        assert d.arc_end_radius_ok(r0, r1, units), (name, units, r0, r1)
            assert d.arc_end_radius_tolerance(1e4, units) >= sure
