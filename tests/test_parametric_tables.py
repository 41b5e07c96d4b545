import json

import numpy as np
import pytest
from click.testing import CliRunner
from numpy.testing import assert_allclose

from postproc.calfile import load_calibration
from postproc.calibration.axis_tables import AXES, AxisTables, Squareness
from postproc.calibration.tables import (
    format_squareness,
    format_tables,
    read_squareness,
    read_tables,
    squareness_path_for,
)
from postproc.cli import main
from postproc.engine.parametric import ParametricEngine
from postproc.errors import EXIT_INPUT, CalibrationError, MeasurementError
from postproc.metrology.tables_fit import fit_tables
from postproc.simulate.s500 import synthetic_tables

RNG = np.random.default_rng(11)


def write_machine(tmp_path, seed=0, length_unit="mm", angle_unit="rad", name="tables.csv"):
    tables, sq = synthetic_tables(seed)
    path = tmp_path / name
    path.write_text(format_tables(tables, length_unit=length_unit, angle_unit=angle_unit))
    squareness_path_for(path).write_text(format_squareness(sq, angle_unit=angle_unit))
    return path, tables, sq


@pytest.mark.parametrize("length_unit", ["mm", "um"])
@pytest.mark.parametrize("angle_unit", ["rad", "urad", "arcsec"])
def test_every_unit_combination_gives_the_same_model(tmp_path, length_unit, angle_unit):
    path, tables, sq = write_machine(tmp_path, length_unit=length_unit, angle_unit=angle_unit)
    read = read_tables(path)
    sq_read = read_squareness(squareness_path_for(path))
    for ax in AXES:
        assert_allclose(read.position_mm[ax], tables.position_mm[ax], rtol=1e-13)
        assert_allclose(read.errors[ax], tables.errors[ax], rtol=1e-12, atol=1e-18)
    assert_allclose(list(sq_read.as_dict().values()), list(sq.as_dict().values()), rtol=1e-12)
    q = RNG.uniform(0, 315, (50, 3))
    r = np.array([0, 0, -100.0])
    assert_allclose(ParametricEngine(read, sq_read).forward(q, r), ParametricEngine(tables, sq).forward(q, r),
                    atol=1e-12)


def test_unit_text_is_converted(tmp_path):
    path = tmp_path / "t.csv"
    # positions 0 and 100000 um: a 100 mm axis (a 0.1 mm one would be refused as implausible)
    rows = "".join(f"{ax},{x},1,2,3,1,2,3\n" for ax in AXES for x in (0, 100000))
    path.write_text("# postproc axis error tables v1\n# units: length=um angle=arcsec\n"
                    "axis,position,EX,EY,EZ,EA,EB,EC\n" + rows)
    t = read_tables(path)
    assert_allclose(t.position_mm["Y"], [0, 100])
    assert_allclose(t.errors["Z"][0], [1e-3, 2e-3, 3e-3, *(np.array([1, 2, 3]) * np.pi / 648000)])


def test_uneven_positions_not_starting_at_zero(tmp_path):
    path = tmp_path / "t.csv"
    rows = "".join(f"{ax},{x},0.001,0,0,0,0,0\n" for ax in AXES for x in (-20, 5, 7.5, 300))
    path.write_text("# units: length=mm angle=rad\naxis,position,EX,EY,EZ,EA,EB,EC\n" + rows)
    t = read_tables(path)
    assert_allclose(t.volume_mm, [[-20] * 3, [300] * 3])


BAD_TABLES = [
    # (replace line k (1-based) with text, expected line, expected col, words in message)
    (4, "X,15.000,0.1,zz,0,0,0,0", 4, 14, "not a number"),
    (4, "W,15.000,0,0,0,0,0,0", 4, 1, "not one of X, Y, Z"),
    (5, "X,0.000,0,0,0,0,0,0", 5, 3, "does not increase"),
]


def base_table_lines():
    lines = ["# postproc axis error tables v1", "# units: length=mm angle=rad", "axis,position,EX,EY,EZ,EA,EB,EC"]
    for ax in AXES:
        for x in (0.0, 15.0, 30.0):
            lines.append(f"{ax},{x:.3f},0,0,0,0,0,0")
    return lines


@pytest.mark.parametrize(("k", "text", "line", "col", "words"), BAD_TABLES)
def test_malformed_tables_name_line_and_column(tmp_path, k, text, line, col, words):
    lines = base_table_lines()
    lines[k - 1] = text
    path = tmp_path / "bad.csv"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(MeasurementError) as info:
        read_tables(path)
    err = info.value
    assert (err.path, err.lineno, err.col) == (str(path), line, col)
    assert words in err.message
    assert str(err).startswith(f"{path}:{line}:{col}: ")


def test_missing_axis_and_single_row_are_refused(tmp_path):
    lines = [ln for ln in base_table_lines() if not ln.startswith("Z")]
    path = tmp_path / "noz.csv"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(MeasurementError, match="axis Z has no rows"):
        read_tables(path)
    lines = [ln for ln in base_table_lines() if not ln.startswith("Y,15") and not ln.startswith("Y,30")]
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(MeasurementError, match="axis Y has 1 row") as info:
        read_tables(path)
    assert info.value.lineno == 7


def test_missing_column_and_bad_unit(tmp_path):
    lines = base_table_lines()
    lines[2] = "axis,position,EX,EY,EZ,EA,EB"
    lines[3:] = [ln.rsplit(",", 1)[0] for ln in lines[3:]]
    path = tmp_path / "nocol.csv"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(MeasurementError, match="'EC' is missing") as info:
        read_tables(path)
    assert info.value.lineno == 3
    lines = base_table_lines()
    lines[1] = "# units: length=inch angle=rad"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(MeasurementError, match="length unit 'inch'") as info:
        read_tables(path)
    assert info.value.lineno == 2


def test_squareness_errors_name_their_place(tmp_path):
    path = tmp_path / "sq.csv"
    path.write_text("# units: angle=urad\nname,value\nEC0Y,12\nEB0X,3\nEA0Z,1\n")
    with pytest.raises(MeasurementError, match="'EB0X' is not one of") as info:
        read_squareness(path)
    assert (info.value.lineno, info.value.col) == (4, 1)
    path.write_text("# units: angle=urad\nname,value\nEC0Y,12\nEA0Z,1\n")
    with pytest.raises(MeasurementError, match="EB0Z missing"):
        read_squareness(path)
    path.write_text("# units: angle=urad\nname,value\nEC0Y,12\nEB0Z,x\nEA0Z,1\n")
    with pytest.raises(MeasurementError, match="not a number") as info:
        read_squareness(path)
    assert (info.value.lineno, info.value.col) == (4, 6)


def test_axis_tables_refuse_bad_arrays():
    t, _ = synthetic_tables(0)
    pos = dict(t.position_mm)
    pos["X"] = pos["X"][::-1]
    with pytest.raises(CalibrationError, match="strictly increasing"):
        AxisTables(pos, t.errors)


def test_fit_tables_finds_companion_squareness(tmp_path):
    path, tables, sq = write_machine(tmp_path)
    res = fit_tables([str(path)])
    assert res.engine.squareness == sq
    assert res.info["squareness_source"] == str(squareness_path_for(path))
    squareness_path_for(path).unlink()
    res = fit_tables([str(path)])
    assert res.engine.squareness == Squareness()
    assert any("squareness taken as zero" in line for line in res.report)


def test_fit_tables_from_several_files(tmp_path):
    tables, sq = synthetic_tables(2)
    text = format_tables(tables).splitlines()
    head, body = text[:3], text[3:]
    a, b = tmp_path / "xy.csv", tmp_path / "z.csv"
    a.write_text("\n".join(head + [ln for ln in body if ln[0] in "XY"]) + "\n")
    b.write_text("\n".join(head + [ln for ln in body if ln[0] == "Z"]) + "\n")
    res = fit_tables([a, b])
    for ax in AXES:
        assert_allclose(res.engine.tables.errors[ax], tables.errors[ax])
    with pytest.raises(MeasurementError, match="axis X is given in two"):
        fit_tables([a, a])


def test_cli_fit_tables_round_trips_through_the_calibration(tmp_path):
    path, tables, sq = write_machine(tmp_path, seed=4, length_unit="um", angle_unit="arcsec")
    out = tmp_path / "cal.json"
    result = CliRunner().invoke(main, ["fit", str(path), "-o", str(out)])
    assert result.exit_code == 0, result.output
    data = json.loads(out.read_text())
    assert data["method"] == "parametric"
    assert data["model"]["order"] == "first"
    assert data["model"]["solver"] == "newton"
    cal = load_calibration(out)
    q = RNG.uniform(0, 315, (100, 3))
    r = np.array([10.0, 0, -80])
    assert_allclose(cal.engine.forward(q, r), ParametricEngine(tables, sq).forward(q, r), atol=1e-12)
    assert_allclose(cal.engine.volume_mm, [[0] * 3, [315] * 3])


def test_cli_fit_bad_table_exits_with_input_error(tmp_path):
    lines = base_table_lines()
    lines[5] = "X,30.000,0,0,0,0,nan?,0"
    path = tmp_path / "bad.csv"
    path.write_text("\n".join(lines) + "\n")
    out = tmp_path / "cal.json"
    result = CliRunner().invoke(main, ["fit", str(path), "-o", str(out)])
    assert result.exit_code == EXIT_INPUT
    assert f"{path}:6:" in result.output
    assert not out.exists()


def test_cli_fit_tables_stores_order_and_solver(tmp_path):
    path, _, _ = write_machine(tmp_path, seed=1)
    out = tmp_path / "cal.json"
    result = CliRunner().invoke(main, ["fit", str(path), "--order", "exact", "--solver", "astatic", "-o", str(out)])
    assert result.exit_code == 0, result.output
    engine = load_calibration(out).engine
    assert (engine.order, engine.solver) == ("exact", "astatic")
    assert engine.accept_residual_mm == 2.0
    assert engine.with_options(solver="newton").accept_residual_mm == 1e-6


def test_cli_fit_takes_a_squareness_file_given_among_the_files(tmp_path):
    path, tables, sq = write_machine(tmp_path, seed=5, name="axes.csv")
    other = tmp_path / "sq_elsewhere.csv"
    squareness_path_for(path).rename(other)
    out = tmp_path / "cal.json"
    result = CliRunner().invoke(main, ["fit", str(path), str(other), "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert load_calibration(out).engine.squareness == sq


def test_fit_tables_reports_options_that_do_not_apply(tmp_path):
    path, _, _ = write_machine(tmp_path, seed=6)
    res = fit_tables([path], knot_spacing=20.0, order="second")
    assert res.engine.order == "second"
    assert res.info["ignored_options"] == ["knot_spacing"]
    assert any("knot_spacing do not apply" in line for line in res.report)


def test_cli_order_on_a_static_fit_is_a_usage_error(tmp_path):
    from postproc.calibration.measurements import Measurements, format_measurements

    q = RNG.uniform(0, 300, (20, 3))
    src = tmp_path / "pts.csv"
    src.write_text(format_measurements(Measurements(q=q, m=q.copy(), r=np.zeros((20, 3)))))
    result = CliRunner().invoke(main, ["fit", str(src), "--order", "exact", "-o", str(tmp_path / "c.json")])
    assert result.exit_code == 2
    assert "parametric method only" in result.output
