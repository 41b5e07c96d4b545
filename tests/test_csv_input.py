"""Forgiving, explicit CSV input: separators, decimal commas, BOM, units, implausible
positions, and a calibration that is really a CSV."""

import numpy as np
import pytest
from click.testing import CliRunner
from numpy.testing import assert_allclose

from postproc.calibration.measurements import read_measurements
from postproc.calibration.tables import format_tables, read_tables
from postproc.cli import main
from postproc.errors import MeasurementError
from postproc.metrology.runs import read_runs
from postproc.simulate.s500 import synthetic_tables


def tables_text(seed=3):
    tables, _ = synthetic_tables(seed, step_mm=45.0)
    return tables, format_tables(tables)


def localise(text: str, sep: str) -> str:
    """The same file as a spreadsheet in a decimal-comma locale writes it."""
    out = []
    for line in text.splitlines():
        if line.startswith("#"):
            out.append(line)
        else:
            out.append(sep.join(c.replace(".", ",") for c in line.split(",")))
    return "\n".join(out) + "\n"


@pytest.mark.parametrize("sep", [";", "\t"])
def test_tables_with_other_separators_and_decimal_commas(tmp_path, sep):
    tables, text = tables_text()
    path = tmp_path / "t.csv"
    path.write_text(localise(text, sep))
    got = read_tables(path)
    for ax in "XYZ":
        assert_allclose(got.position_mm[ax], tables.position_mm[ax])
        assert_allclose(got.errors[ax], tables.errors[ax], rtol=1e-12)


def test_semicolon_without_decimal_commas_and_errors_keep_their_column(tmp_path):
    path = tmp_path / "m.csv"
    path.write_text("# postproc measurements v1\nX;Y;Z;mx;my;mz\n0;0;0;0.001;0;0\n100;50;20;100.002;50;20\n"
                    "200;10;5;200,5x;10;5\n")
    with pytest.raises(MeasurementError) as info:
        read_measurements(path)
    # line 5, the 4th cell starts at column 10 when cells are split on ';' ("200;10;5;" is 9)
    assert (info.value.lineno, info.value.col) == (5, 10)
    assert "'200,5x' is not a number" in info.value.message


def test_bom_is_accepted_everywhere(tmp_path):
    tables, text = tables_text()
    path = tmp_path / "t.csv"
    path.write_bytes("\ufeff".encode() + text.encode())
    assert_allclose(read_tables(path).errors["X"], tables.errors["X"])
    runs = tmp_path / "r.csv"
    runs.write_bytes("\ufeff".encode() + b"axis,target,run,direction,deviation\n"
                     + b"".join(f"X,{p},{j},{d},0.001\n".encode() for p in (0, 50) for j in (1, 2) for d in "+-"))
    assert len(read_runs(runs)) == 8
    cal = tmp_path / "c.json"
    assert CliRunner().invoke(main, ["fit", str(path), "-o", str(cal)]).exit_code == 0
    cal.write_bytes("\ufeff".encode() + cal.read_bytes())
    res = CliRunner().invoke(main, ["export", str(cal), "-f", "siemens", "--step", "45", "-o", str(tmp_path / "e.spf"),
                                    *(f"--reference={a}=0" for a in "XYZ")])
    assert res.exit_code == 0, res.output


def test_error_unit_separate_from_length(tmp_path):
    path = tmp_path / "t.csv"
    path.write_text("# postproc axis error tables v1\n# units: length=mm error=um angle=urad\n"
                    "axis,position,EX,EY,EZ,EA,EB,EC\n"
                    + "".join(f"{a},{x},{x / 100},1,2,3,4,5\n" for a in "XYZ" for x in (0, 150, 300)))
    t = read_tables(path)
    assert_allclose(t.position_mm["X"], [0, 150, 300])  # positions stay in mm
    assert_allclose(t.column("X", "EX"), [0, 1.5e-3, 3e-3])  # errors in um
    assert_allclose(t.errors["Y"][0, 3:], [3e-6, 4e-6, 5e-6])


def test_length_um_for_positions_in_mm_is_an_error_at_the_units_line(tmp_path):
    # formats.md: 'length' applies to positions and errors alike unless 'error' is given,
    # so 0..300 read as um is a 0.3 mm axis: refused, naming the units line
    path = tmp_path / "t.csv"
    path.write_text("# postproc axis error tables v1\n# units: length=um angle=rad\n"
                    "axis,position,EX,EY,EZ,EA,EB,EC\n"
                    + "".join(f"{a},{x},1,0,0,0,0,0\n" for a in "XYZ" for x in (0, 150, 300)))
    with pytest.raises(MeasurementError) as info:
        read_tables(path)
    assert (info.value.lineno, info.value.col) == (2, 10)
    assert "axis X: positions span 0.3 mm" in info.value.message
    assert "length=mm error=um" in info.value.hint


def test_implausible_positions_in_measurements_and_runs(tmp_path):
    meas = tmp_path / "m.csv"
    meas.write_text("# units: length=um\nX,Y,Z,mx,my,mz\n0,0,0,0,0,0\n300,200,100,300,200,100\n")
    with pytest.raises(MeasurementError, match="the commanded positions .X, the widest axis. span 0.3 mm") as info:
        read_measurements(meas)
    assert info.value.lineno == 1
    runs = tmp_path / "r.csv"
    # targets written in um (a 300 mm axis) with no units line: read as a 300 m axis
    runs.write_text("axis,target,run,direction,deviation\n"
                    + "".join(f"X,{p},1,{d},1\n" for p in (0, 300000) for d in "+-"))
    with pytest.raises(MeasurementError, match="axis X: targets span 300000 mm") as info:
        read_runs(runs)
    assert info.value.lineno == 1  # no units line: the header is named
    assert "length=um" in info.value.hint


def test_missing_column_hint_speaks_of_case_only_when_case_differs(tmp_path):
    path = tmp_path / "m.csv"
    path.write_text("x,Y,Z,mx,my,mz\n0,0,0,0,0,0\n10,10,10,10,10,10\n")
    with pytest.raises(MeasurementError) as info:
        read_measurements(path)
    assert "write 'X', not 'x'" in info.value.hint
    path.write_text("Y,Z,mx,my,mz\n0,0,0,0,0\n10,10,10,10,10\n")
    with pytest.raises(MeasurementError) as info:
        read_measurements(path)
    assert "case" not in info.value.hint


def test_calibration_that_is_a_csv_points_to_fit(tmp_path):
    res = CliRunner().invoke(main, ["correct", "samples/pocket.nc", "-c", "samples/s500_interferometer_2mm.csv",
                                    "-o", str(tmp_path / "o.nc")])
    assert res.exit_code == 4
    assert "this is a CSV file of axis error tables, not a calibration" in res.stderr
    assert "postproc fit samples/s500_interferometer_2mm.csv -o CAL.json" in res.stderr


def test_runs_with_semicolons_and_decimal_commas(tmp_path):
    path = tmp_path / "r.csv"
    rows = [f"X;{p};{j};{d};{v}" for j, v in ((1, "1,5"), (2, "2,5")) for p in ("0,0", "120,5") for d in "+-"]
    path.write_text("# postproc iso230 runs v1\n# units: length=mm error=um\naxis;target;run;direction;deviation\n"
                    + "\n".join(rows) + "\n")
    runs = read_runs(path)
    assert_allclose(np.unique(runs.target_mm), [0.0, 120.5])
    assert_allclose(np.unique(runs.deviation_mm), [0.0015, 0.0025])
