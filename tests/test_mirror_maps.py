import numpy as np
import pytest
from numpy.testing import assert_allclose

from postproc.errors import MeasurementError, OutOfVolumeError, PostprocError
from postproc.mirror.maps import CorrectionMap, format_map, load_map, parse_direction

RNG = np.random.default_rng(11)


def write_map(path, header, rows, meta=("units: length=mm", "apply: Y")):
    lines = ["# postproc correction map v1", *[f"# {m}" for m in meta], header]
    lines += [",".join(f"{v:.15g}" for v in row) for row in rows]
    path.write_text("\n".join(lines) + "\n")
    return path


def bilinear(b, z):
    return 0.01 + 2e-3 * b - 5e-4 * z + 3e-5 * b * z


def test_bilinear_map_is_exact_on_bilinear_data(tmp_path):
    bs = np.array([0.0, 1.5, 4.0, 7.0])  # uneven steps are still a regular grid
    zs = np.array([100.0, 120.0, 160.0])
    rows = [(b, z, bilinear(b, z)) for z in zs for b in bs]
    m = load_map(write_map(tmp_path / "m.csv", "B,Z,value", rows))
    assert m.regular
    b = RNG.uniform(0, 7, 500)
    z = RNG.uniform(100, 160, 500)
    p = np.column_stack([np.zeros(500), np.full(500, -5.0), z])
    d = m.delta(p, {"B": b})
    assert_allclose(d[:, 1], bilinear(b, z), atol=1e-12)
    assert np.all(d[:, [0, 2]] == 0)


def test_units_um_and_sign(tmp_path):
    rows = [(x, y, 10.0 * x + y) for x in (0.0, 10.0) for y in (0.0, 10.0)]  # um
    m = load_map(write_map(tmp_path / "m.csv", "X,Y,value", rows,
                           ("units: length=um", "apply: Z", "sign: -1")))
    # X,Y columns are in um too: the map spans 0..0.01 mm
    d = m.delta(np.array([[0.005, 0.005, 0.0]]), {})
    assert_allclose(d, [[0.0, 0.0, -(55.0e-3)]], atol=1e-12)


def test_scattered_map_is_exact_on_linear_data_and_refuses_outside_hull(tmp_path):
    pts = RNG.uniform([0, 0], [10, 50], (40, 2))
    pts = np.vstack([pts, [[0, 0], [10, 0], [0, 50], [10, 50]]])
    rows = [(b, z, 0.02 - 1e-3 * b + 2e-4 * z) for b, z in pts]
    m = load_map(write_map(tmp_path / "s.csv", "B,Z,value", rows))
    assert not m.regular
    b, z = RNG.uniform(0, 10, 200), RNG.uniform(0, 50, 200)
    got = m.values_at(np.column_stack([b, z]))
    assert_allclose(got, 0.02 - 1e-3 * b + 2e-4 * z, atol=1e-12)
    tri = [(0.0, 0.0, 0.0), (10.0, 0.0, 0.0), (0.0, 50.0, 0.0), (2.0, 5.0, 0.0)]
    t = load_map(write_map(tmp_path / "t.csv", "B,Z,value", tri))
    assert_allclose(t.values_at([[1.0, 1.0]]), [0.0])
    with pytest.raises(OutOfVolumeError, match="hull"):
        t.values_at([[9.0, 45.0]])  # inside the bounding box, outside the triangle


def test_out_of_map_is_refused_with_the_program_line(tmp_path):
    rows = [(b, z, 0.0) for z in (0.0, 10.0) for b in (0.0, 5.0)]
    m = load_map(write_map(tmp_path / "m.csv", "B,Z,value", rows))
    p = np.array([[0, 0, 5.0], [0, 0, 5.0], [0, 0, 12.0]])
    with pytest.raises(OutOfVolumeError) as exc:
        m.delta(p, {"B": np.array([1.0, 2.0, 3.0]), "lineno": np.array([7, 8, 9])})
    assert exc.value.lineno == 9
    assert "Z=12.0000" in str(exc.value)
    assert "clamp" in exc.value.hint


def test_clamp_holds_the_edge_value(tmp_path):
    rows = [(b, z, b + 0.1 * z) for z in (0.0, 10.0) for b in (0.0, 5.0)]
    path = write_map(tmp_path / "m.csv", "B,Z,value", rows)
    m = load_map(path, outside="clamp")
    assert_allclose(m.values_at([[7.0, 12.0], [-1.0, 5.0]]), [5.0 + 1.0, 0.5])
    clamped_in_file = load_map(write_map(tmp_path / "c.csv", "B,Z,value", rows,
                                         ("units: length=mm", "apply: Y", "outside: clamp")))
    assert_allclose(clamped_in_file.values_at([[7.0, 12.0]]), [6.0])


def test_rotary_full_circle_wraps(tmp_path):
    bs = np.arange(0.0, 360.0, 90.0)
    rows = [(b, z, np.cos(np.radians(b)) + z) for z in (0.0, 1.0) for b in bs]
    m = load_map(write_map(tmp_path / "m.csv", "B,Z,value", rows))
    # between 270 and 360(=0): halfway value of cos(270)=0 and cos(0)=1
    assert_allclose(m.values_at([[315.0, 0.0], [-45.0, 1.0], [405.0, 0.0]]), [0.5, 1.5, 0.5])


def test_one_coordinate_map(tmp_path):
    m = load_map(write_map(tmp_path / "m.csv", "B,value", [(0.0, 0.0), (10.0, 0.02)]))
    d = m.delta(np.zeros((2, 3)), {"B": np.array([2.5, 10.0])})
    assert_allclose(d[:, 1], [0.005, 0.02])


def test_missing_rotary_axis_is_an_error(tmp_path):
    m = load_map(write_map(tmp_path / "m.csv", "B,value", [(0.0, 0.0), (10.0, 0.02)]))
    with pytest.raises(PostprocError, match="rotary axis B"):
        m.delta(np.zeros((1, 3)), {})


@pytest.mark.parametrize(
    ("meta", "header", "match"),
    [
        (("units: length=mm",), "B,Z,value", "apply"),
        (("units: length=mm", "apply: Q"), "B,Z,value", "apply"),
        (("units: length=mm", "apply: Y", "sign: 2"), "B,Z,value", "sign"),
        (("units: length=in", "apply: Y"), "B,Z,value", "length unit"),
        (("units: length=mm", "apply: Y"), "B,Q,value", "coordinates"),
        (("units: length=mm", "apply: Y"), "B,Z,corr", "value"),
    ],
)
def test_bad_headers_name_the_problem(tmp_path, meta, header, match):
    rows = [(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (1.0, 1.0, 0.0)]
    with pytest.raises(MeasurementError, match=match):
        load_map(write_map(tmp_path / "m.csv", header, rows, meta))


def test_missing_magic_line_and_duplicate_node(tmp_path):
    p = tmp_path / "m.csv"
    p.write_text("# units: length=mm\n# apply: Y\nB,Z,value\n0,0,0\n1,0,0\n")
    with pytest.raises(MeasurementError, match="not a correction map"):
        load_map(p)
    rows = [(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (1.0, 0.0, 0.5), (0.0, 1.0, 0.0)]
    with pytest.raises(MeasurementError, match="given twice") as exc:
        load_map(write_map(tmp_path / "d.csv", "B,Z,value", rows))
    assert exc.value.lineno == 7


def test_collinear_scattered_nodes_are_an_error(tmp_path):
    rows = [(0.0, 0.0, 0.0), (1.0, 1.0, 0.0), (2.0, 2.0, 0.0)]
    with pytest.raises(MeasurementError, match="on a line"):
        load_map(write_map(tmp_path / "m.csv", "B,Z,value", rows))


def test_format_round_trip(tmp_path):
    nodes = np.array([[b, z] for z in (0.0, 5.0) for b in (0.0, 1.0, 2.0)])
    m = CorrectionMap("k", ("B", "Z"), nodes, RNG.normal(0, 0.01, 6), apply_axis="Y", sign=-1.0)
    for units in ("mm", "um"):
        path = tmp_path / f"k_{units}.csv"
        path.write_text(format_map(m, units=units, comments=["free text"]))
        back = load_map(path)
        assert back.sign == -1.0
        assert back.apply_axis == "Y"
        assert_allclose(back.values_mm, m.values_mm, atol=1e-7)
        assert_allclose(back.nodes, nodes)


def test_parse_direction():
    assert parse_direction("+Y") == ("Y", 1.0)
    assert parse_direction("-z") == ("Z", -1.0)
    with pytest.raises(ValueError, match="expected"):
        parse_direction("B")


def test_map_through_the_pipeline_adds_to_the_geometric_inverse(tmp_path):
    """Geometric inverse first, then the map value added along its axis, in commanded space."""
    from postproc.engine.static import StaticEngine
    from postproc.gcode.path import program_path
    from postproc.gcode.pipeline import CorrectOptions, correct_text

    xs, ys = np.array([0.0, 50.0, 100.0]), np.array([0.0, 40.0, 80.0])
    rows = [(x, y, bilinear_xy(x, y)) for y in ys for x in xs]
    m = load_map(write_map(tmp_path / "flat.csv", "X,Y,value", rows, ("units: length=mm", "apply: Z")))
    g = np.eye(3) + np.array([[50e-6, 0, 0], [20e-6, -30e-6, 0], [0, 0, 10e-6]])
    eng = StaticEngine(g, [0.01, -0.02, 0.005], [[-10, -10, -50], [200, 200, 50]])
    prog = "G21 G90\nG0 X0 Y0 Z5\nG1 Z-1 F300\nG1 X100 Y0\nG1 X100 Y80\nG1 X10\nG1 Y35\nG0 Z5\nM30\n"
    text, report = correct_text(prog, eng, None, CorrectOptions(added=[m]))
    nominal = program_path(prog, max_step_mm=1e9)
    got = program_path(text, max_step_mm=1e9)
    ends = ~nominal.rapid
    p = nominal.points_mm[ends]
    expect = eng.inverse(p).q
    expect[:, 2] += bilinear_xy(p[:, 0], p[:, 1])
    assert_allclose(got.points_mm[ends], expect, atol=0.6e-4)  # 4 decimals written
    assert report.max_correction_mm > 0.01


def bilinear_xy(x, y):
    return 1e-3 * (5 + 0.1 * x - 0.05 * y + 1e-3 * x * y)


def test_grid_lines_shifted_by_round_off_are_still_one_grid():
    b0 = 27.1
    b = np.array([27.35, 27.6, 27.85]) - b0  # 0.25 +- 1e-15 from row to row
    nodes = np.array([[bb + row * 1e-13, z] for row, z in enumerate((0.0, 5.0)) for bb in b])
    vals = bilinear(nodes[:, 0], nodes[:, 1])
    m = CorrectionMap("k", ("B", "Z"), nodes, vals)
    assert m.regular
    assert_allclose(m.values_at(nodes), vals, atol=1e-12)
