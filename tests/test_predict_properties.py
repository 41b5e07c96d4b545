"""Property tests: every chain docs/predict.md allows evaluates, or is refused with an
error that names its file (and, for an element, the element) and the reason.

Chains are generated over every element kind and value form (numbers, variables,
tables, polynomials, sines, sums, products, scales, random variables), with the
degenerate cases among them: coincident or collinear frame points, a zero direction,
a tool turned about another axis or not at all, rotary axes about the tool axis,
fields of zero width. They run through the analyses the commands print (bore,
tolerance) and, fewer of them, through the commands themselves (bore, tolerance,
point), in-process; an internal error (exit 1) fails the test.

The suite runs some 600 chains. ``POSTPROC_PROPERTY_SCALE=10`` runs ten times as
many (``python -m pytest tests/test_predict_properties.py``), a longer search.
"""

import json
import os
import tempfile
from functools import cache
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from postproc.cli import main
from postproc.errors import EXIT_CALIBRATION, EXIT_INPUT, EXIT_NOT_HELD, EXIT_SAFETY, PostprocError
from postproc.predict.analysis import analyse_feature, predict_bore
from postproc.predict.operation import operation_from_dict

STATIC = str(Path(__file__).parents[1] / "calibrations" / "s500_static.json")
AXES = ("x", "y", "z")
AXIS_VARS = ("X", "Y", "Z", "t")
RANDOM_VARS = ("a", "b", "c")
#: Exit codes a refused chain or operation may give; 1 (internal error) is never one.
REFUSED = (EXIT_INPUT, EXIT_CALIBRATION, EXIT_SAFETY)
NAME = "generated.operation.json"

#: Multiplies every test's number of examples (see the module docstring).
SCALE = float(os.environ.get("POSTPROC_PROPERTY_SCALE", "1"))


def examples(n: int) -> settings:
    return settings(max_examples=max(1, int(n * SCALE)), deadline=None, derandomize=True,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])


# Every strategy is built once (functools.cache): building and validating nested
# strategies costs far more than drawing from them.


# -- values -----------------------------------------------------------------------------
@cache
def numbers(scale: float):
    """Floats within +-scale, and small integers (JSON ints) that stay within it."""
    k = min(3, int(scale))
    return st.one_of(st.floats(-scale, scale, allow_nan=False, allow_infinity=False), st.integers(-k, k))


@cache
def variable_names():
    return st.sampled_from(AXIS_VARS + RANDOM_VARS + ("-a", "-X", "S"))


@cache
def tables(scale):
    positions = st.lists(st.floats(-400, 400, allow_nan=False), min_size=1, max_size=5, unique=True).map(sorted)
    return st.builds(
        lambda var, pos, vals: {"var": var, "table": {"positions": pos, "values": vals[:len(pos)]}},
        st.sampled_from(AXIS_VARS + RANDOM_VARS),
        positions,
        st.lists(numbers(scale), min_size=5, max_size=5),
    )


@cache
def functions(scale):
    poly = st.builds(lambda v, c: {"var": v, "poly": c}, st.sampled_from(AXIS_VARS + RANDOM_VARS),
                     st.lists(numbers(scale), min_size=1, max_size=4))
    sine = st.builds(lambda v, a, w, f: {"var": v, "sine": {"amplitude": a, "omega": w, "phase": f}},
                     st.sampled_from(AXIS_VARS + RANDOM_VARS), numbers(scale), numbers(1.0), numbers(3.2))
    return st.one_of(tables(scale), poly, sine)


@cache
def values(scale: float = 100.0):
    """Any value form of docs/predict.md, nested through sum, product and scale."""
    leaves = st.one_of(numbers(scale), variable_names(), functions(scale))
    return st.recursive(
        leaves,
        lambda inner: st.one_of(
            st.lists(inner, min_size=1, max_size=3).map(lambda v: {"sum": v}),
            st.lists(inner, min_size=1, max_size=2).map(lambda v: {"product": v}),
            st.builds(lambda k, v: {"scale": k, "of": v}, numbers(10.0), inner),
        ),
        max_leaves=3,
    )


# -- elements ---------------------------------------------------------------------------
def rotation_matrix(angles, shift):
    m = np.eye(4)
    for i, ang in enumerate(angles):
        c, s = np.cos(ang), np.sin(ang)
        r = np.eye(4)
        j, k = (i + 1) % 3, (i + 2) % 3
        r[j, j] = r[k, k] = c
        r[j, k], r[k, j] = -s, s
        m = m @ r
    m[:3, 3] = shift
    return m.tolist()


@cache
def triples(elements):
    return st.lists(elements, min_size=3, max_size=3)


@cache
def fixed():
    return st.one_of(
        triples(numbers(500)).map(lambda t: {"translation": t}),
        st.builds(lambda a, ang: {"rotation": {"axis": a, "angle": ang}}, st.sampled_from(AXES), numbers(3.2)),
        st.builds(lambda ang, t: {"matrix": rotation_matrix(ang, t)}, triples(numbers(3.2)), triples(numbers(500))),
        st.builds(lambda p, inv: {"small_angle": p, **({"inverse": True} if inv else {})},
                  st.lists(numbers(0.01), min_size=6, max_size=6), st.booleans()),
    ).map(lambda b: {"fixed": b})


@cache
def linear(scale):
    where = st.one_of(st.sampled_from(AXES).map(lambda a: {"axis": a}),
                      triples(numbers(2.0)).map(lambda d: {"direction": d}))  # zero vectors included
    return st.builds(lambda w, v, k: {"linear": {**w, "var": v, **k}}, where, values(scale),
                     st.one_of(st.just({}), numbers(2.0).map(lambda k: {"scale": k})))


@cache
def rotary(scale):
    return st.builds(lambda a, v, u: {"rotary": {"axis": a, "var": v, "unit": u}},
                     st.sampled_from(AXES), values(scale), st.sampled_from(["deg", "rad"]))


@cache
def spindle(axis=None):
    axes = st.sampled_from(AXES) if axis is None else st.just(axis)
    return st.builds(
        lambda a, rpm, var, ph, d: {"spindle": {"axis": a, "rpm": rpm, "var": var, "phase": ph, "direction": d}},
        axes, values(3000), st.sampled_from(["t", "a"]), values(3.0), st.sampled_from(["cw", "ccw"]))


@cache
def error(scale):
    params = st.dictionaries(st.sampled_from(["u", "v", "w", "alpha", "beta", "gamma"]), values(scale), max_size=6)
    return st.builds(lambda p, o: {"error": {**p, "order": o}}, params, st.sampled_from(["small", "exact"]))


@cache
def points(scale):
    return st.builds(lambda i, j, k: {"points": {"i": i, "j": j, "k": k}},
                     triples(values(scale)), triples(values(scale)), triples(values(scale)))


@cache
def plane(scale):
    nodes = st.lists(st.tuples(numbers(500), numbers(500)).map(list), min_size=3, max_size=5)
    return nodes.flatmap(lambda n: st.builds(
        lambda z: {"plane": {"nodes": n, "z": z}}, st.lists(values(scale), min_size=len(n), max_size=len(n))))


@cache
def calibration():
    at = st.one_of(st.just(["X", "Y", "Z"]), triples(values(300)))
    return at.map(lambda a: {"calibration": {"file": STATIC, "at": a}})


@cache
def any_element():
    return st.one_of(fixed(), linear(500), rotary(400), spindle(), error(1.0), points(500), plane(1.0),
                     calibration())


@cache
def bounded_values(scale: float):
    """Values that stay within about ``scale`` over the axes' travel and the random fields:
    numbers, the small random variables, tables and sines of any variable, their sums,
    products and scales (what an error parameter of a real machine is)."""
    sine = st.builds(lambda v, a, w, f: {"var": v, "sine": {"amplitude": a, "omega": w, "phase": f}},
                     st.sampled_from(AXIS_VARS + RANDOM_VARS), numbers(scale), numbers(1.0), numbers(3.2))
    leaves = st.one_of(st.floats(-scale, scale), st.sampled_from(RANDOM_VARS + ("-a",)), tables(scale), sine)
    return st.recursive(
        leaves,
        lambda inner: st.one_of(
            st.lists(inner, min_size=1, max_size=3).map(lambda v: {"sum": v}),
            st.lists(inner, min_size=1, max_size=2).map(lambda v: {"product": v}),
            st.builds(lambda k, v: {"scale": k, "of": v}, st.floats(-1, 1), inner),
        ),
        max_leaves=4,
    )


@cache
def machine_element():
    """Elements of the size a real machine has: errors of micrometres to a tenth of a
    millimetre and microradians to a milliradian, on axes of any travel."""
    small_fixed = st.one_of(triples(numbers(500)).map(lambda t: {"fixed": {"translation": t}}),
                            st.lists(st.floats(-1e-3, 1e-3), min_size=6, max_size=6).map(
                                lambda p: {"fixed": {"small_angle": p}}))
    errors = st.builds(lambda p, o: {"error": {**p, "order": o}},
                       st.dictionaries(st.sampled_from(["u", "v", "w", "alpha", "beta", "gamma"]),
                                       bounded_values(1e-3), max_size=6), st.sampled_from(["small", "exact"]))
    travel = st.builds(lambda a, v: {"linear": {"axis": a, "var": v}}, st.sampled_from(AXES),
                       st.one_of(st.sampled_from(("X", "Y", "Z", "-X")), bounded_values(300)))
    return st.one_of(small_fixed, travel, errors, st.just({"calibration": {"file": STATIC}}),
                     st.builds(lambda a, v: {"rotary": {"axis": a, "var": v}}, st.sampled_from(AXES),
                               bounded_values(0.05)))


@cache
def commented(element):
    return st.builds(lambda e, c: {**e, "comment": "a note"} if c else e, element, st.booleans())


@cache
def distributions(scale: float = 0.1):
    uniform = st.builds(lambda lo, w: {"uniform": [lo, lo + w]}, st.floats(-scale, scale), st.floats(0, scale))
    normal = st.builds(lambda m, s: {"normal": [m, s]}, st.floats(-scale, scale), st.floats(0, scale / 3))
    fixed_value = st.floats(-scale, scale).map(lambda v: {"uniform": [v, v]})
    return st.one_of(uniform, normal, fixed_value)


@cache
def chains(element, last=None, random_scale: float = 3.0):
    """Chains of 1-3 modules of 1-3 elements; ``random_scale`` < 1: a, b, c all random."""
    if random_scale < 1:
        random = st.fixed_dictionaries({v: distributions(random_scale) for v in RANDOM_VARS})
    else:
        random = st.dictionaries(st.sampled_from(RANDOM_VARS), distributions(random_scale), max_size=3)
    module = st.lists(commented(element), min_size=1, max_size=2).map(lambda els: {"name": "m", "elements": els})
    mods = st.lists(module, min_size=1, max_size=3)
    if last is not None:
        mods = st.builds(lambda m, e: [*m, {"name": "tool", "elements": [e]}], mods, last)
    return st.builds(
        lambda m, r: {"format": "postproc chain", "version": 1, "name": "generated", "random": r, "modules": m},
        mods, random)


@cache
def turning(axis):
    """What turns a bore's tool: a spindle element or a rotary element by S, or nothing."""
    return st.one_of(spindle(axis), st.just({"rotary": {"axis": axis, "var": "S"}}),
                     st.just({"fixed": {"translation": [0, 0, 0]}}))


# -- operations -------------------------------------------------------------------------
CONTEXT = st.fixed_dictionaries({v: st.floats(0, 315) for v in AXIS_VARS})


@cache
def bores(axis):
    return st.fixed_dictionaries({
        "format": st.just("postproc operation"), "kind": st.just("bore"), "machine": st.just("chain.json"),
        "diameter_mm": st.floats(0.5, 200), "overhang_mm": numbers(300), "axis": st.just(axis),
        "nominal_centre_mm": triples(numbers(500)).map(lambda t: t[:2]),
        "tolerance_mm": st.lists(st.floats(0.001, 1), min_size=2, max_size=2),
        "context": CONTEXT, "monte_carlo": st.just({"n": 20, "seed": 1}),
    })


POINTS = st.fixed_dictionaries({
    "format": st.just("postproc operation"), "kind": st.just("point"), "machine": st.just("chain.json"),
    "tool_point_mm": triples(numbers(200)), "nominal_mm": triples(numbers(500)),
    "tolerance_mm": st.lists(st.floats(0.001, 1), min_size=3, max_size=3),
    "context": CONTEXT, "monte_carlo": st.just({"n": 20, "seed": 1}),
})


@pytest.fixture(scope="module")
def workdir():
    with tempfile.TemporaryDirectory() as d:
        yield Path(d)


def build(chain: dict, op: dict):
    """The operation with its chain embedded, as load_operation gives it for a file NAME."""
    op = operation_from_dict({**op, "machine": chain}, Path("."))
    op.path = op.chain.path = NAME
    return op


def refused_by_name(exc: PostprocError) -> None:
    """An evaluation error names the file; a load error names its place in the operation."""
    text = str(exc)
    assert text.startswith(NAME) or text.startswith("operation"), text
    if "modules[" in text:
        assert ".elements[" in text or "module" in text, text


@examples(200)
@given(data=st.data(), axis=st.sampled_from(AXES))
def test_any_chain_in_a_bore_evaluates_or_is_refused_by_name(data, axis):
    chain = data.draw(chains(any_element(), last=turning(axis)))
    try:
        report = predict_bore(build(chain, data.draw(bores(axis))))
    except PostprocError as exc:
        refused_by_name(exc)
        return
    out = report.to_dict()
    assert np.all(np.isfinite(out["worst_case"]["max_abs_mm"]))
    assert np.isfinite(out["mid_field"]["diameter_mm"])


@examples(200)
@given(chain=chains(any_element()), op=POINTS)
def test_any_chain_for_a_point_evaluates_or_is_refused_by_name(chain, op):
    try:
        report = analyse_feature(build(chain, op))
    except PostprocError as exc:
        refused_by_name(exc)
        return
    assert np.all(np.isfinite(report.worst.max_abs_mm))
    assert report.verdict["held"] is bool(np.all(report.worst.max_abs_mm <= np.asarray(op["tolerance_mm"])))


@examples(150)
@given(data=st.data(), axis=st.sampled_from(AXES))
def test_machine_sized_chains_in_a_bore_always_evaluate(data, axis):
    # Errors of a real machine's size, the tool turned about the bore axis (a rotary
    # about the tool axis among them): the bore must evaluate, whatever the values' forms.
    last = st.one_of(spindle(axis), st.just({"rotary": {"axis": axis, "var": "S"}}))
    chain = data.draw(chains(machine_element(), last=last, random_scale=0.05))
    op = data.draw(bores(axis))
    op["overhang_mm"] = data.draw(st.floats(-300, 300))
    out = predict_bore(build(chain, op)).to_dict()
    if not chain["random"]:
        assert out["deterministic"] is True
    if out["deterministic"]:
        assert out["monte_carlo"] is None
        assert out["worst_case"]["min_mm"] == out["worst_case"]["max_mm"] == out["mid_field"]["error_mm"]
    else:
        assert out["monte_carlo"]["n"] == 20
    tol = np.asarray(op["tolerance_mm"])
    assert out["verdict"]["centre_within"] is bool(np.all(np.asarray(out["worst_case"]["max_abs_mm"]) <= tol))


@examples(40)
@given(data=st.data(), axis=st.sampled_from(AXES), command=st.sampled_from(["bore", "tolerance"]))
def test_the_commands_name_the_file_of_a_refused_chain(workdir, data, axis, command):
    chain = data.draw(chains(any_element(), last=turning(axis)))
    op = data.draw(bores(axis))
    (workdir / "chain.json").write_text(json.dumps(chain))
    (workdir / "op.json").write_text(json.dumps(op))
    args = ["predict", command, str(workdir / "op.json"), "--json", "--check"]
    res = CliRunner().invoke(main, [*args, "--worst-case"] if command == "tolerance" else args)
    assert res.exit_code in (0, EXIT_NOT_HELD, *REFUSED), res.output
    if res.exit_code in (0, EXIT_NOT_HELD):
        assert json.loads(res.output)["verdict"]["held"] is (res.exit_code == 0)
    else:
        assert res.output.startswith(f"postproc: error: {workdir}"), res.output  # the chain or the operation


@examples(40)
@given(chain=chains(any_element()), x=st.floats(-500, 500), a=st.floats(-1, 1))
def test_any_chain_gives_a_point_or_is_refused_by_name(workdir, chain, x, a):
    path = workdir / "point_chain.json"
    path.write_text(json.dumps(chain))
    res = CliRunner().invoke(main, ["predict", "point", str(path), "--set", f"X={x}", "--set", "Y=10",
                                    "--set", "Z=20", "--set", "t=0.5", "--set", f"S={a}", "--tool", "1,2,-100"])
    assert res.exit_code in (0, *REFUSED), res.output
    if res.exit_code:
        assert str(path) in res.output, res.output
    else:
        assert "nan" not in res.output
