import json

import numpy as np
import pytest
from numpy.testing import assert_allclose

from postproc.calfile import load_calibration, save_calibration
from postproc.calibration.measurements import (
    Measurements,
    format_measurements,
    read_measurements,
)
from postproc.engine.static import StaticEngine, fit
from postproc.errors import CalibrationError, MeasurementError

RNG = np.random.default_rng(7)
VOLUME = [[0, 0, 0], [315, 315, 315]]


def known_engine():
    G = np.eye(3) + np.array([[120e-6, -90e-6, 60e-6], [0, -80e-6, 150e-6], [0, 0, 40e-6]])
    return StaticEngine(G, [0.05, -0.03, 0.02], VOLUME)


def test_inverse_lands_on_target():
    eng = known_engine()
    p = RNG.uniform(0, 315, (200, 3))
    r = np.array([0, 0, -100.0])
    res = eng.inverse(p, r)
    assert_allclose(eng.forward(res.q, r), p, atol=1e-9)
    assert res.residual_mm.max() < 1e-9


def test_fit_recovers_from_two_points_per_axis(tmp_path):
    eng = known_engine()
    q = np.array([[0, 0, 0], [300, 0, 0], [0, 0, 0], [0, 300, 0], [0, 0, 0], [0, 0, 300.0]])
    r = np.zeros((6, 3))
    meas = Measurements(q=q, m=eng.forward(q, r), r=r)
    path = tmp_path / "six.csv"
    path.write_text(format_measurements(meas))
    res = fit([read_measurements(path)])
    assert_allclose(res.engine.G, eng.G, atol=1e-8)
    assert_allclose(res.engine.origin_mm, eng.origin_mm, atol=1e-6)


def test_fit_least_squares_with_noise():
    eng = known_engine()
    q = RNG.uniform(0, 315, (400, 3))
    r = np.tile([0, 0, -50.0], (400, 1))
    sigma = 0.002
    m = eng.forward(q, r) + RNG.normal(0, sigma, q.shape)
    res = fit([Measurements(q=q, m=m, r=r)])
    # 3D residual RMS of pure noise is sigma*sqrt(3) (less the 12 fitted parameters).
    assert res.rms_mm == pytest.approx(sigma * np.sqrt(3), rel=0.1)
    p = RNG.uniform(0, 315, (50, 3))
    err = np.linalg.norm(eng.forward(res.engine.inverse(p, r[:50]).q, r[:50]) - p, axis=1)
    assert err.max() < 3 * sigma


def test_fit_refuses_degenerate_points():
    q = np.array([[0, 0, 0], [100, 0, 0], [200, 0, 0], [0, 100, 0], [50, 50, 0]], float)
    with pytest.raises(MeasurementError, match="do not span three axes"):
        fit([Measurements(q=q, m=q, r=np.zeros_like(q))])


def test_calibration_round_trip_and_validation(tmp_path):
    eng = known_engine()
    path = tmp_path / "cal.anyname"
    save_calibration(path, eng, name="demo")
    cal = load_calibration(path)
    assert cal.name == "demo"
    assert cal.method == "static"
    assert len(cal.sha256) == 64
    assert_allclose(cal.engine.G, eng.G)
    data = json.loads(path.read_text())
    data["units"]["length"] = "um"
    path.write_text(json.dumps(data))
    with pytest.raises(CalibrationError, match="units"):
        load_calibration(path)
    data["units"]["length"] = "mm"
    data["model"]["G"] = [[1, 0], [0, 1]]
    path.write_text(json.dumps(data))
    with pytest.raises(CalibrationError, match="static model"):
        load_calibration(path)
    path.write_text("{not json")
    with pytest.raises(CalibrationError, match=r"not valid JSON") as info:
        load_calibration(path)
    assert str(info.value).startswith(f"{path}:1:2:")


def test_measurement_reader_units_and_errors(tmp_path):
    text = (
        "# postproc measurements v1\n# units: length=um\n# operator: A. N. Other\n"
        "X,Y,Z,mx,my,mz,dirx,diry,dirz,t,temp,load,probe_id\n"
        "1000,2000,3000,1001,2002,2999,1,-1,0,0,20.1,0,7\n"
    )
    path = tmp_path / "m.csv"
    path.write_text(text)
    m = read_measurements(path)
    assert_allclose(m.q, [[1, 2, 3]])
    assert_allclose(m.m, [[1.001, 2.002, 2.999]])
    assert_allclose(m.r, [[0, 0, 0]])
    assert m.meta["operator"] == "A. N. Other"
    assert set(m.context) == {"t", "temp", "load", "probe_id"}
    assert_allclose(m.direction, [[1, -1, 0]])
    path.write_text(text.replace("1001,", "1OO1,"))
    with pytest.raises(MeasurementError) as info:
        read_measurements(path)
    assert str(info.value).startswith(f"{path}:5:")
    path.write_text(text.replace("length=um", "length=furlong"))
    with pytest.raises(MeasurementError, match="length unit"):
        read_measurements(path)


def test_saved_files_have_ordinary_permissions(tmp_path):
    import os

    path = tmp_path / "cal.json"
    save_calibration(path, known_engine())
    umask = os.umask(0)
    os.umask(umask)
    assert path.stat().st_mode & 0o777 == 0o666 & ~umask
    path.chmod(0o640)
    save_calibration(path, known_engine())
    assert path.stat().st_mode & 0o777 == 0o640
