import json

import numpy as np
import pytest
from click.testing import CliRunner

from postproc.calibration.measurements import Measurements, format_measurements
from postproc.cli import main
from postproc.engine.parametric import ParametricEngine
from postproc.engine.parametric_fit import fit
from postproc.errors import MeasurementError
from postproc.simulate.s500 import SEED_CONTROL_POINTS_MM, synthetic_tables

SIGMA = 0.002  # mm: a good tracker averaged over several shots
TOOL = np.array([0.0, 0.0, -100.0])
TOOLS = np.array([[0, 0, -100.0], [80, 0, -60], [0, 80, -60], [0, 0, -20]])
CONTROL = np.array(SEED_CONTROL_POINTS_MM, dtype=float)


@pytest.fixture(scope="module")
def truth():
    tables, sq = synthetic_tables(0)
    return ParametricEngine(tables, sq)


def measure(truth, n, tools, seed, sigma=SIGMA):
    rng = np.random.default_rng(seed)
    q = rng.uniform(0, 315, (n, 3))
    r = tools[rng.integers(0, len(tools), n)]
    m = truth.forward(q, r) + rng.normal(0, sigma, (n, 3))
    return Measurements(q=q, m=m, r=r)


def compensation_error(engine, truth, tool=TOOL):
    target = CONTROL + tool
    q = engine.inverse(target, tool).q
    return np.linalg.norm(truth.forward(q, tool) - target, axis=1)


def test_fit_recovers_the_machine_with_several_tool_vectors(truth):
    res = fit([measure(truth, 3000, TOOLS, seed=1)])
    assert isinstance(res.engine, ParametricEngine)
    assert res.rms_mm == pytest.approx(SIGMA * np.sqrt(3), rel=0.10)
    assert res.info["undetermined"] == []
    assert res.info["rank"] == res.info["n_params"]
    err = compensation_error(res.engine, truth)
    assert err.max() < 3 * SIGMA
    # Another tool, not one of the measured four, is compensated too: the angles are known.
    other = np.array([40.0, -40.0, -120.0])
    assert compensation_error(res.engine, truth, other).max() < 3 * SIGMA
    # ... and the uncorrected machine was a hundred times worse.
    before = np.linalg.norm(truth.forward(CONTROL, TOOL) - (CONTROL + TOOL), axis=1)
    assert before.min() > 30 * SIGMA


def test_single_tool_vector_reports_what_it_cannot_see(truth):
    res = fit([measure(truth, 2000, TOOLS[:1], seed=2)], knot_spacing=30.0)
    undetermined = set(res.info["undetermined"])
    # Every angular function acts through r only: with one r it is either invisible
    # (rotation about r: the EC ones for a vertical tool) or confounded with a linear error.
    assert {"EAX", "EBX", "ECX", "EAY", "EBY", "ECY", "EAZ", "EBZ", "ECZ", "eps0x", "eps0y", "eps0z"} <= undetermined
    assert not {"EXX", "EYY", "EZZ", "EC0Y", "EB0Z", "EA0Z"} & undetermined
    assert res.info["rank"] < res.info["n_params"]
    lines = {line.split()[0]: line for line in res.report if line.startswith("  ")}
    assert "not seen at all" in lines["ECX"]
    assert "indistinguishable at these tool vectors from EXX" in lines["EBX"]
    # They are set to zero, not invented ...
    for ax in "XYZ":
        assert np.abs(res.engine.tables.errors[ax][:, 3:]).max() == 0.0
    # ... and the fit still compensates exactly at the tool it was measured with.
    assert res.rms_mm == pytest.approx(SIGMA * np.sqrt(3), rel=0.10)
    assert compensation_error(res.engine, truth).max() < 3 * SIGMA


def test_files_fitted_together_see_more_than_each_alone(truth):
    a = measure(truth, 1200, TOOLS[:1], seed=3)
    b = measure(truth, 1200, TOOLS[1:2], seed=4)
    c = measure(truth, 1200, TOOLS[2:3], seed=5)
    alone = fit([a], knot_spacing=45.0)
    together = fit([a, b, c], knot_spacing=45.0)
    assert alone.info["undetermined"]
    assert together.info["undetermined"] == []
    assert together.info["n_points"] == 3600
    assert compensation_error(together.engine, truth, np.array([40.0, -40.0, -120.0])).max() < 3 * SIGMA


def test_unmoved_axis_is_refused(truth):
    meas = measure(truth, 200, TOOLS, seed=6)
    meas.q[:, 2] = 100.0
    with pytest.raises(MeasurementError, match="axis Z travels 0.000 mm"):
        fit([meas])


def test_cli_fit_parametric_with_knot_spacing(tmp_path, truth):
    path = tmp_path / "points.csv"
    path.write_text(format_measurements(measure(truth, 1500, TOOLS, seed=7)))
    out = tmp_path / "cal.json"
    result = CliRunner().invoke(main, ["fit", str(path), "--method", "parametric", "--knot-spacing", "40",
                                       "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert "numerical rank" in result.output
    data = json.loads(out.read_text())
    assert data["method"] == "parametric"
    assert data["fit"]["knot_spacing_mm"][0] == pytest.approx(40, rel=0.15)
    assert data["fit"]["undetermined"] == []
