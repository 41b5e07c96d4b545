"""predict init -c with a calibration fitted from ISO 230-2 runs (backlash needs dirx)."""

import json

import numpy as np
from click.testing import CliRunner
from metrology_machines import write_runs, x_machine
from numpy.testing import assert_allclose

from postproc.calfile import load_calibration
from postproc.cli import main
from postproc.predict.operation import load_chain


def test_init_maps_the_direction_context_of_a_runs_calibration(tmp_path):
    runs, _ = write_runs(tmp_path / "runs.csv", x_machine())
    cal = tmp_path / "cal.json"
    assert CliRunner().invoke(main, ["fit", str(runs), "-o", str(cal)]).exit_code == 0
    out = tmp_path / "chain.json"
    for layout in ("vertical-mill", "horizontal-boring"):
        res = CliRunner().invoke(main, ["predict", "init", "--layout", layout, "-c", str(cal), "-o", str(out)])
        assert res.exit_code == 0, res.output
        assert "dirx" in res.output
    res = CliRunner().invoke(main, ["predict", "init", "--layout", "vertical-mill", "-c", str(cal), "-o", str(out)])
    data = json.loads(out.read_text())
    assert data["defaults"]["dirx"] == 1.0
    chain = load_chain(out)
    engine = load_calibration(cal).engine
    q = np.array([162.2, 10.0, -20.0])
    for d in (1.0, -1.0):
        ctx = {"dirx": np.array([d]), "diry": np.zeros(1), "dirz": np.zeros(1)}
        want = engine.forward(q[None], np.array([[0, 0, -100.0]]), ctx)[0]
        got = chain.transform([0, 0, -100], {"X": q[0], "Y": q[1], "Z": q[2], "dirx": d})
        assert_allclose(got, want, atol=1e-10)
