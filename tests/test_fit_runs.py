"""fit from ISO 230-2 runs and from tables that give only the measured components."""

import json

import numpy as np
import pytest
from click.testing import CliRunner
from numpy.testing import assert_allclose

from postproc.calfile import load_calibration
from postproc.cli import main
from postproc.errors import MeasurementError
from postproc.metrology.tables_fit import fit_tables


def make_runs(path, rng, axis="X", targets=(0.0, 37.5, 81.0, 118.25, 160.0, 203.5, 240.0), n=5):
    """Runs with a known systematic error e(P) and reversal b(P) plus noise (um)."""
    t = np.asarray(targets)
    e = 12.0 * np.sin(t / 70.0) + 0.02 * t
    b = 5.0 + 0.02 * t
    lines = ["# postproc iso230 runs v1", "# units: length=mm error=um", "axis,target,run,direction,deviation"]
    for j in range(n):
        for d, order in ((1, range(len(t))), (-1, reversed(range(len(t))))):
            for i in order:
                x = e[i] + d * b[i] / 2 + rng.normal(0, 0.4)
                lines.append(f"{axis},{t[i]:.3f},{j + 1},{'+' if d > 0 else '-'},{x:.4f}")
    path.write_text("\n".join(lines) + "\n")
    return path, lines


def unidirectional_means(lines, axis="X"):
    """The mean deviation (mm) per (target, direction), straight from the file's rows."""
    acc = {}
    for ln in lines[3:]:
        a, p, _, d, x = ln.split(",")
        if a == axis:
            acc.setdefault((float(p), d), []).append(float(x) / 1000)
    return {k: float(np.mean(v)) for k, v in acc.items()}


def test_runs_calibration_reproduces_the_measured_means(tmp_path):
    rng = np.random.default_rng(5)
    path, lines = make_runs(tmp_path / "runs.csv", rng)
    out = tmp_path / "cal.json"
    res = CliRunner().invoke(main, ["fit", str(path), "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert "EY, EZ, EA, EB, EC not measured: taken as zero" in res.stderr
    assert "Y: not measured" in res.stderr
    cal = load_calibration(out)
    assert [e["name"] for e in cal.effects] == ["backlash:X"]
    # The model (positioning table + backlash profile) reproduces each target's measured
    # mean deviation in each approach direction: x + mean = F(x) along X.
    for (p, d), mean in unidirectional_means(lines).items():
        q = np.array([[p, 10.0, 20.0]])
        ctx = {"dirx": np.array([1.0 if d == "+" else -1.0]), "diry": np.zeros(1), "dirz": np.zeros(1)}
        got = cal.engine.forward(q, np.zeros((1, 3)), ctx)
        assert_allclose(got[0], [p + mean, 10.0, 20.0], atol=1e-9)


def test_runs_combine_with_straightness_tables(tmp_path):
    rng = np.random.default_rng(6)
    runs, lines = make_runs(tmp_path / "runs.csv", rng)
    tables = tmp_path / "straight.csv"
    tables.write_text("# postproc axis error tables v1\n# units: length=mm error=um\n"
                      "axis,position,EY,EZ\nX,0,0,0\nX,120,3.0,-1.0\nX,240,2.0,4.0\n"
                      "Y,0,1.0,0\nY,200,-2.0,0\n")
    res = fit_tables([tables], runs=[runs])
    t = res.engine.tables
    # X: EX from the runs (7 targets), EY/EZ from the tables (0, 120, 240): the union has 8.
    assert_allclose(t.position_mm["X"], [0, 37.5, 81, 118.25, 120, 160, 203.5, 240])
    means = unidirectional_means(lines)
    ex = [(means[(p, "+")] + means[(p, "-")]) / 2 for p in (0.0, 81.0, 240.0)]
    assert_allclose(np.interp([0.0, 81.0, 240.0], t.position_mm["X"], t.column("X", "EX")), ex, atol=1e-12)
    # EY at 81 mm lies on the table's straight line between 0 and 120 mm: 81/120 * 3 um.
    assert np.interp(81.0, t.position_mm["X"], t.column("X", "EY")) == pytest.approx(81 / 120 * 3e-3)
    assert_allclose(t.column("Y", "EX"), 0.0)
    assert "Y: EX, EA, EB, EC not measured: taken as zero" in res.report
    assert any("Z: not measured" in line for line in res.report)


def test_a_component_given_twice_is_refused(tmp_path):
    rng = np.random.default_rng(7)
    runs, _ = make_runs(tmp_path / "runs.csv", rng)
    tables = tmp_path / "x.csv"
    tables.write_text("# postproc axis error tables v1\naxis,position,EX\nX,0,0\nX,240,0.01\n")
    with pytest.raises(MeasurementError, match=r"axis X is given in two sources for EX"):
        fit_tables([tables], runs=[runs])


def test_runs_and_points_are_not_fitted_together(tmp_path):
    rng = np.random.default_rng(8)
    runs, _ = make_runs(tmp_path / "runs.csv", rng)
    res = CliRunner().invoke(main, ["fit", str(runs), "samples/walkthrough_points.csv", "-o", str(tmp_path / "c.json")])
    assert res.exit_code == 3
    assert "interferometer runs cannot be fitted together with point files" in res.stderr


def test_rotary_axis_runs_are_refused_by_fit(tmp_path):
    rng = np.random.default_rng(9)
    runs, _ = make_runs(tmp_path / "runs.csv", rng, axis="A")
    res = CliRunner().invoke(main, ["fit", str(runs), "-o", str(tmp_path / "c.json")])
    assert res.exit_code == 3
    assert "runs.csv:4:1: axis 'A'" in res.stderr


def test_backlash_profile_is_validated_on_load(tmp_path):
    rng = np.random.default_rng(10)
    runs, _ = make_runs(tmp_path / "runs.csv", rng)
    out = tmp_path / "cal.json"
    assert CliRunner().invoke(main, ["fit", str(runs), "-o", str(out)]).exit_code == 0
    data = json.loads(out.read_text())
    data["effects"][0]["config"]["shape"] = data["effects"][0]["config"]["shape"][:-1]
    out.write_text(json.dumps(data))
    res = CliRunner().invoke(main, ["correct", "samples/pocket.nc", "-c", str(out), "-o", str(tmp_path / "o.nc")])
    assert res.exit_code == 4
    assert "reversal profile needs position_mm" in res.stderr


def test_runs_with_a_squareness_file_among_files(tmp_path):
    rng = np.random.default_rng(11)
    runs, _ = make_runs(tmp_path / "runs.csv", rng)
    sq = tmp_path / "sq.csv"
    sq.write_text("# postproc squareness v1\n# units: angle=urad\nname,value\nEC0Y,20\nEB0Z,0\nEA0Z,0\n")
    out = tmp_path / "cal.json"
    res = CliRunner().invoke(main, ["fit", str(runs), str(sq), "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert load_calibration(out).engine.base.squareness.EC0Y == pytest.approx(20e-6)
