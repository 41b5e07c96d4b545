"""Chains a user writes from docs/predict.md: known errors without random variables, a
spindle element in a bore, degenerate sections, and the --check verdict."""

import json

import numpy as np
import pytest
from click.testing import CliRunner
from numpy.testing import assert_allclose

from postproc.cli import main
from postproc.errors import EXIT_INPUT, EXIT_NOT_HELD
from postproc.predict import bore
from postproc.predict.operation import load_operation

# The chain of the issue: a fixed translation to the spindle nose, an error element
# with v = 0.03 mm, w = -0.02 mm, beta = 0.2 mrad, then the spindle (about x).
NOSE = [500.0, 270.0, 560.0]
ERROR = {"v": 0.03, "w": -0.02, "beta": 0.2e-3}


def user_chain(error=None, spindle=None, random=None, extra=()):
    chain = {
        "format": "postproc chain", "version": 1, "name": "three modules",
        "modules": [
            {"name": "to the spindle nose", "elements": [{"fixed": {"translation": NOSE}}]},
            {"name": "head", "elements": [{"error": dict(ERROR, **(error or {}))}, *extra]},
            {"name": "spindle", "elements": [{"spindle": spindle or {"axis": "x", "rpm": 0}}]},
        ],
    }
    if random is not None:
        chain["random"] = random
    return chain


def write_bore(tmp_path, chain, tolerance=(0.05, 0.05), **fields):
    (tmp_path / "machine.json").write_text(json.dumps(chain))
    op = {"format": "postproc operation", "kind": "bore", "machine": "machine.json", "diameter_mm": 50,
          "overhang_mm": 100, "axis": "x", "nominal_centre_mm": NOSE[1:], "tolerance_mm": list(tolerance),
          "monte_carlo": {"n": 200, "seed": 3}, **fields}
    path = tmp_path / "bore.operation.json"
    path.write_text(json.dumps(op))
    return path


def run(*args):
    return CliRunner().invoke(main, ["predict", *map(str, args)])


@pytest.mark.parametrize("order", ["small", "exact"])
def test_known_errors_give_the_first_order_centre_error(tmp_path, order):
    # Hand derivation. Tool points in the spindle frame: r = (100, 25 cos S, 25 sin S)
    # (overhang 100 mm along x, radius 25 mm); the spindle turns about x, so in the
    # error element's frame they are the same circle. The error element maps r to
    # r + rho + eps x r with rho = (u, v, w) = (0, 0.03, -0.02), eps = (0, beta, 0):
    #   eps x r = (beta r_z - 0 r_y, 0 r_x - 0 r_z, 0 r_y - beta r_x) = (beta 25 sin S, 0, -beta 100)
    # so every point moves by +0.03 in Y and by -0.02 - 0.2e-3 * 100 = -0.04 in Z: the
    # circle keeps its radius and its centre moves by Y +30 um, Z -40 um. The exact
    # rotation differs by -100 (sin beta - beta) and cos beta - 1 terms, below 1e-8 mm.
    path = write_bore(tmp_path, user_chain(error={"order": order}))
    res = run("bore", path, "--json")
    assert res.exit_code == 0, res.output
    out = json.loads(res.output)
    assert_allclose(out["mid_field"]["error_mm"], [0.030, -0.040], atol=0.5e-3)
    assert_allclose(out["mid_field"]["error_mm"], [0.030, -0.040], atol=1e-8)
    assert_allclose(out["mid_field"]["diameter_mm"], 50.0, atol=1e-6)


def test_a_chain_without_random_variables_gives_one_prediction_and_no_monte_carlo(tmp_path):
    path = write_bore(tmp_path, user_chain())
    out = json.loads(run("bore", path, "--json").output)
    assert out["deterministic"] is True
    assert out["monte_carlo"] is None
    worst = out["worst_case"]
    assert_allclose(worst["min_mm"], [0.03, -0.04], atol=1e-9)
    assert worst["min_mm"] == worst["max_mm"] == out["mid_field"]["error_mm"]
    assert worst["within"] is True
    text = run("bore", path).output
    assert "single prediction" in text
    assert "Monte Carlo" not in text
    assert "P(centre" not in text


@pytest.mark.parametrize("random", [
    {"dummy": {"uniform": [0, 0.01]}},          # a variable nothing uses (was an IndexError)
    {"dummy": {"normal": [0, 0.01]}},
    {"w0": {"uniform": [-0.02, -0.02]}},        # used, but a field of no width
])
def test_random_variables_that_cannot_move_the_centre_keep_the_single_prediction(tmp_path, random):
    error = {"w": "w0"} if "w0" in random else None
    path = write_bore(tmp_path, user_chain(error=error, random=random))
    res = run("bore", path, "--json")
    assert res.exit_code == 0, res.output
    out = json.loads(res.output)
    assert out["deterministic"] is True
    assert_allclose(out["mid_field"]["error_mm"], [0.03, -0.04], atol=1e-9)


def test_sections_of_a_chain_that_ignores_its_variables_come_one_per_draw(tmp_path):
    op = load_operation(write_bore(tmp_path, user_chain(random={"d": {"uniform": [0, 1]}})))
    pts = bore.section_points(op, {"d": np.linspace(0, 1, 5)})
    assert pts.shape == (5, 9, 3)
    assert_allclose(pts[0], pts[4])


def test_monte_carlo_with_a_variable_only_some_elements_use(tmp_path):
    # w = -0.02 + c, c uniform in +-0.01: the Z error is -0.04 + c, Y stays +0.03.
    chain = user_chain(error={"w": {"sum": [-0.02, "c"]}}, random={"c": {"uniform": [-0.01, 0.01]}})
    out = json.loads(run("bore", write_bore(tmp_path, chain), "-n", 2000, "--seed", 5, "--json").output)
    assert out["deterministic"] is False
    assert_allclose(out["worst_case"]["min_mm"], [0.03, -0.05], atol=1e-9)
    assert_allclose(out["worst_case"]["max_mm"], [0.03, -0.03], atol=1e-9)
    mc = out["monte_carlo"]
    assert_allclose(mc["mean_mm"][1], -0.04, atol=3 * 0.02 / np.sqrt(12 * 2000))
    assert_allclose(mc["std_mm"][0], 0.0, atol=1e-12)


@pytest.mark.parametrize("spindle", [
    {"axis": "x", "rpm": 0},
    {"axis": "x", "rpm": 1200, "var": "t", "direction": "ccw"},
    {"axis": "x", "rpm": "n", "phase": 0.3},
])
def test_a_spindle_element_is_turned_by_the_section_angle(tmp_path, spindle):
    # At rpm 0 the spindle's own angle is constant: the eight points coincided (a
    # singular circle fit). In a bore the spindle turns by S whatever rpm and time say.
    path = write_bore(tmp_path, user_chain(spindle=spindle), context={"t": 0.25, "n": 0})
    out = json.loads(run("bore", path, "--json").output)
    assert_allclose(out["mid_field"]["error_mm"], [0.03, -0.04], atol=1e-9)
    assert_allclose(out["mid_field"]["diameter_mm"], 50.0, atol=1e-9)
    assert out["mid_field"]["roundness_mm"] < 1e-9


def test_a_tool_nothing_turns_is_refused_with_the_reason(tmp_path):
    chain = user_chain()
    chain["modules"][2]["elements"] = [{"rotary": {"axis": "x", "var": "C"}}]
    path = write_bore(tmp_path, chain, context={"C": 0})
    res = run("bore", path)
    assert res.exit_code == EXIT_INPUT
    assert str(path) in res.output
    assert "section points coincide" in res.output
    assert "'S'" in res.output
    assert "internal error" not in res.output


def test_a_tool_turned_about_another_axis_is_refused_with_the_reason(tmp_path):
    # The spindle turns about z while the bore's axis is x: the eight tips lie on a
    # line in the Y-Z plane (Z constant), which has no circle.
    path = write_bore(tmp_path, user_chain(spindle={"axis": "z", "rpm": 0}))
    res = run("bore", path)
    assert res.exit_code == EXIT_INPUT
    assert "lie on no circle of the tool's diameter 50 mm" in res.output
    assert str(path) in res.output


def test_a_zero_diameter_is_refused_by_name(tmp_path):
    res = run("bore", write_bore(tmp_path, user_chain(), diameter_mm=0))
    assert res.exit_code == EXIT_INPUT
    assert '"diameter_mm" must be positive' in res.output


def test_check_exit_status_is_the_verdict(tmp_path):
    held = write_bore(tmp_path, user_chain(), tolerance=(0.05, 0.05))
    res = run("bore", held, "--check")
    assert res.exit_code == 0, res.output
    assert "check: held" in res.output
    missed = write_bore(tmp_path, user_chain(), tolerance=(0.05, 0.035))  # Z is -0.040
    res = run("bore", missed, "--check")
    assert res.exit_code == EXIT_NOT_HELD
    assert "check: NOT held" in res.output
    res = run("bore", missed, "--check", "--json")
    assert res.exit_code == EXIT_NOT_HELD
    verdict = json.loads(res.output)["verdict"]
    assert verdict == {"held": False, "basis": "single prediction", "centre_within": False,
                       "diameter_within": None, "diameter_range_mm": pytest.approx([50.0, 50.0])}
    assert run("bore", missed).exit_code == 0  # without --check the report is all


def test_check_counts_the_diameter_limits(tmp_path):
    path = write_bore(tmp_path, user_chain(), diameter_limits_mm=[50.01, 50.03])  # the tool cuts 50.000
    res = run("bore", path, "--check", "--json")
    assert res.exit_code == EXIT_NOT_HELD
    verdict = json.loads(res.output)["verdict"]
    assert verdict["centre_within"] is True
    assert verdict["diameter_within"] is False


def test_check_on_the_seed_bore_uses_the_worst_case():
    from pathlib import Path

    sample = Path(__file__).parents[1] / "samples" / "predict" / "bore_50H7.operation.json"
    res = run("bore", sample, "-n", 200, "--check", "--json")
    assert res.exit_code == EXIT_NOT_HELD  # Z reaches 0.110 mm at a corner of the fields
    verdict = json.loads(res.output)["verdict"]
    assert verdict["basis"] == "worst case"
    assert verdict["held"] is False
    res = run("tolerance", sample, "--worst-case", "--check")
    assert res.exit_code == EXIT_NOT_HELD
    assert "check: NOT held (worst case)" in res.output


def test_tolerance_of_a_point_on_a_deterministic_chain(tmp_path):
    chain = user_chain()
    (tmp_path / "machine.json").write_text(json.dumps(chain))
    op = {"format": "postproc operation", "kind": "point", "machine": "machine.json", "context": {"t": 0},
          "tool_point_mm": [100, 0, 0], "nominal_mm": [600, 270, 560], "tolerance_mm": [0.01, 0.05, 0.05]}
    path = tmp_path / "point.json"
    path.write_text(json.dumps(op))
    res = run("tolerance", path, "--json", "--check")
    assert res.exit_code == 0, res.output
    out = json.loads(res.output)
    # r = (100, 0, 0): eps x r = (0, 0, -beta 100), so the point moves by (0, 0.03, -0.04).
    assert_allclose(out["worst_case"]["max_mm"], [0.0, 0.03, -0.04], atol=1e-9)
    assert out["deterministic"] is True
    assert "monte_carlo" not in out
    assert out["verdict"]["held"] is True


def test_a_tool_turned_exactly_across_the_bore_axis_is_refused_as_a_line(tmp_path):
    # No error element: turning about z, the tips (100 cos S - 25 sin S, ...) keep Z.
    chain = user_chain(error={"beta": 0}, spindle={"axis": "z", "rpm": 0})
    res = run("bore", write_bore(tmp_path, chain))
    assert res.exit_code == EXIT_INPUT
    assert "lie on a line in the Y-Z plane" in res.output


def test_tips_spaced_unevenly_on_the_circle_still_give_its_centre(tmp_path):
    # A phase of S rad on top of the S deg turning puts the eight tips at uneven
    # angles (-S deg + S rad), all on the same circle: its centre is still Y +30, Z -40 um.
    path = write_bore(tmp_path, user_chain(spindle={"axis": "x", "rpm": 0, "phase": "S"}))
    res = run("bore", path, "--json")
    assert res.exit_code == 0, res.output
    out = json.loads(res.output)
    assert_allclose(out["mid_field"]["error_mm"], [0.03, -0.04], atol=1e-9)
    assert_allclose(out["mid_field"]["diameter_mm"], 50.0, atol=1e-9)
