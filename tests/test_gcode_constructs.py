"""Constructs of real programs: program numbers, tape marks, BOM, G28/G30, G52, G10 tool
writes, full circles, off-plane offsets, I/O M codes, look-ahead codes, and refusals that
name what the line really is."""

import numpy as np
import pytest
from conftest import CORPUS

from postproc.engine.identity import IdentityEngine
from postproc.engine.static import StaticEngine
from postproc.errors import MissingSetupError, PostprocError, UnsupportedGcodeError
from postproc.gcode import emit
from postproc.gcode.interp import Interpreter, classify_construct
from postproc.gcode.moves import Role
from postproc.gcode.path import Setup
from postproc.gcode.pipeline import CorrectOptions, correct_text

BIG = [[-1e5] * 3, [1e5] * 3]
ZERO = Setup(offsets={"G54": (0.0, 0.0, 0.0)})


def scale_engine(k=1.001):
    """A machine that moves k times what it is told: the correction divides by k."""
    return StaticEngine(k * np.eye(3), np.zeros(3), BIG)


def run(text, setup=ZERO, dialect="generic"):
    it = Interpreter(setup, "p.nc", dialect=dialect)
    moves = []
    for n, line in enumerate(text.splitlines(keepends=True), start=1):
        mv = it.feed_line(n, line)
        while mv is not None:
            moves.append(mv)
            mv = mv.then
    return it, moves


def identity(text, setup=ZERO):
    out, rep = correct_text(text, IdentityEngine(BIG), setup, CorrectOptions(), path="p.nc")
    return "".join(ln for ln in out.splitlines(keepends=True) if not emit.is_header(ln)), rep


@pytest.mark.parametrize("head", ["O1234\n", "O0001 (PART NAME)\n", ":1234\n", "o100\n"])
def test_program_number_lines_pass_through(head):
    text = head + "G21 G90\nG0 X1 Y2 Z3\nG1 X4 F100\nM30\n"
    out, rep = identity(text)
    assert out == text
    assert rep.moves == 2


def test_tape_mark_with_text_is_accepted_except_by_linuxcnc():
    text = "% PROGRAM START\nG21 G90\nG0 X1 Y2 Z3\nM30\n%\n"
    _, moves = run(text)
    assert [m.q1 for m in moves] == [(1.0, 2.0, 3.0)]
    with pytest.raises(PostprocError, match="'%' must stand alone"):
        run(text, dialect="linuxcnc")


def test_utf8_bom_is_not_a_word_and_stays_in_place():
    text = "\ufeffG21 G90 G0 X1 Y2 Z3\nG1 X4 F100\nM30\n"
    _, moves = run(text)
    assert moves[0].q1 == (1.0, 2.0, 3.0)
    # the word spans index the line as read (with its BOM)
    letter, num, start, end, lpos = moves[0].words[-1]
    assert text[start:end] == "3"
    assert text[lpos] == "Z"
    # a scale of the coordinates: words rewritten at the right places
    eng = scale_engine()
    out, _ = correct_text(text, eng, ZERO, CorrectOptions(), path="p.nc")
    assert out.startswith("\ufeff(POSTPROC ")  # the mark stays the file's first bytes
    body = emit.split_header(out)[1].splitlines(keepends=True)
    assert body[0].startswith("G21 G90 G0 X")


def test_g28_goes_through_the_intermediate_point_to_the_stored_position():
    setup = Setup(offsets={"G54": (100.0, 50.0, -20.0)}, home={"G28": {"X": 0.0, "Y": 0.0, "Z": 0.0}})
    text = "G21 G90 G54\nG0 X10 Y20 Z5\nG28 Z30\nG0 X1\nM30\n"
    it, moves = run(text, setup)
    inter, home, nxt = moves[1], moves[2], moves[3]
    assert inter.q1 == (110.0, 70.0, 10.0)  # Z30 in G54
    assert home.role is Role.AT
    assert inter.role is Role.WHOLE
    assert home.q1 == (110.0, 70.0, 0.0)  # only Z goes to the stored position
    assert nxt.q0 == (110.0, 70.0, 0.0)
    assert nxt.q1 == (101.0, 70.0, 0.0)


def test_g91_g28_z0_moves_only_z_and_unknown_home_refuses_the_move_that_needs_it():
    text = "G21 G90\nG0 X10 Y20 Z5\nG91 G28 Z0\nG90 G0 X1 Y2\nM30\n"
    with pytest.raises(MissingSetupError) as err:
        run(text)
    assert err.value.lineno == 4
    assert "--home G28" in err.value.hint
    # positioning Z absolutely again makes it known
    it, moves = run("G21 G90\nG0 X10 Y20 Z5\nG91 G28 Z0\nG90 G0 Z50\nG0 X1 Y2\nM30\n")
    assert moves[-1].q1 == (1.0, 2.0, 50.0)
    # and the whole program corrects, the G28 line unchanged
    out, _ = identity("G21 G90\nG0 X10 Y20 Z5\nG91 G28 Z0\nG90 G0 Z50\nG0 X1 Y2\nM30\n")
    assert "G91 G28 Z0\n" in out


def test_g28_in_a_corrected_program_rewrites_only_its_own_words():
    eng = scale_engine()
    setup = Setup(offsets={"G54": (0.0, 0.0, 0.0)}, home={"G28": {"X": 0.0, "Y": 0.0, "Z": 200.0}})
    text = "G21 G90\nG0 X10 Y20 Z5\nG28 Z100\nG0 X50\nM30\n"
    out, _ = correct_text(text, eng, setup, CorrectOptions(), path="p.nc")
    body = [ln for ln in out.splitlines() if not emit.is_header(ln + "\n")]
    assert body[2].startswith("G28 Z")
    assert "X" not in body[2]
    assert "G0" not in body[2]
    assert abs(float(body[2].split("Z")[1]) - 100 / 1.001) < 1e-4
    # after G28 the machine is at the stored Z=200 uncorrected (the tool at 200.2): the
    # next move lands on its nominal point (50, 20, 200), so it gains Y and Z words
    words = dict((w[0], float(w[1:])) for w in body[3].split()[1:])
    assert words == pytest.approx({"X": 50 / 1.001, "Y": 20 / 1.001, "Z": 200 / 1.001}, abs=1e-4)


def test_g28_1_stores_the_current_position():
    it, moves = run("G21 G90\nG0 X10 Y20 Z5\nG28.1\nG0 X0 Y0 Z0\nG28\nM30\n")
    assert moves[-1].role is Role.AT
    assert moves[-1].q1 == (10.0, 20.0, 5.0)


def test_g52_local_offset():
    _, moves = run("G21 G90\nG0 X1 Y2 Z3\nG52 X10\nG0 X1\nG52 X0\nG0 X1\nM30\n")
    assert [m.q1[0] for m in moves] == [1.0, 11.0, 1.0]


def test_g10_l1_and_l10_write_tool_lengths_used_by_later_g43():
    # expected values are LinuxCNC's (rs274): L1 Z50 -> 50; L10 Z4 at Z10 under a 50 mm
    # tool -> the new length makes the current Z read 4: 60 - 4 = 56
    text = "G21 G90\nG0 X1 Y2 Z3\nG10 L1 P1 Z50\nT1 M6\nG43\nG0 Z0\nG0 X0 Y0 Z10\nG10 L10 P2 Z4\nT2 M6\nG43\nG0 Z0\nM30\n"
    it, moves = run(text, Setup(offsets={"G54": (0.0, 0.0, 0.0)}))
    assert it.tool_lengths == {1: 50.0, 2: 56.0}
    assert moves[1].q1[2] == 50.0
    assert moves[-1].q1[2] == 56.0


def test_full_circle_from_centre_offsets_only():
    _, moves = run("G21 G90 G17\nG0 X1 Y2 Z3\nG2 I1 F100\nM30\n")
    arc = moves[-1]
    assert arc.q0 == arc.q1 == (1.0, 2.0, 3.0)
    assert arc.arc.center[:2] == (2.0, 2.0)
    with pytest.raises(PostprocError, match="arc without end point"):
        run("G21 G90 G17\nG0 X1 Y2 Z3\nG2 I1 F100\nM30\n", dialect="grbl")


def test_off_plane_offset_ignored_where_the_controller_ignores_it():
    text = "G21 G90 G17\nG0 X1 Y2 Z3\nG2 X3 Y2 I1 J0 K0 F100\nM30\n"
    _, moves = run(text, dialect="fanuc")
    assert moves[-1].arc.center[:2] == (2.0, 2.0)
    with pytest.raises(PostprocError, match="K word is not an arc offset") as err:
        run(text, dialect="linuxcnc")  # "K word given for arc in xy plane" in LinuxCNC
    assert "--dialect" in err.value.hint


@pytest.mark.parametrize(("dialect", "k", "r_form_too"), [
    ("grbl", "K0", False), ("grbl", "K5", False),  # gcode.c: the offset form clears I, J and K
    ("fanuc", "K5", True), ("generic", "K0", False)])
def test_off_plane_offset_beside_centre_words(dialect, k, r_form_too):
    _, moves = run(f"G21 G90 G17\nG0 X1 Y2 Z3\nG2 X3 Y2 I1 J0 {k} F100\nM30\n", dialect=dialect)
    assert moves[-1].arc.center[:2] == (2.0, 2.0)
    r_form = f"G21 G90 G17\nG0 X1 Y2 Z3\nG2 X3 Y2 R1 {k} F100\nM30\n"
    if r_form_too:
        assert run(r_form, dialect=dialect)[1][-1].arc is not None
    else:  # Grbl: I/J/K beside R are unused words (STATUS_GCODE_UNUSED_WORDS)
        with pytest.raises(PostprocError, match="K word is not an arc offset"):
            run(r_form, dialect=dialect)
    with pytest.raises(PostprocError, match="K word is not an arc offset"):
        run(f"G21 G90 G17\nG0 X1 Y2 Z3\nG2 X3 Y2 I1 J0 {k} F100\nM30\n", dialect="linuxcnc")


def test_a_freecad_grbl_post_program_is_corrected_as_grbl():
    """FreeCAD's grbl_post writes K0.000 on every G17 arc; Grbl runs it."""
    path = CORPUS / "real" / "freecad_sergey" / "Cicloid_Gear__External_gear_pin.nc"
    if not path.exists():
        pytest.skip("needs ../shared/corpus")
    text = path.read_text()
    setup = Setup(offsets={"G54": (0.0, 0.0, 100.0)})
    out, rep = correct_text(text, scale_engine(), setup, CorrectOptions(dialect="grbl"), path=str(path))
    assert rep.arcs_kept > 0
    body = [ln for ln in out.splitlines() if not emit.is_header(ln)]
    k_lines = [ln for ln in text.splitlines() if "K0.000" in ln]
    assert k_lines
    assert sum("K0.000" in ln for ln in body) == len(k_lines)  # the ignored words stay as written


def test_io_m_codes_take_e_words_and_g92_takes_rotary_axes():
    it, moves = run("G21 G90\nM68 E3 Q50\nM66 E0 L0\nG0 X1 Y2 Z3 A10\nG92 A0\nG0 A5\nM30\n")
    assert moves[-1].rotary == {"A": 15.0}


@pytest.mark.parametrize("line", ["G5.1 Q1\n", "G05.1 Q0\n", "G05 P10000\n", "G187 P1 E0.01\n", "G103 P4\n",
                                  "G08 P1\n"])
def test_look_ahead_codes_are_neutral(line):
    text = "G21 G90\nG0 X1 Y2 Z3\n" + line + "G1 X4 F100\nM30\n"
    out, rep = identity(text)
    assert out == text
    assert rep.moves == 2


@pytest.mark.parametrize(("line", "what"), [
    ("#<toolno> = 1\n", "parameter assignment"),
    ("#100=5.\n", "parameter assignment"),
    ("IF[#890 NE 1] GOTO2\n", "Fanuc custom macro IF"),
    ("WHILE [#1 LT 5] DO1\n", "Fanuc custom macro WHILE"),
    ("o100 sub\n", "LinuxCNC O-word 'sub'"),
    ("O<probe> call [1]\n", "LinuxCNC O-word 'call'"),
    ("G1 X[#1 + 2]\n", "parameter reference"),
    ("G1 X[1 + 2]\n", "expression"),
])
def test_refusals_name_what_the_line_really_is(line, what):
    text = "G21 G90\nG0 X1 Y2 Z3\n" + line + "M30\n"
    with pytest.raises(UnsupportedGcodeError) as err:
        run(text)
    assert what in err.value.message
    assert err.value.lineno == 3
    assert classify_construct(line)[0].startswith(what)


@pytest.mark.parametrize(("line", "what"), [
    ("G38.2 Z-10 F50\n", "probing"),
])
def test_refused_codes_say_why(line, what):
    with pytest.raises(UnsupportedGcodeError) as err:
        run("G21 G90\nG0 X1 Y2 Z3\n" + line + "M30\n")
    assert what in err.value.message
    assert err.value.hint


SPLINES = "G21 G90 G17\nG0 X0 Y0 Z1\nG5 X10 Y0 I2 J5 P-2 Q5 F100\nG5 X20 Y0 P-3 Q-4\nG5.1 X30 Y5 I5 J5\nG0 Z10\nM30\n"


def _bezier(ctrl, s):
    # de Casteljau, independent of the closed form used by the interpreter
    pts = [np.array(c, dtype=float) for c in ctrl]
    while len(pts) > 1:
        pts = [(1 - s) * a + s * b for a, b in zip(pts[:-1], pts[1:], strict=True)]
    return pts[0]


def test_splines_follow_linuxcncs_control_points():
    _, moves = run(SPLINES)
    g5a, g5b, g51 = moves[1], moves[2], moves[3]
    assert g5a.spline == [(0.0, 0.0), (2.0, 5.0), (8.0, 5.0), (10.0, 0.0)]
    # the second G5 without I/J starts in the direction the first ended: I/J = -(P/Q)
    assert g5b.spline == [(10.0, 0.0), (12.0, -5.0), (17.0, -4.0), (20.0, 0.0)]
    assert g51.spline == [(20.0, 0.0), (25.0, 5.0), (30.0, 5.0)]


def test_identity_keeps_splines_and_a_scale_linearises_them_within_tolerance():
    out, rep = identity(SPLINES)
    assert out == SPLINES
    eng = scale_engine(1.0001)
    out, rep = correct_text(SPLINES, eng, ZERO, CorrectOptions(), path="p.nc")
    assert rep.splines_linearised == 3
    assert not any(ln.startswith("G5") for ln in out.splitlines())
    # every emitted vertex, run through the machine (x 1.0001), lies on the nominal splines
    # within the tolerance, and the chords between them stay within it too
    _, moves = run(SPLINES)
    curve = np.vstack([np.array([_bezier(m.spline, s) for s in np.linspace(0, 1, 4001)]) for m in moves[1:4]])
    c0, c1 = curve[:-1], curve[1:]
    seg = c1 - c0
    seg2 = np.maximum((seg * seg).sum(axis=1), 1e-30)

    def distance(p):  # from p to the dense polyline of the splines
        t = np.clip(((p - c0) * seg).sum(axis=1) / seg2, 0.0, 1.0)
        return np.min(np.linalg.norm(c0 + t[:, None] * seg - p, axis=1))

    verts = []
    for ln in out.splitlines():
        if ln.startswith("G1"):
            w = dict((t[0], float(t[1:])) for t in ln.split()[1:] if t[0] in "XY")
            verts.append((w["X"] * 1.0001, w["Y"] * 1.0001))
    verts = np.array(verts)
    for a, b in zip(verts[:-1], verts[1:], strict=True):
        for s in np.linspace(0, 1, 5):
            p = a + s * (b - a)
            assert distance(p) < 0.001
    assert len(verts) < 400


def test_g5_without_ij_first_is_refused_as_linuxcnc_does():
    with pytest.raises(PostprocError, match="needs I and J"):
        run("G21 G90 G17\nG0 X0 Y0 Z1\nG5 X10 Y0 P-2 Q5 F100\nM30\n")


def test_programs_needing_expansion_are_corrected_flat_with_source_line_numbers(tmp_path):
    text = ("G21 G90\nG0 X0 Y0 Z5\n#1 = 10\no100 sub\n  G1 X[#1 + #2] F100\no100 endsub\n"
            "o100 call [0] [1]\no100 call [0] [5]\nG1 Y7\nM2\n")
    out, rep = correct_text(text, scale_engine(1.0001), ZERO, CorrectOptions(), path="p.ngc")
    assert rep.expanded
    head, rest = emit.split_header(out)
    body = rest.splitlines()
    assert "(POSTPROC EXPANDED SUBPROGRAMS LOOPS AND MACROS)\n" in head
    assert body[:2] == ["G21 G90", "G0 X0 Y0 Z4.9995"]
    # the call's arguments are #1 and #2 inside the subroutine (LinuxCNC): X = 0 + 1, 0 + 5
    xs = [float(ln.split()[1][1:]) for ln in body if ln.strip().startswith("G1 X")]
    assert xs == pytest.approx([1 / 1.0001, 5 / 1.0001], abs=6e-5)
    assert body[-2].startswith("G1 Y6.9993")  # an untouched-by-expansion line keeps its own bytes but Y moves
    # errors inside a subroutine name the subroutine's own line
    bad = "G21 G90\nG0 X0 Y0 Z5\no100 sub\n  G1 X[#1 + #<_x>] F100\no100 endsub\no100 call [1]\nM2\n"
    with pytest.raises(PostprocError) as err:
        correct_text(bad, scale_engine(1.0001), ZERO, CorrectOptions(), path="p.ngc")
    assert err.value.lineno == 4
    # --no-expand refuses, naming the construct
    with pytest.raises(UnsupportedGcodeError, match="parameter assignment"):
        correct_text(text, scale_engine(1.0001), ZERO, CorrectOptions(expand=False), path="p.ngc")


def test_fanuc_sample_expands_its_subprogram_and_corrects_cycles_and_g28():
    from pathlib import Path
    text = (Path(__file__).parents[1] / "samples" / "fanuc_drill.nc").read_text()
    setup = Setup(offsets={"G54": (100.0, 100.0, 100.0)}, tool_lengths={1: 100.0},
                  home={"G28": {"X": 0.0, "Y": 0.0, "Z": 300.0}})
    out, rep = correct_text(text, scale_engine(1.0001), setup, CorrectOptions(dialect="fanuc", cycles="expand"),
                            path="fanuc_drill.nc")
    lines = out.splitlines()
    assert lines[0] == "%"
    assert lines[1] == "O1001 (FANUC DRILL SAMPLE)"
    assert emit.is_header_start(lines[2])
    assert "(POSTPROC EXPANDED SUBPROGRAMS LOOPS AND MACROS)" in lines
    assert rep.expanded
    assert rep.cycles_expanded == 5  # three G81 holes, two G83 holes from the M98 subprogram
    assert "M98" not in out
    assert "M99" not in out
    assert "G91 G28 Z0." in lines


def test_blank_lines_before_the_tape_mark_stay_before_it_and_the_header_follows_the_program_number():
    text = "\n%\nO78240\nG21 G90\nG0 X1 Y2 Z3\nM30\n%\n"
    out, _ = correct_text(text, scale_engine(), ZERO, CorrectOptions(), path="p.nc")
    lines = out.splitlines()
    assert lines[:3] == ["", "%", "O78240"]
    assert lines[3].startswith("(POSTPROC ")


def test_the_header_after_a_program_number_with_a_form_feed_is_found():
    # a form feed is a blank inside the program number's comment, not a line end: the
    # header still follows that line
    text = "O1000 (PART\fA)\nG21 G90\nG0 X1 Y2 Z3\nM30\n"
    out, _ = correct_text(text, scale_engine(), ZERO, CorrectOptions(), path="p.nc")
    header, rest = emit.split_header(out)
    assert header
    assert all(line.startswith("(POSTPROC ") for line in header)
    assert rest.startswith("O1000 (PART\fA)\nG21 G90\n")
