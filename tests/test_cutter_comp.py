"""Cutter radius compensation (G41/G42/G40, G41.1/G42.1): the programmed contour is
corrected, the compensation words stay, and LinuxCNC's rs274 (given a tool table with
diameters) offsets the corrected contour itself. Its tool-centre path for the corrected
program, sent through the virtual machine the calibration was measured on, must land on
its tool-centre path for the original within the model error + --tolerance + the bound
postproc states (the change of the correction across the tool radius) + rs274's print
rounding.

rs274 standalone reads its tool table in inches (tests/test_oracle.py), so the tables
given to it carry the diameters in inches; postproc's are in mm."""

from pathlib import Path

import numpy as np
import pytest
from conftest import polyline_distance
from oracle import RS274, machine_path, run_rs274  # noqa: I001  (the tests' own helper, a sibling module)

from postproc.errors import GcodeSyntaxError, MissingSetupError, UnsupportedGcodeError
from postproc.gcode.cutter import CutterBoundError
from postproc.gcode.path import Setup
from postproc.gcode.pipeline import CorrectOptions, correct_text

ROOT = Path(__file__).parents[1]
requires_rs274 = pytest.mark.skipif(RS274 is None, reason="LinuxCNC's rs274 is not installed")

# s500_parametric changes by up to about 4.5 um per mm across the volume (a heavily erring
# demonstration machine): a 3 mm radius leaves about 13 um, so these programs run with a
# tolerance that admits it
TOL_MM = 0.015
# rs274's tool-centre path is compared sampled this finely (mm)
LINE_STEP_MM = 0.05

POCKET_INSIDE_G41_MM = """G21 G17 G90 G94
T1 M6
G0 X60 Y60 Z30
G1 Z20 F300
G41 D1 G1 X60 Y45 (lead-in line)
G3 X75 Y30 R15 (lead-in arc)
G1 X140
G3 X160 Y50 I0 J20
G1 Y130
X40
Y30
X75
G3 X90 Y45 R15 (lead-out arc)
G40 G1 X90 Y60 (exit line)
G0 Z30
M2
"""

# the same outline cut from outside (climb, G42 travelling clockwise... as the part's outside)
OUTLINE_OUTSIDE_G42_MM = """G21 G17 G90 G94
T1 M6
G0 X20 Y10 Z30
G1 Z20 F300
G42 G1 X40 Y20 (lead-in line)
G1 X140
G3 X160 Y40 I0 J20
G1 Y130
X40
Y20
G40 G1 X30 Y10 (exit line)
G0 Z30
M2
"""

OUTLINE_OUTSIDE_G41_INCH = """G20 G17 G90 G94
T2 M6
G0 X3.0 Y0.5 Z1.2
G1 Z0.8 F12
G41 D2
G1 X3.6 Y0.8 (entry move)
G2 X3.6 Y4.8 I0 J2.0 (outside of a round boss, clockwise with G41)
G1 X6.0
G2 X6.0 Y0.8 I0 J-2.0
G1 X3.6
G40 G1 X3.0 Y0.5
G0 Z1.2
M2
"""

POCKET_INSIDE_G42_INCH = """G20 G17 G90 G94
T2 M6
G0 X3.0 Y3.0 Z1.2
G1 Z0.8 F12
G42.1 D0.125 G1 X3.0 Y2.0 (G42.1 gives the diameter itself)
G2 X2.0 Y1.0 R1.0 (lead-in arc)
G1 X1.0 Y1.0
Y5.0
X5.0
Y1.0
X2.0
G40 G1 X3.0 Y2.5
G0 Z1.2
M2
"""

# a profile in the XZ plane (G18, as LinuxCNC offsets it: "left" seen from +Y)
PROFILE_XZ_G41_MM = """G21 G18 G90 G94
T1 M6
G0 X40 Y100 Z40
G1 F300
G41 D1 G1 X50 Z50 (entry move)
G1 X120
G2 X140 Z70 R20
G1 Z120
X50
Z50
G40 G1 X40 Z40
M2
"""

PROGRAMS = {
    "profile_xz_g41_mm": (PROFILE_XZ_G41_MM, {1: 3.0}),
    "pocket_inside_g41_mm": (POCKET_INSIDE_G41_MM, {1: 3.0}),
    "outline_outside_g42_mm": (OUTLINE_OUTSIDE_G42_MM, {1: 3.0}),
    "outline_outside_g41_inch": (OUTLINE_OUTSIDE_G41_INCH, {2: 2.0}),
    "pocket_inside_g42_inch": (POCKET_INSIDE_G42_INCH, {}),
}


def rs274_tools(radii: dict[int, float]) -> str:
    """A tool table for standalone rs274: tools 1..9, the given radii as diameters in inches."""
    return "".join(f"T{t} P{t} Z0 D{2 * radii.get(t, 0.0) / 25.4:.6f}\n" for t in range(1, 10))


@pytest.fixture(scope="module")
def s500():
    from postproc.calfile import load_calibration
    from postproc.simulate.machine import load_machine

    return (load_calibration(ROOT / "calibrations" / "s500_parametric.json").engine,
            load_machine(ROOT / "calibrations" / "s500.machine.json"))


def _correct(text, engine, radii, tol=TOL_MM):
    setup = Setup(tool_radii=radii)
    return correct_text(text, engine, setup, CorrectOptions(tolerance_mm=tol, dialect="linuxcnc"))


@requires_rs274
@pytest.mark.parametrize("name", sorted(PROGRAMS))
def test_corrected_comp_program_lands_on_the_original_tool_centre_path(name, s500):
    engine, machine = s500
    text, radii = PROGRAMS[name]
    out, rep = _correct(text, engine, radii)
    assert rep.cutter is not None
    assert rep.cutter.moves > 0
    bound = rep.cutter.bound_mm
    assert 0.0 < bound <= TOL_MM
    assert f"{bound * 1000:.2f} UM" in out.upper()  # the header states it
    # the compensation words are kept as they are
    for word in ("G41 D1", "G42 G1", "G41 D2", "G42.1 D0.125", "G40 G1"):
        assert (word in out) == (word in text)
    tools = rs274_tools(radii)
    ref = run_rs274(text, tools=tools)
    got = run_rs274(out, tools=tools)
    assert ref.ok, ref.error
    assert got.ok, got.error
    inch = "G20" in text
    step = 25.4e-4 if inch else 1e-4  # rs274 prints 4 decimals in the program's units
    # the model error: the calibration's own miss on the original tool-centre path
    _, ref_path, _ = machine_path(ref, LINE_STEP_MM, mm=True)
    q = ref_path + engine.correction(ref_path, np.zeros_like(ref_path), {}).q
    model = float(np.linalg.norm(machine.forward(q, np.zeros_like(q)) - ref_path, axis=1).max())
    centre = _deviation(ref, got, machine)
    assert centre <= model + TOL_MM + bound + 2 * step
    # tighter: beyond what the contour itself deviates (the same programs run with radius 0,
    # model error and emitted tolerance included), the tool centre adds at most the bound
    zero = {"D0.125": "D0"}
    contour = _deviation(run_rs274(_replace(text, zero), tools=rs274_tools({})),
                         run_rs274(_replace(out, zero), tools=rs274_tools({})), machine)
    assert centre <= contour + bound + 2 * step


def _replace(text: str, words: dict[str, str]) -> str:
    for a, b in words.items():
        text = text.replace(a, b)
    return text


def _deviation(ref, got, machine) -> float:
    """How far (mm, both ways) the path rs274 printed for the corrected program, where the
    virtual machine takes it, lies from the path it printed for the original."""
    _, ref_path, ref_rapid = machine_path(ref, LINE_STEP_MM, mm=True)
    _, got_path, got_rapid = machine_path(got, LINE_STEP_MM, mm=True)
    actual = machine.forward(got_path, np.zeros_like(got_path))
    return max(polyline_distance(actual[~got_rapid], ref_path).max(),
               polyline_distance(ref_path[~ref_rapid], actual).max())


@pytest.mark.parametrize("name", sorted(PROGRAMS))
def test_the_bound_is_refused_above_the_tolerance_naming_it(name, s500):
    engine, _machine = s500
    text, radii = PROGRAMS[name]
    with pytest.raises(CutterBoundError) as info:
        _correct(text, engine, radii, tol=0.001)
    msg = str(info.value)
    assert "more than the tolerance 0.001 mm" in msg
    assert " um across the tool radius" in msg


def test_an_identity_calibration_leaves_the_program_as_it_is():
    from postproc.engine.static import StaticEngine

    eng = StaticEngine(np.eye(3), np.zeros(3), [[-1e6] * 3, [1e6] * 3])
    for text, radii in PROGRAMS.values():
        out, rep = _correct(text, eng, radii, tol=0.001)
        assert rep.cutter.bound_mm == 0.0
        assert out.endswith(text)


def test_the_radius_must_be_given():
    from postproc.engine.static import StaticEngine

    eng = StaticEngine(np.eye(3), np.zeros(3), [[-1e6] * 3, [1e6] * 3])
    with pytest.raises(MissingSetupError) as info:
        _correct(POCKET_INSIDE_G41_MM, eng, {})
    assert "--tool-radius 1=R" in info.value.hint
    assert info.value.lineno == 5


def test_radius_from_the_tool_table_and_the_options(tmp_path):
    from postproc.cli.options import build_setup

    table = tmp_path / "tools.tbl"
    table.write_text("T1 P1 Z100 D6 ;six\nT2 P2 Z50\n")
    assert build_setup(tool_table=str(table)).tool_radii == {1: 3.0}
    assert build_setup(tool_table=str(table), tool_radius=("1=2.5",)).tool_radii == {1: 2.5}
    assert build_setup(tool_diameter=("4",), tool_radius=("D2=1",)).tool_radii == {None: 2.0, 2: 1.0}


# programs LinuxCNC refuses under compensation, and the message rs274 gives
LINUXCNC_RULES = [
    ("G41\nG1 X1 Y0\n", "Length of cutter compensation entry move is not greater than the tool radius"),
    ("G41\nG1 Z-1\nG1 X10 Y0\n", "Length of cutter compensation entry move is not greater than the tool radius"),
    ("G41\nG2 X1 Y1 I1 J0\n", "Radius of cutter compensation entry arc is not greater than the tool radius"),
    ("G41\nG1 X10 Y0\nG41\n", "Cannot turn cutter radius comp on when on"),
    ("G41\nG1 X10 Y0\nG40\nG2 X20 I5\n", "The move just after exiting cutter compensation mode must be straight"),
    ("G41\nG1 X10 Y0\nG18\n", "Cannot change planes with cutter radius compensation on"),
    ("G41\nG1 X10 Y0\nG28\n", "Cannot use g28 or g30 with cutter radius comp"),
    ("G41\nG1 X10 Y0\nG53 G1 X5\n", "Cannot use g53 with cutter radius comp"),
    ("G41\nG1 X10 Y0\nG81 X5 Z-1 R1\n", "Cannot use canned cycles with cutter compensation on"),
    ("G41\nG1 X10 Y0\nG3 X10 Y3 R1.5\n", "Tool radius not less than arc radius with comp"),
    ("G41\nG1 X10 Y0\nG43 H1\n", "Cannot change tool offset with cutter radius compensation on"),
    ("G41\nG1 X10 Y0\nT2 M6\n", "Cannot change tools with cutter radius compensation on"),
    ("G41\nG1 X10 Y0\nG55\n", "Cannot change coordinate systems with cutter radius compensation on"),
    ("G19\nG41\n", "Cutter radius compensation allowed only in XY, XZ planes"),
    ("G41.1 X10\n", "G41.1 with no D word"),
]


@pytest.mark.parametrize(("body", "message"), LINUXCNC_RULES)
def test_linuxcnc_comp_rules_are_refused_with_rs274s_reason(body, message):
    from postproc.engine.static import StaticEngine

    text = f"G21 G17 G90 F100\nT1 M6\nG0 X0 Y0 Z0\n{body}G40 G1 X30 Y30\nM2\n"
    eng = StaticEngine(np.eye(3), np.zeros(3), [[-1e6] * 3, [1e6] * 3])
    with pytest.raises((GcodeSyntaxError, UnsupportedGcodeError)) as info:
        _correct(text, eng, {1: 2.0, 2: 1.0})
    assert message in info.value.message
    if RS274 is not None:
        res = run_rs274(text, tools=rs274_tools({1: 2.0, 2: 1.0}))
        assert not res.ok
        assert message in res.error


def test_fanuc_refuses_an_arc_as_the_start_up_move():
    from postproc.engine.static import StaticEngine

    eng = StaticEngine(np.eye(3), np.zeros(3), [[-1e6] * 3, [1e6] * 3])
    text = "G21 G17 G90 F100\nG0 X0 Y0 Z0\nG41 D1\nG2 X10 Y0 I5 J0\nG40 G1 X0\nM30\n"
    with pytest.raises(UnsupportedGcodeError, match="start-up move"):
        correct_text(text, eng, Setup(tool_radii={1: 2.0}), CorrectOptions(dialect="fanuc"))


def test_a_backlash_take_up_under_compensation_is_refused():
    from postproc.effects import compose, get_effect
    from postproc.engine.identity import IdentityEngine

    # lost motion (b < 0) is taken up by an inserted move, which the controller would offset
    # as a contour element of its own; an axis that runs ahead (b > 0) needs no take-up
    eng = compose(IdentityEngine([[-1000.0] * 3, [1000.0] * 3]),
                  [get_effect("backlash:X", params={"b_mm": -0.004}).to_dict()])
    text = "G21 G17 G90 F100\nT1 M6\nG0 X0 Y0 Z0\nG41 G1 X10 Y0\nX20\nY10\nX10\nG40 G1 X0 Y0\nM2\n"
    with pytest.raises(UnsupportedGcodeError, match="take-up"):
        _correct(text, eng, {1: 1.0}, tol=0.01)


def test_the_command_reads_diameters_from_the_tool_table_and_reports_the_bound(tmp_path):
    from click.testing import CliRunner

    from postproc.cli import main

    prog = tmp_path / "pocket.ngc"
    prog.write_text(POCKET_INSIDE_G41_MM)
    table = tmp_path / "tools.tbl"
    table.write_text("T1 P1 Z0 D6\n")
    out = tmp_path / "out.ngc"
    cal = str(ROOT / "calibrations" / "s500_parametric.json")
    res = CliRunner().invoke(main, ["correct", str(prog), "-c", cal, "--tool-table", str(table),
                                    "--tolerance", "0.015", "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert "cutter radius compensation kept: 10 moves" in res.output
    assert "(line 13, tool 1 radius 3 mm)" in res.output
    assert "(POSTPROC CUTTER COMP TOOL 1 RADIUS 3 MM BOUND" in out.read_text()
    res = CliRunner().invoke(main, ["correct", str(prog), "-c", cal, "--tool-table", str(table), "-o", str(out)])
    assert res.exit_code == 5
    assert "more than the tolerance 0.001 mm" in res.output


def test_fanuc_reads_d_as_a_modal_offset_register():
    from postproc.engine.static import StaticEngine

    eng = StaticEngine(np.eye(3) * 1.0001, np.zeros(3), [[-1e6] * 3, [1e6] * 3])
    text = ("%\nO1000\nG21 G17 G90 G94\nT1 M6\nG0 X0 Y0 Z5\nG1 Z-1 F100\nG41 D11 G1 X10 Y0\nX20\nG40 G1 X30\n"
            "G42 G1 X40 Y-10\nX50\nG40 G1 X60\nM30\n%\n")
    out, rep = correct_text(text, eng, Setup(tool_radii={11: 2.0}), CorrectOptions(dialect="fanuc"))
    assert rep.cutter.radii == {"D11": 2.0}  # the second G42 offsets by D11 too
    assert rep.cutter.moves == 6
    assert "G41 D11 G1" in out
    assert "(POSTPROC CUTTER COMP D11 RADIUS 2 MM BOUND" in out
    with pytest.raises(MissingSetupError, match="radius of D11"):
        correct_text(text, eng, Setup(tool_radii={1: 2.0}), CorrectOptions(dialect="fanuc"))


def test_a_take_up_in_a_subprogram_is_not_taken_for_a_compensated_line_of_the_same_number(tmp_path):
    # the compensated moves are known by file and line: a subprogram's line 5 is not the
    # main program's line 5, which the controller offsets (the take-up there goes in)
    from postproc.effects import compose, get_effect
    from postproc.engine.identity import IdentityEngine
    from postproc.gcode.pipeline import correct_file

    eng = compose(IdentityEngine([[-1000.0] * 3, [1000.0] * 3]),
                  [get_effect("backlash:X", params={"b_mm": -0.004}).to_dict()])
    main = "G21 G17 G90 F100\nT1 M6\nG0 X0 Y0 Z0\nG1 X5 Y5\nG41 G1 X10 Y6\nX20\nY10\nG40 G1 X40 Y40\n" \
           "o<back> call\nM2\n"
    sub = "o<back> sub\nG1 X60 Y40\nG1 X70\nG1 Y50\nG1 X65\no<back> endsub\nM2\n"
    assert main.splitlines()[4] == "G41 G1 X10 Y6"  # line 5 of each
    assert sub.splitlines()[4] == "G1 X65"
    (tmp_path / "subs").mkdir()
    (tmp_path / "subs" / "back.ngc").write_text(sub)
    (tmp_path / "main.ngc").write_text(main)
    rep = correct_file(str(tmp_path / "main.ngc"), str(tmp_path / "out.ngc"), eng, Setup(tool_radii={1: 1.0}),
                       CorrectOptions(subroutine_path=[str(tmp_path / "subs")], tolerance_mm=0.01))
    assert rep.takeups >= 1  # the reversal on X at the subprogram's line 5 is taken up


def test_the_summary_names_the_subprogram_file_of_the_largest_change(tmp_path):
    # the compensated moves are in a subprogram's file: the summary's line is that file's
    from click.testing import CliRunner

    from postproc.cli import main

    prog = "G21 G17 G90 F100\nT1 M6\nG0 X100 Y100 Z100\no<comp> call\nG0 X150\nM2\n"
    sub = "o<comp> sub\nG41 G1 X110 Y105\nX160\nY140\nX110\nG40 G1 X100 Y100\no<comp> endsub\nM2\n"
    (tmp_path / "subs").mkdir()
    (tmp_path / "subs" / "comp.ngc").write_text(sub)
    (tmp_path / "main.ngc").write_text(prog)
    table = tmp_path / "tools.tbl"
    table.write_text("T1 P1 D6 Z0\n")
    cal = str(ROOT / "calibrations" / "s500_parametric.json")
    res = CliRunner().invoke(main, ["correct", str(tmp_path / "main.ngc"), "-c", cal, "--tool-table", str(table),
                                    "--subroutine-path", str(tmp_path / "subs"), "--tolerance", "0.015",
                                    "-o", str(tmp_path / "out.ngc")])
    assert res.exit_code == 0, res.output
    assert "cutter radius compensation kept: 5 moves" in res.output
    place = res.output.split("across the tool radius (line ")[1].split(",")[0]
    assert place.endswith("comp.ngc:" + place.rsplit(":", 1)[1])
    assert 2 <= int(place.rsplit(":", 1)[1]) <= 6  # a line of the subprogram's file, in that file's numbers
