import numpy as np
import pytest
from numpy.testing import assert_allclose

from postproc.errors import MeasurementError
from postproc.mirror.kdist import SensorData, fit_kdist, line_fit, read_sensor
from postproc.mirror.maps import format_map, load_map

RNG = np.random.default_rng(5)
R, D = 10.0, 2000.0
MM_PER_DEG = np.pi * D / 360.0  # arc length of one degree on the shell


def tilted_wall(segment_deg=5.0, noise=0.0005):
    """A piecewise-linear (continuous) back wall: slope k_s mm/deg on each 5-degree segment."""
    k_true = np.array([0.03, -0.01, 0.02, 0.0, -0.035, 0.012])
    edges = np.arange(len(k_true) + 1) * segment_deg
    b = np.arange(0.0, edges[-1] + 1e-9, 0.05)
    v0 = np.concatenate([[0.0], np.cumsum(k_true * segment_deg)])
    seg = np.clip(np.searchsorted(edges, b, side="right") - 1, 0, len(k_true) - 1)
    z_rows = np.array([100.0, 130.0, 160.0])
    bb = np.tile(b, len(z_rows))
    zz = np.repeat(z_rows, len(b))
    vv = np.tile(v0[seg] + k_true[seg] * (b - edges[seg]), len(z_rows)) + 1e-3 * zz
    vv = vv + RNG.normal(0, noise, vv.shape)
    return SensorData(bb, zz, vv), k_true, z_rows


def test_line_fit_is_formulas_3_and_4():
    b = RNG.uniform(0, 10, 50)
    v = 0.3 + 0.02 * b + RNG.normal(0, 0.01, 50)
    n = len(b)
    k_seed = (n * np.sum(b * v) - np.sum(b) * np.sum(v)) / (n * np.sum(b**2) - np.sum(b) ** 2)
    l_seed = (np.sum(v) - k_seed * np.sum(b)) / n
    assert_allclose(line_fit(b, v), (k_seed, l_seed), rtol=1e-10)


def test_kdist_recovers_the_tilt_of_each_segment():
    data, k_true, z_rows = tilted_wall()
    res = fit_kdist(data, cutter_radius_mm=R, diameter_mm=D, segment_deg=5.0)
    assert len(res.segments) == len(k_true) * len(z_rows)
    k = np.array([s.k_mm_per_deg for s in res.segments]).reshape(len(z_rows), -1)
    # slope standard error sigma / sqrt(sum (B - mean B)^2): 100 points over 5 deg with
    # 0.5 um noise give 3.5e-5 mm/deg; allow five of them (0.1 um of E)
    b_seg = np.arange(0.0, 5.0, 0.05)
    se = 0.0005 / np.sqrt(np.sum((b_seg - b_seg.mean()) ** 2))
    assert_allclose(k, np.tile(k_true, (len(z_rows), 1)), atol=5 * se)
    slope = np.array([s.slope for s in res.segments])
    assert_allclose(slope, k.ravel() / MM_PER_DEG, rtol=1e-12)
    e = np.array([s.e_mm for s in res.segments])
    assert_allclose(e, R * k.ravel() * 360.0 / (np.pi * D), rtol=1e-12)
    # map: regular (B, Z), value at each segment centre is that segment's E
    assert res.kmap.regular
    centres = np.array([0.5 * (s.b_lo + s.b_hi) for s in res.segments])
    zs = np.array([s.z_mm for s in res.segments])
    assert_allclose(res.kmap.values_at(np.column_stack([centres, zs])), e, atol=1e-15)
    # the end nodes hold the end segments' values over the whole measured range
    assert_allclose(res.kmap.values_at([[0.0, 100.0], [30.0, 160.0]]), [e[0], e[-1]], atol=1e-15)


def test_worked_example_figures():
    """0.035 mm/deg on a 2000 mm shell is a slope of 0.002005; a 10 mm cutter radius gives 20.05 um."""
    b = np.tile(np.linspace(0, 4, 41), 2)
    z = np.repeat([0.0, 10.0], 41)
    data = SensorData(b, z, 0.035 * b)
    res = fit_kdist(data, cutter_radius_mm=10.0, diameter_mm=2000.0, segment_deg=4.0)
    assert res.segments[0].slope == pytest.approx(0.035 * 360 / (np.pi * 2000), rel=1e-12)
    assert res.segments[0].e_mm == pytest.approx(0.0200535, abs=1e-7)
    over = fit_kdist(SensorData(b, z, -0.035 * b), cutter_radius_mm=10.0, diameter_mm=2000.0,
                     segment_deg=4.0, model="overcut")
    assert over.segments[0].e_mm == pytest.approx(-0.0200535, abs=1e-7)
    signed = fit_kdist(SensorData(b, z, -0.035 * b), cutter_radius_mm=10.0, diameter_mm=2000.0,
                       segment_deg=4.0)
    assert signed.segments[0].e_mm == pytest.approx(-0.0200535, abs=1e-7)


def test_sensor_file_units_and_map_file(tmp_path):
    data, k_true, _ = tilted_wall(noise=0.0)
    lines = ["# units: length=um", "B,Z,V"]
    lines += [f"{b:.4f},{z * 1e3:.3f},{v * 1e3:.6f}" for b, z, v in zip(data.b_deg, data.z_mm, data.v_mm, strict=True)]
    (tmp_path / "s.csv").write_text("\n".join(lines) + "\n")
    back = read_sensor(tmp_path / "s.csv")
    assert_allclose(back.v_mm, data.v_mm, atol=1e-9)
    res = fit_kdist(back, cutter_radius_mm=R, diameter_mm=D, segment_deg=5.0)
    assert res.segments[1].k_mm_per_deg == pytest.approx(k_true[1], abs=1e-7)
    (tmp_path / "k.csv").write_text(format_map(res.kmap))
    m = load_map(tmp_path / "k.csv")
    assert_allclose(m.values_mm, res.kmap.values_mm, atol=1e-7)


def test_helical_sweep_needs_z_bins():
    b = np.linspace(0, 20, 400)
    z = np.linspace(100, 101, 400)  # every point at its own height
    data = SensorData(b, z, 0.01 * b)
    with pytest.raises(MeasurementError, match="z-bin"):
        fit_kdist(data, cutter_radius_mm=R, diameter_mm=D, segment_deg=5.0)
    res = fit_kdist(data, cutter_radius_mm=R, diameter_mm=D, segment_deg=5.0, z_bin_mm=10.0)
    assert res.kmap.coords == ("B",)
    assert res.segments[0].k_mm_per_deg == pytest.approx(0.01)


def test_too_few_points_in_a_segment_names_the_line(tmp_path):
    (tmp_path / "s.csv").write_text("B,Z,V\n0,0,0\n0.5,0,0.1\n1,0,0.2\n10,0,0.3\n10.5,0,0.3\n")
    data = read_sensor(tmp_path / "s.csv")
    with pytest.raises(MeasurementError, match="too few") as exc:
        fit_kdist(data, cutter_radius_mm=R, diameter_mm=D, segment_deg=5.0)
    assert exc.value.lineno == 5
