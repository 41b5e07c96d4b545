import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from numpy.testing import assert_allclose

from postproc.calibration.axis_tables import AxisTables
from postproc.cli import main
from postproc.simulate import Machine, MachineGeometry, save_machine, simulate_points
from postproc.simulate.program import verify_program
from postproc.simulate.verify import NOMINAL_CHORD_MM, Polyline, point_segment_distance

REPO = Path(__file__).parents[1]
POCKET = REPO / "samples" / "pocket.nc"
VOLUME = [[0, 0, 0], [315, 315, 315]]
# The nominal path's arcs are chords within NOMINAL_CHORD_MM of them: a point on an arc
# is at most that far from the nominal polyline.
CHORD_MM = NOMINAL_CHORD_MM


def offset_machine(offset):
    s = np.array([0.0, 315.0])
    v = np.zeros((2, 6))
    v[:, :3] = offset
    return Machine(MachineGeometry(AxisTables({"X": s}, {"X": v}), {}, VOLUME))


def test_polyline_nearest_is_exact():
    rng = np.random.default_rng(0)
    t = np.linspace(0, 20, 800)
    pts = np.column_stack([10 * np.cos(t), 10 * np.sin(t), t])
    poly = Polyline(pts)
    p = pts[rng.integers(0, 800, 300)] + rng.normal(0, 0.5, (300, 3))
    d, seg = poly.nearest(p)
    brute = np.array([point_segment_distance(np.repeat(x[None], 799, 0), pts[:-1], pts[1:]) for x in p])
    assert_allclose(d, brute.min(axis=1), atol=1e-12)
    assert_allclose(d, brute[np.arange(300), seg], atol=1e-12)
    # Long segments are indexed in pieces; the distances and segment numbers stay exact.
    zig = np.array([[0, 0, 0], [100, 0, 0], [100, 3, 0], [0, 3, 0], [0, 6, 1.0]])
    q = rng.uniform([-5, -2, -1], [105, 8, 2], (400, 3))
    d, seg = Polyline(zig, piece_mm=0.7).nearest(q)
    brute = np.array([point_segment_distance(np.repeat(x[None], 4, 0), zig[:-1], zig[1:]) for x in q])
    assert_allclose(d, brute.min(axis=1), atol=1e-12)
    assert_allclose(d, brute[np.arange(400), seg], atol=1e-12)


def test_ideal_machine_runs_the_program_on_its_path():
    rep = verify_program(POCKET, offset_machine([0, 0, 0]), [], corrected=POCKET)
    for run in rep.runs:
        assert run.max_mm <= CHORD_MM + 1e-12


def test_a_lift_of_the_tool_shows_as_its_height_and_names_lines():
    # Every feed move of the pocket lies in a plane or runs along Z: a 10 um shift in Z is
    # a 10 um deviation everywhere except on the plunges, which it slides along.
    rep = verify_program(POCKET, offset_machine([0, 0, 0.010]), [], corrected=POCKET)
    run = rep.runs[0]
    assert run.max_mm == pytest.approx(0.010, abs=CHORD_MM)
    plunges = {9, 18, 27}  # file lines of N60, N150, N240 (G1 Z.. plunges)
    lines = {ln for ln, _ in run.worst_lines()}
    assert not lines & plunges
    # A shift along X leaves the X-direction moves on their line and moves the others.
    run_x = verify_program(POCKET, offset_machine([0.010, 0, 0]), [], corrected=POCKET).runs[0]
    on_line = run_x.deviation_mm[run_x.feed] <= CHORD_MM
    assert on_line.any()
    assert (~on_line).any()
    assert run_x.max_mm == pytest.approx(0.010, abs=CHORD_MM)


def test_verify_program_cli_json_and_plot(tmp_path):
    mpath = tmp_path / "lift.machine.json"
    save_machine(mpath, offset_machine([0, 0, 0.004]))
    png = tmp_path / "dev.png"
    res = CliRunner().invoke(main, ["verify", str(POCKET), "--corrected", str(POCKET), "--machine",
                                    str(mpath), "--json", "--plot", str(png)])
    assert res.exit_code == 0, res.output
    data = json.loads(res.stdout)
    assert [r["label"] for r in data["runs"]] == ["uncorrected", "corrected (pocket.nc)"]
    assert data["runs"][0]["max_mm"] == pytest.approx(0.004, abs=CHORD_MM)
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    for side in ("actual_to_nominal", "nominal_to_actual"):
        assert data["runs"][0][side]["max_mm"] == pytest.approx(0.004, abs=CHORD_MM)
    res = CliRunner().invoke(main, ["verify", str(POCKET), "--corrected", str(POCKET), "--machine", str(mpath)])
    assert res.exit_code == 0, res.output
    assert "max = two-sided, the larger of (a) and (b)" in res.stdout
    row = next(ln for ln in res.stdout.splitlines() if ln.strip().startswith("uncorrected")).split()
    assert [float(row[i]) for i in (1, 2, 4)] == pytest.approx([4.0, 4.0, 4.0], abs=0.01)  # the maxima
    res = CliRunner().invoke(main, ["verify", str(POCKET), "--machine", str(mpath)])
    assert res.exit_code == 2
    assert "-c CALIBRATION" in res.output


def test_machine_with_backlash_effect_depends_on_approach():
    m = offset_machine([0, 0, 0])
    m = Machine(m.geometry, effects=[{"name": "backlash:X", "config": {}, "params": {"b_mm": 0.02}}])
    q = np.array([[100.0, 50, 50]] * 2)
    meas = simulate_points(m, q, None, None, direction=[[1, 1, 1], [-1, 1, 1]], noise=False)
    assert_allclose(meas.m[0] - meas.m[1], [0.02, 0, 0], atol=1e-12)
    res = m.inverse(meas.m, None, {"dirx": np.array([1.0, -1.0])})
    assert_allclose(res.q, q, atol=1e-6)


@pytest.fixture(scope="module")
def s500_parametric(tmp_path_factory):
    """A parametric calibration fitted from simulated 2 mm interferometer tables."""
    from postproc.calfile import save_calibration
    from postproc.calibration.tables import write_tables
    from postproc.metrology.tables_fit import fit_tables
    from postproc.simulate.s500 import s500_machine
    from postproc.simulate.tables import simulate_tables

    d = tmp_path_factory.mktemp("s500")
    tabs, sq = simulate_tables(s500_machine(), 2.0, np.random.default_rng(11))
    write_tables(d / "t.csv", d / "t_squareness.csv", tabs, sq)
    cal = d / "par.json"
    save_calibration(cal, fit_tables([str(d / "t.csv")]).engine, name="s500_par")
    return cal


def test_corrected_pocket_stays_within_2um_on_s500(s500_parametric):
    s500 = REPO / "calibrations" / "s500.machine.json"
    res = CliRunner().invoke(main, ["verify", str(POCKET), "-c", str(s500_parametric), "--machine", str(s500),
                                    "--json"])
    assert res.exit_code == 0, res.output
    before, after = json.loads(res.stdout)["runs"]
    assert before["max_mm"] > 0.100
    assert after["max_mm"] < 0.002
    assert after["feed_samples"] >= before["feed_samples"]  # the corrected run covers the program too


def test_corrected_pocket_with_a_tool_and_work_offset(s500_parametric):
    from postproc.calfile import load_calibration
    from postproc.simulate.s500 import s500_machine

    # The same pocket moved by G54 and cut with a 100 mm tool: the gauge point runs 100 mm
    # higher, where the machine's errors differ, and the angular errors act on the tool.
    text = POCKET.read_text().replace("N10 G21 G90 G17 G94", "N10 G21 G90 G17 G94 G54 G43 H1")
    prog = s500_parametric.parent / "pocket_g54.nc"
    prog.write_text(text)
    setup = {"offsets": {"G54": (40.0, 60.0, 20.0)}, "tool_lengths": {1: 100.0}}
    rep = verify_program(prog, s500_machine(), [load_calibration(s500_parametric)], setup)
    before, after = rep.runs
    assert before.max_mm > 0.100
    assert after.max_mm < 0.002


def test_a_skipped_stretch_shows_in_the_nominal_to_actual_direction(tmp_path):
    # The second pass (N150..N230, at Z46) left out: every point the program reaches lies
    # on the nominal path, but the Z46 contour is 2 mm from anything it cuts.
    lines = POCKET.read_text().splitlines(keepends=True)
    first = next(i for i, ln in enumerate(lines) if ln.startswith("N150"))
    last = next(i for i, ln in enumerate(lines) if ln.startswith("N230"))
    skipped = tmp_path / "skipped.nc"
    skipped.write_text("".join(lines[:first] + lines[last + 1:]))
    run = verify_program(POCKET, offset_machine([0, 0, 0]), [], corrected=skipped).runs[1]
    assert run.actual_to_nominal_max_mm <= CHORD_MM + 1e-12
    assert run.nominal_to_actual_max_mm == pytest.approx(2.0, abs=CHORD_MM)
    assert run.max_mm == run.nominal_to_actual_max_mm
    assert {ln for ln, _ in run.worst_lines()} <= set(range(first + 1, last + 2))
    # The nominal samples of the skipped lines are the ones far from the run.
    far = run.nominal_to_actual_mm > 0.5
    assert set(run.nominal_sample_line[far]) <= set(range(first + 1, last + 2))


def test_a_corrected_program_that_stops_early_scores_badly(s500_parametric, tmp_path):
    from postproc.calfile import load_calibration
    from postproc.simulate.program import correct_program_text, make_setup
    from postproc.simulate.s500 import s500_machine

    fixed = correct_program_text(POCKET.read_text(), load_calibration(s500_parametric), make_setup(None),
                                 path=str(POCKET)).splitlines(keepends=True)
    # Leave out the helix (N270 and the lines it was split into), the last feed move.
    start = next(i for i, ln in enumerate(fixed) if ln.startswith("N260")) + 1
    end = next(i for i, ln in enumerate(fixed) if ln.startswith("N270"))
    assert end - start >= 1
    short = tmp_path / "short.nc"
    short.write_text("".join(fixed[:start] + fixed[end + 1:]))
    rep = verify_program(POCKET, s500_machine(), [], corrected=short)
    before, after = rep.runs
    # One-sided, the truncated program still looks corrected ...
    assert after.actual_to_nominal_max_mm < 0.002
    # ... two-sided, the 5 mm helix it never cuts is millimetres from its path.
    assert after.nominal_to_actual_max_mm > 5.0
    assert after.max_mm > 5.0
    assert after.worst_lines()[0][0] == 30  # file line of N270
    assert before.max_mm < 0.400
    data = rep.to_dict()["runs"][1]
    assert data["max_mm"] == after.max_mm
    assert data["actual_to_nominal"]["max_mm"] < 0.002
    assert data["nominal_to_actual"]["max_mm"] == after.nominal_to_actual_max_mm
    assert data["nominal_to_actual"]["samples"] == np.count_nonzero(~before.rapid)


def test_actual_path_samples_match_program_path_but_follow_arcs_closely():
    from postproc.gcode.path import Setup, program_path
    from postproc.simulate.verify import actual_path_samples

    # With a chord tolerance that asks for no more points, the samples are program_path's:
    # offsets, tool length, G91, rotary axes and context included.
    cases = [(POCKET, Setup()), (REPO / "samples" / "holes_g91.nc", Setup()),
             (REPO / "samples" / "g54_g43.ngc", Setup(offsets={"G54": (100.0, 80.0, 40.0)},
                                                     tool_lengths={1: 100.0}, context={"temp": 21.5})),
             (REPO / "samples" / "mirror" / "pocket.nc", Setup())]
    for prog, setup in cases:
        ref = program_path(str(prog), setup, max_step_mm=0.5)
        same = actual_path_samples(str(prog), setup, 0.5, chord_mm=1e9)
        np.testing.assert_array_equal(same.points_mm, ref.points_mm)
        np.testing.assert_array_equal(same.tool_mm, ref.tool_mm)
        np.testing.assert_array_equal(same.lineno, ref.lineno)
        np.testing.assert_array_equal(same.rapid, ref.rapid)
        assert same.context.keys() == ref.context.keys()
        for k in ref.context:
            np.testing.assert_array_equal(same.context[k], ref.context[k])
    # With the default, arc chords stay within NOMINAL_CHORD_MM of the arcs: every
    # chord midpoint of the 8 mm corner arc N80 (centre 172,118) is that close to it.
    fine = actual_path_samples(str(POCKET), Setup(), 0.5)
    on = np.flatnonzero(fine.lineno == 11)
    pts = fine.points_mm[np.r_[on[0] - 1, on]]
    mid = 0.5 * (pts[1:] + pts[:-1])
    sag = 8.0 - np.hypot(mid[:, 0] - 172.0, mid[:, 1] - 118.0)
    assert sag.max() <= CHORD_MM
    assert sag.max() > CHORD_MM / 4  # no more points than the tolerance needs


def test_worst_lines_show_their_own_text_after_a_form_feed(tmp_path):
    # A form feed is a blank inside a G-code line (in a comment or between words), not a
    # line end: the text shown for each worst line is that line of the file.
    text = POCKET.read_text()
    text = text.replace("(pocket.nc: rectangular", "(pocket.nc:\frectangular", 1)
    text = text.replace("N10 G21 G90", "N10 G21\fG90", 1)
    assert text.count("\f") == 2
    prog = tmp_path / "ff.nc"
    prog.write_bytes(text.encode())
    lines = text.split("\n")
    rep = verify_program(prog, offset_machine([0, 0, 0.010]), [], corrected=prog)
    worst = rep.to_dict()["runs"][0]["worst_lines"]
    assert worst
    for w in worst:
        assert w["text"] == lines[w["line"] - 1].strip()
        assert w["text"].startswith("N")  # a move's line, never a comment
