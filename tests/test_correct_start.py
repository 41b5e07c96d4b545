"""--start: the machine position of axes a program has not positioned yet (2-D programs
that never name Z)."""

import re

import numpy as np
import pytest
from click.testing import CliRunner
from conftest import assert_same, landing_error, other_line, plain_line, run_all
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from postproc.cli import main
from postproc.engine.identity import IdentityEngine
from postproc.engine.static import StaticEngine
from postproc.errors import MissingSetupError
from postproc.gcode import emit
from postproc.gcode.path import Setup, program_path
from postproc.gcode.pipeline import CorrectOptions, correct_text

TOL = 0.001
# squareness between Z and X/Y: X/Y targets need a Z change (p_z depends on q_x, q_y)
G_Z = np.array([[1 + 300e-6, 900e-6, -600e-6], [200e-6, 1 - 200e-6, 1000e-6], [700e-6, -500e-6, 1 + 150e-6]])
ENGINE = StaticEngine(G_Z, [0.03, -0.02, 0.01], [[-1e4] * 3, [1e4] * 3])
SETUP = Setup(offsets={"G54": (100.0, 80.0, 0.0)}, start={"Z": 150.0})

# a 2-D program: X/Y only, lines and arcs (Z is never named)
FLAT = """G21 G90 G17 G94
G0 X10 Y10
G1 X60 Y10 F800
G3 X60 Y50 I0 J20
G1 X10 Y50
G2 X10 Y10 R20
G0 X0 Y0
M30
"""


def test_without_start_a_program_that_never_names_z_is_refused_naming_start():
    with pytest.raises(MissingSetupError) as err:
        correct_text(FLAT, ENGINE, Setup(offsets={"G54": (100.0, 80.0, 0.0)}))
    assert "Z is never positioned" in err.value.message
    assert "--start Z" in err.value.hint


def test_start_is_used_only_until_the_program_names_the_axis():
    setup = Setup(start={"X": 7.0, "Y": 8.0, "Z": 150.0})
    pp = program_path("G21 G90\nG1 X10 F100\nG1 Z5\nG1 Y2\n", setup, max_step_mm=1000)
    np.testing.assert_allclose(pp.points_mm, [[10, 8, 150], [10, 8, 5], [10, 2, 5]])
    # the feed move out of the start is a path (sampled from the start), not a lone point
    pp = program_path("G21 G90\nG1 X10 F100\n", setup, max_step_mm=1.0)
    assert len(pp) == 3
    np.testing.assert_allclose(pp.points_mm[0], [8, 8, 150])
    assert pp.context["dirx"][0] == 1


def test_start_is_the_gauge_position_tool_length_and_offsets_apply_to_program_words():
    setup = Setup(offsets={"G54": (100.0, 0.0, -200.0)}, tool_lengths={1: 100.0}, start={"Z": 300.0})
    pp = program_path("G21 G90 G43 H1\nG0 X10 Y0\nG1 Z20 F100\n", setup, max_step_mm=1000)
    # functional point = start + r while Z is not named; then word + offset + tool length + r
    np.testing.assert_allclose(pp.points_mm, [[110, 0, 200], [110, 0, -180]])
    np.testing.assert_allclose((pp.points_mm - pp.tool_mm)[:, 2], [300, -80])


def test_start_allows_incremental_moves_arcs_and_g92_from_the_start():
    setup = Setup(start=(100.0, 50.0, 20.0))
    pp = program_path("G21 G91\nG1 X5 F100\nG90 G92 X0\nG1 X1\n", setup, max_step_mm=1000)
    np.testing.assert_allclose(pp.points_mm, [[105, 50, 20], [106, 50, 20]])
    pp = program_path("G21 G90 G17\nG3 X90 Y60 I-10 J0 F100\n", setup, max_step_mm=0.5)
    np.testing.assert_allclose(np.hypot(pp.points_mm[:, 0] - 90, pp.points_mm[:, 1] - 50), 10.0, atol=1e-9)


def test_the_corrected_2d_program_gains_z_words_and_lands_on_the_nominal_path():
    out, rep = correct_text(FLAT, ENGINE, SETUP, CorrectOptions(tolerance_mm=TOL))
    assert "(POSTPROC START Z150)" in "".join(emit.split_header(out)[0])
    assert not re.search("[Zz]", FLAT)
    assert len(re.findall(r"Z1[45]\d\.\d{4}", out)) >= 4  # the correction moves Z as X/Y go
    assert landing_error(FLAT, out, ENGINE, SETUP) <= TOL * 1.01
    # the original misses by far more: the check can fail
    assert landing_error(FLAT, FLAT, ENGINE, SETUP) > 20 * TOL
    # an engine whose Z does not depend on X/Y needs no Z word after the first one
    flat_z = StaticEngine(np.diag([1 + 300e-6, 1 - 200e-6, 1.0]), [0.03, -0.02, 0.0], [[-1e4] * 3, [1e4] * 3])
    out2, _ = correct_text(FLAT, flat_z, SETUP, CorrectOptions(tolerance_mm=TOL))
    assert not re.search("[Zz]", emit.split_header(out2)[1])


def test_start_needs_the_work_offset_of_the_program():
    # words added on an axis known only from --start are written in the work frame
    with pytest.raises(MissingSetupError) as err:
        correct_text(FLAT, ENGINE, Setup(start={"Z": 150.0}))
    assert "--offset G54" in err.value.hint
    assert err.value.lineno == 2
    # a program naming its own offset is fine once that offset is given
    out, _ = correct_text("G55\n" + FLAT, ENGINE, Setup(offsets={"G55": (100.0, 80.0, 0.0)}, start={"Z": 150.0}))
    assert "G0 X" in out


def test_identity_with_start_changes_nothing_but_the_header():
    out, rep = correct_text(FLAT, IdentityEngine([[-1e4] * 3, [1e4] * 3]), SETUP)
    assert emit.split_header(out)[1] == FLAT
    assert rep.words_changed == 0


@st.composite
def flat_program(draw):
    body = ["G21 G90 G17 G94", "G0 X10 Y10"]
    for _ in range(draw(st.integers(1, 30))):
        line = draw(other_line()) if draw(st.integers(0, 4)) == 0 else draw(plain_line())
        body.append(line)
    ending = draw(st.sampled_from(["\n", "\r\n"]))
    return ending.join(body) + ending


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(flat_program(), st.sampled_from([1, 3, 20_000]),
       st.sampled_from([{"Z": 150.0}, {"X": 5.0, "Y": -3.0, "Z": 40.0}, {"Y": 12.0}]))
def test_lanes_give_the_same_output_with_a_start(text, chunk_lines, start):
    setup = Setup(offsets={"G54": (100.0, 80.0, 40.0)}, tool_lengths={1: 50.0}, start=start)
    assert_same(run_all(text, chunk_lines=chunk_lines, setup=setup, engine=ENGINE))


def test_cli_start_option(tmp_path):
    src = tmp_path / "flat.nc"
    src.write_text(FLAT)
    cal = tmp_path / "cal.json"
    from postproc.calfile import save_calibration

    save_calibration(cal, ENGINE, name="zsq")
    runner = CliRunner()
    res = runner.invoke(main, ["correct", str(src), "-c", str(cal), "-o", str(tmp_path / "a.nc")])
    assert res.exit_code == 5
    assert "--start" in res.output
    res = runner.invoke(main, ["correct", str(src), "-c", str(cal), "-o", str(tmp_path / "b.nc"),
                               "--offset", "G54=X100,Y80,Z0", "--start", "Z150"])
    assert res.exit_code == 0, res.output
    want, _ = correct_text(FLAT, ENGINE, SETUP)
    assert emit.split_header((tmp_path / "b.nc").read_text())[1] == emit.split_header(want)[1]
    res = runner.invoke(main, ["correct", str(src), "-c", str(cal), "-o", str(tmp_path / "c.nc"),
                               "--offset", "G54=X100,Y80,Z0", "--start", "z5.90551in"])
    assert res.exit_code == 0, res.output
    assert f"(POSTPROC START Z{5.90551 * 25.4!r})" in "".join(emit.split_header((tmp_path / "c.nc").read_text())[0])
    for bad in ("A10", "Z1,Z2", "", "Z", "X1;Y2"):
        res = runner.invoke(main, ["correct", str(src), "-c", str(cal), "--offset", "G54=X0,Y0,Z0",
                                   "--start", bad])
        assert res.exit_code == 2, (bad, res.output)
        assert "--start" in res.output


def test_diff_takes_the_start_from_the_header():
    from postproc.gcode.compare import compare_programs

    lines = "G21 G90\nG0 X10 Y10\nG1 X60 F800\nG1 Y50\nG1 X10\nG0 X0 Y0\nM30\n"
    out, rep = correct_text(lines, ENGINE, SETUP)
    assert rep.lines_inserted == 0  # every move pairs with its own line
    stats = compare_programs(lines, out).axis_stats()
    explicit = compare_programs(lines, out, Setup(start={"Z": 150.0})).axis_stats()
    assert stats == explicit
    # Z moves by the Z-X/Y squareness over X 110..160 mm (0.7 mrad): about 0.1 mm
    assert stats["Z"]["max_mm"] > 0.05
    pp = program_path(out, SETUP, max_step_mm=1e9)
    assert stats["Z"]["max_mm"] == pytest.approx(np.abs((pp.points_mm - pp.tool_mm)[:, 2] - 150.0).max())
    # without the start the Z change of a program that never names Z is not seen
    blind = compare_programs(lines, out.replace("(POSTPROC START Z150)\n", "")).axis_stats()
    assert blind["Z"]["max_mm"] == 0.0
