"""Chains of modules: element kinds, the description file, and the 21-parameter model as a chain."""

import json
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose

from postproc.engine.parametric import ParametricEngine
from postproc.errors import PostprocError
from postproc.predict import frames
from postproc.predict.chain import chain_from_dict
from postproc.predict.operation import load_chain
from postproc.predict.parametric_chain import chain_from_tables, tool_points
from postproc.predict.values import evaluate
from postproc.simulate.s500 import synthetic_tables

RNG = np.random.default_rng(11)
SAMPLES = Path(__file__).parents[1] / "samples" / "predict"


def chain(*modules, random=None):
    return chain_from_dict(
        {"format": "postproc chain", "random": random or {}, "modules": [{"name": f"m{i}", "elements": list(m)}
                                                                     for i, m in enumerate(modules)]}
    )


def test_three_axis_chain_moves_the_tool_by_the_axis_positions():
    ch = chain([{"linear": {"axis": "x", "var": "X"}}], [{"linear": {"axis": "y", "var": "Y"}}],
               [{"linear": {"axis": "z", "var": "Z"}}])
    q = RNG.uniform(-100, 100, (20, 3))
    r = np.array([0, 0, -100.0])
    assert_allclose(tool_points(ch, q, r), q + r, atol=1e-12)


def test_seed002_module_order_error_motion_constant():
    # M = M_D M_V M_C: the constant offset is carried by the rotary motion, the error acts last
    ch = chain([{"error": {"u": 0.01, "gamma": 1e-4}}, {"rotary": {"axis": "z", "var": "C", "unit": "deg"}},
                {"fixed": {"translation": [50, 0, 0]}}])
    p = ch.transform([0, 0, 0], {"C": 90.0})
    # rotary 90 deg takes (50, 0, 0) to (0, 50, 0); the error then adds u and gamma x p
    assert_allclose(p, [0.01 - 1e-4 * 50, 50, 0], atol=1e-12)


def test_spindle_turns_clockwise_at_the_given_speed():
    ch = chain([{"spindle": {"axis": "z", "rpm": 600, "var": "t"}}])  # 10 rev/s
    t = np.array([0.0, 0.025, 0.05])  # quarter and half revolution
    p = ch.transform([1.0, 0, 0], {"t": t})
    assert_allclose(p, [[1, 0, 0], [0, -1, 0], [-1, 0, 0]], atol=1e-12)


def test_values_tables_polynomials_sines_sums():
    env = {"X": np.array([0.0, 50.0, 200.0]), "t": 0.25, "load": 2.0}
    table = {"var": "X", "table": {"positions": [0, 100], "values": [0.0, 0.002]}}
    assert_allclose(evaluate(table, env), [0, 0.001, 0.002])  # clamped beyond the end
    assert evaluate({"var": "load", "poly": [1.0, 2.0, 3.0]}, env) == pytest.approx(1 + 4 + 12)
    sine = {"var": "t", "sine": {"amplitude": 2.0, "omega": 2 * np.pi, "phase": 0.0}}
    assert evaluate(sine, env) == pytest.approx(2.0)
    assert evaluate({"sum": [1.5, "-load", {"scale": 3, "of": "t"}]}, env) == pytest.approx(1.5 - 2 + 0.75)
    assert evaluate({"product": ["load", sine, 0.5]}, env) == pytest.approx(2.0)


def test_missing_variable_names_the_element():
    ch = chain([{"linear": {"axis": "x", "var": "X"}}])
    with pytest.raises(PostprocError, match=r"modules\[0\].*variable 'X' is not set"):
        ch.transform([0, 0, 0], {})


@pytest.mark.parametrize(
    ("element", "message"),
    [
        ({"wobble": {}}, "unknown element kind"),
        ({"error": {"zeta": 1}}, "unknown error parameters"),
        ({"fixed": {"translation": [1, 2]}}, "list of 3"),
        ({"plane": {"nodes": [[0, 0], [1, 0], [0, 1]], "z": [0, 0]}}, "one per node"),
        ({"linear": {"axis": "x", "var": {"var": "X", "table": {"positions": [1, 0], "values": [0, 0]}}}},
         "increase strictly"),
    ],
)
def test_bad_elements_are_refused_with_their_place(element, message):
    with pytest.raises(PostprocError, match=message) as err:
        chain([element])
    assert "modules[0]" in str(err.value)


def test_bad_distribution_is_refused():
    with pytest.raises(PostprocError, match="uniform"):
        chain([{"fixed": {"translation": [0, 0, 0]}}], random={"g": {"uniform": [1, 0]}})


def test_points_element_is_the_frame_on_the_triangle():
    ch = chain([{"points": {"i": [0, "a", 0], "j": [400, 0, "b"], "k": [0, 400, 0]}}])
    env = {"a": 0.01, "b": 0.02}
    expected = frames.pose_from_points([0, 0.01, 0], [400, 0, 0.02], [0, 400, 0])
    assert_allclose(ch.matrix(env), expected)


def test_chain_file_round_trip(tmp_path):
    ch = load_chain(SAMPLES / "mc12.machine.json")
    path = tmp_path / "c.json"
    path.write_text(json.dumps(ch.to_dict()))
    again = load_chain(path)
    env = {name: 0.01 for name in ch.random} | {"X": 10.0, "S": 30.0, "A1": 0.002, "A2": 0.0, "A3": 0.0, "A4": 0.0}
    assert_allclose(again.transform([100, 25, 0], env), ch.transform([100, 25, 0], env))
    assert again.random == ch.random
    assert {"X", "S", "g1", "cz_front", "A4"} <= ch.variables()


def test_chain_file_syntax_error_names_line(tmp_path):
    path = tmp_path / "bad.json"
    path.write_text('{"format": "postproc chain",\n "modules": [}\n')
    with pytest.raises(PostprocError) as err:
        load_chain(path)
    assert str(err.value).startswith(f"{path}:2:")


# -- the 21-parameter model as a chain -------------------------------------------------


@pytest.fixture(scope="module")
def machine():
    tables, squareness = synthetic_tables(3)
    q = np.random.default_rng(5).uniform(0, 315, (400, 3))
    return tables, squareness, q


R_TOOL = np.array([30.0, -20.0, -100.0])


def test_chain_equals_parametric_engine_exact_order(machine):
    tables, sq, q = machine
    engine = ParametricEngine(tables, sq, order="exact", interpolation="linear")
    p = tool_points(chain_from_tables(tables, sq, order="exact"), q, R_TOOL)
    assert_allclose(p, engine.forward(q, R_TOOL), rtol=0, atol=1e-9)


def test_chain_with_small_angle_matrix_equals_first_order_engine(machine):
    tables, sq, q = machine
    engine = ParametricEngine(tables, sq, order="first", interpolation="linear")
    p = tool_points(chain_from_tables(tables, sq, order="small"), q, R_TOOL)
    assert_allclose(p, engine.forward(q, R_TOOL), rtol=0, atol=1e-9)


def test_chain_equals_the_formats_formula(machine):
    # p = q + rho + R(eps) r written out from formats.md, independent of the engine
    tables, sq, q = machine
    total = np.zeros((len(q), 6))
    for i, ax in enumerate("XYZ"):
        for j in range(6):
            total[:, j] += np.interp(q[:, i], tables.position_mm[ax], tables.errors[ax][:, j])
    rho = total[:, :3] + np.column_stack([-sq.EC0Y * q[:, 1] + sq.EB0Z * q[:, 2], -sq.EA0Z * q[:, 2], 0 * q[:, 0]])
    rot = frames.rodrigues(total[:, 3], total[:, 4], total[:, 5])
    expected = q + rho + rot @ R_TOOL
    p = tool_points(chain_from_tables(tables, sq, order="exact"), q, R_TOOL)
    assert_allclose(p, expected, rtol=0, atol=1e-9)


def test_orders_and_per_axis_matrices_differ_at_second_order(machine):
    tables, sq, q = machine
    engine = ParametricEngine(tables, sq, order="exact", interpolation="linear")
    _, eps = engine.errors_at(q)
    # bound on products of angles times the tool length: |eps|^2 |r|
    bound = np.sum(eps**2, axis=1) * np.linalg.norm(R_TOOL)
    exact = engine.forward(q, R_TOOL)
    for kwargs in ({"order": "small"}, {"order": "exact", "angular": "per-axis"}):
        d = np.linalg.norm(tool_points(chain_from_tables(tables, sq, **kwargs), q, R_TOOL) - exact, axis=1)
        assert np.all(d <= bound)
        assert d.max() > 1e-3 * bound.max()  # really a second-order difference, not zero


def test_collinear_frame_points_are_reported_at_evaluation_with_their_place():
    ch = chain([{"points": {"i": [0, 0, 0], "j": ["L", 0, 0], "k": [{"scale": 2, "of": "L"}, 0, 0]}}])
    with pytest.raises(PostprocError, match=r"modules\[0\].*collinear"):
        ch.matrix({"L": 100.0})


def test_defaults_fill_variables_that_are_not_given():
    data = {"format": "postproc chain", "defaults": {"X": 5.0},
            "modules": [{"name": "x", "elements": [{"linear": {"axis": "x", "var": "X"}}]}]}
    ch = chain_from_dict(data)
    assert_allclose(ch.transform([0, 0, 0]), [5, 0, 0])
    assert_allclose(ch.transform([0, 0, 0], {"X": 7.0}), [7, 0, 0])
    assert chain_from_dict(ch.to_dict()).defaults == {"X": 5.0}
    with pytest.raises(PostprocError, match="defaults"):
        chain_from_dict({**data, "defaults": {"X": "five"}})
