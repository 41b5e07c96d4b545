"""What the pipeline takes from each engine: its solver's accepted residual, linear
extrapolation, the context its effects need, and where a map's refusal points."""

import re
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from postproc.calfile import load_calibration, save_calibration
from postproc.cli import main
from postproc.effects import compose, get_effect
from postproc.engine.base import Engine, InverseResult, check_points, check_tool_vectors
from postproc.engine.identity import IdentityEngine
from postproc.engine.static import StaticEngine
from postproc.errors import EXIT_SAFETY, MissingSetupError, OutOfVolumeError, SolverError
from postproc.gcode import emit
from postproc.gcode.path import Setup, program_path
from postproc.gcode.pipeline import SOLVER_ACCEPT_MM, CorrectOptions, Corrector, correct_text
from postproc.metrology.tables_fit import fit_tables

ROOT = Path(__file__).parents[1]
TABLES = ROOT / "calibrations" / "s500_tables.csv"
PARAMETRIC = ROOT / "calibrations" / "s500_parametric.json"
VOLUME = [[0.0, 0.0, 0.0], [315.0, 315.0, 315.0]]
# Rapid moves only: their end points are corrected, never split.
RAPIDS = "G21 G90\nG0 X10 Y10 Z10\nG0 X200 Y150 Z80\nG0 X300 Y20 Z200\nG0 X40 Y290 Z30\nM30\n"


def header_text(text: str) -> str:
    return "".join(emit.split_header(text)[0])


def invoke(args):
    return CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)


def ends(text: str) -> np.ndarray:
    """Gauge positions reached at the end of each move of a corrected program."""
    pp = program_path(text, Setup(offsets={"G54": (0, 0, 0)}))
    return pp.points_mm - pp.tool_mm


class NoisySolver(Engine):
    """Identity model whose inverse is off by a fixed residual (a coarse solver)."""

    method = "noisy"
    affine = True

    def __init__(self, residual_mm, accept=None):
        super().__init__(VOLUME)
        self.res = residual_mm
        if accept is not None:
            self.accept_residual_mm = accept

    def forward(self, q, r=None, context=None):
        q = check_points(q)
        return q + check_tool_vectors(r, len(q))

    def inverse(self, p, r=None, context=None):
        p = check_points(p)
        q = p - check_tool_vectors(r, len(p))
        q[:, 0] += self.res
        return InverseResult(q, np.full(len(p), self.res), np.ones(len(p), dtype=int))

    def model_to_dict(self):
        return {}

    @classmethod
    def model_from_dict(cls, model, volume_mm):
        return cls(0.0)


# -- the solver's own acceptance bound ------------------------------------------------------
def test_residual_bound_comes_from_the_engine():
    with pytest.raises(SolverError, match=r"residual 0.005 mm"):
        correct_text(RAPIDS, NoisySolver(0.005), Setup())
    out, rep = correct_text(RAPIDS, NoisySolver(0.005, accept=0.01), Setup())
    assert rep.max_residual_mm == pytest.approx(0.005)
    assert rep.accept_residual_mm == pytest.approx(0.01)
    assert "(POSTPROC NOISY SOLVER ACCEPTING RESIDUALS UP TO 0.01 MM)" in header_text(out)
    # the engine's bound never lowers the pipeline's float-noise allowance
    _, rep = correct_text(RAPIDS, NoisySolver(0.5 * SOLVER_ACCEPT_MM, accept=0.0), Setup())
    assert rep.accept_residual_mm == SOLVER_ACCEPT_MM
    with pytest.raises(SolverError):
        correct_text(RAPIDS, NoisySolver(0.02, accept=0.01), Setup())


@pytest.fixture(scope="module")
def astatic_cal(tmp_path_factory):
    fit = fit_tables([TABLES], solver="astatic")
    path = tmp_path_factory.mktemp("astatic") / "astatic.json"
    save_calibration(path, fit.engine, name="s500-astatic")
    return path


def test_astatic_calibration_corrects_a_program(astatic_cal, tmp_path):
    prog = tmp_path / "rapids.nc"
    prog.write_text(RAPIDS)
    out = tmp_path / "out.nc"
    r = invoke(["correct", prog, "-c", astatic_cal, "-o", out])
    assert r.exit_code == 0, r.output
    header = header_text(out.read_text())
    assert "(POSTPROC PARAMETRIC SOLVER ASTATIC ACCEPTING RESIDUALS UP TO 2 MM)" in header
    m = re.search(r"solver astatic: largest inverse residual ([\d.e+-]+) um", r.output)
    assert m, r.output
    resid_mm = float(m.group(1)) / 1000
    assert 0 < resid_mm < 2.0
    # the emitted commands reach the nominal targets through the model, within the
    # solver's reported residual (plus the 4-decimal rounding of the words)
    eng = load_calibration(astatic_cal).engine
    nominal = ends(RAPIDS)
    q = ends(out.read_text())
    reached = eng.forward(q, np.zeros_like(q))
    err = np.linalg.norm(reached - nominal, axis=1)
    assert err.max() <= resid_mm + 1e-4 * np.sqrt(3) * 2
    # and they differ from the nominal by the model's correction (hundreds of um)
    assert np.abs(q - nominal).max() > 0.05


def test_astatic_scatter_beyond_the_tolerance_is_explained(astatic_cal, tmp_path):
    prog = tmp_path / "feed.nc"
    prog.write_text("G21 G90\nG0 X10 Y10 Z10\nG1 X200 Y150 Z80 F500\nM30\n")
    r = invoke(["correct", prog, "-c", astatic_cal, "-o", tmp_path / "o.nc"])
    assert r.exit_code == EXIT_SAFETY
    assert f"{prog}:3:" in r.output
    assert "raise --tolerance above that residual" in r.output
    assert not (tmp_path / "o.nc").exists()
    r = invoke(["correct", prog, "-c", astatic_cal, "-o", tmp_path / "o.nc", "--tolerance", "0.05"])
    assert r.exit_code == 0, r.output


# -- linear extrapolation ----------------------------------------------------------------------
OUTSIDE = "G21 G90\nG0 X10 Y10 Z10\nG0 X335 Y10 Z10\nG0 X10 Y10 Z10\nM30\n"


def test_linear_extrapolation_switches_the_parametric_engine(tmp_path):
    eng = load_calibration(PARAMETRIC).engine
    assert eng.extrapolate == "clamp"
    results = {}
    for mode in ("clamp", "linear"):
        out, rep = correct_text(OUTSIDE, eng, Setup(), CorrectOptions(extrapolate=mode))
        assert rep.extrapolated_points == 1
        results[mode] = ends(out)[1]
    target = np.array([[335.0, 10.0, 10.0]])
    zero = np.zeros((1, 3))
    linear = eng.with_options(extrapolate="linear")
    expect_linear = target + linear.correction(target, zero).q
    expect_clamp = target + eng.correction(np.array([[315.0, 10.0, 10.0]]), zero).q
    np.testing.assert_allclose(results["linear"], expect_linear[0], atol=6e-5)
    np.testing.assert_allclose(results["clamp"], expect_clamp[0], atol=6e-5)
    # 20 mm beyond the tables the end slopes make a visible difference
    assert np.abs(results["linear"] - results["clamp"]).max() > 0.005
    # the calibration's own engine is left as it was
    assert eng.extrapolate == "clamp"


def test_linear_extrapolation_reaches_the_base_of_a_composed_engine():
    base = load_calibration(PARAMETRIC).engine
    eff = get_effect("thermal:temp", config={"reference_C": 20.0},
                     params={"kx_mm_per_C": 0.001, "ky_mm_per_C": 0.0, "kz_mm_per_C": 0.0})
    eng = compose(base, [eff.to_dict()])
    c = Corrector(eng, Setup(context={"temp": 22.0}), CorrectOptions(extrapolate="linear"))
    assert c.engine.base.extrapolate == "linear"
    assert [e.name for e in c.engine.effects] == ["thermal:temp"]
    out, _ = correct_text(OUTSIDE, eng, Setup(context={"temp": 22.0}), CorrectOptions(extrapolate="linear"))
    alone, _ = correct_text(OUTSIDE, base, Setup(), CorrectOptions(extrapolate="linear"))
    # the effect adds +2 um of X growth on top of the base correction: commands 2 um less
    np.testing.assert_allclose(ends(out)[1] - ends(alone)[1], [-0.002, 0.0, 0.0], atol=1.2e-4)


def test_linear_extrapolation_of_an_affine_engine_is_the_model_itself():
    eng = StaticEngine(np.eye(3) + 1e-4 * np.array([[0, 1, 0], [0, 0, 0], [0, 0, 0]]), [0.01, 0, 0], VOLUME)
    out, _ = correct_text(OUTSIDE, eng, Setup(), CorrectOptions(extrapolate="linear"))
    target = np.array([[335.0, 10.0, 10.0]])
    expect = target + eng.correction(target, np.zeros((1, 3))).q
    np.testing.assert_allclose(ends(out)[1], expect[0], atol=6e-5)


# -- context an effect needs --------------------------------------------------------------------
def test_missing_context_is_refused_before_any_line_is_read(tmp_path):
    eff = get_effect("thermal:temp", config={"reference_C": 20.0},
                     params={"kx_mm_per_C": 0.001, "ky_mm_per_C": 0.0, "kz_mm_per_C": 0.0})
    eng = compose(IdentityEngine(VOLUME), [eff.to_dict()])
    with pytest.raises(MissingSetupError, match=r"--context temp=VALUE"):
        Corrector(eng, Setup(), CorrectOptions(), path="part.nc")
    # refused up front: even a program whose first line is already broken is not read
    with pytest.raises(MissingSetupError, match=r"needs the context value 'temp'"):
        correct_text("G21 #1=2\n", eng, Setup())
    cal = tmp_path / "thermal.json"
    save_calibration(cal, IdentityEngine(VOLUME), name="thermal", effects=[eff.to_dict()])
    prog = tmp_path / "p.nc"
    prog.write_text(RAPIDS)
    r = invoke(["correct", prog, "-c", cal, "-o", tmp_path / "o.nc"])
    assert r.exit_code == EXIT_SAFETY
    assert f"error: {prog}: the calibration's effect thermal:temp needs the context value 'temp'" in r.output
    assert "--context temp=VALUE" in r.output
    assert not (tmp_path / "o.nc").exists()
    r = invoke(["correct", prog, "-c", cal, "-o", tmp_path / "o.nc", "--context", "temp=25"])
    assert r.exit_code == 0, r.output
    np.testing.assert_allclose(ends((tmp_path / "o.nc").read_text())[1:, 0] - ends(RAPIDS)[1:, 0], -0.005,
                               atol=6e-5)


def test_directions_and_rotary_positions_need_no_context():
    eng = compose(IdentityEngine(VOLUME), [get_effect("backlash:X", params={"b_mm": 0.02}).to_dict()])
    Corrector(eng, Setup(), CorrectOptions())  # dirx comes from the program's moves


# -- a map that does not cover the program --------------------------------------------------------
def test_map_refusal_names_the_program_file_and_line(tmp_path):
    prog = tmp_path / "part.nc"
    prog.write_text("G21 G90\nG0 X10 Y10 Z10\nG1 X40 F300\nG1 X80\nG1 X20\nM30\n")
    small = tmp_path / "small.csv"
    small.write_text("# postproc correction map v1\n# units: length=mm\n# apply: Z\nX,value\n0,0.001\n50,0.002\n")
    out = tmp_path / "o.nc"
    r = invoke(["correct", prog, "-c", ROOT / "tests" / "cases" / "demo_static.json", "--map", small, "-o", out])
    assert r.exit_code == EXIT_SAFETY
    assert f"error: {prog}:4:1: program point X=" in r.output
    assert "outside the correction map small" in r.output
    assert not out.exists()
    # the same through -j with several files
    outdir = tmp_path / "outdir"
    r = invoke(["correct", prog, ROOT / "samples" / "pocket.nc", "-c", ROOT / "tests" / "cases" / "demo_static.json",
                "--map", small, "--output-dir", outdir, "-j", "1"])
    assert f"refused   {prog}:4:1: program point X=" in r.output
    assert f"refused (exit {EXIT_SAFETY}) {prog}:4:1: program point X=" in r.output


class IndexOnlyMap:
    """A map that names the refused point by index only (no line numbers)."""

    name = "indexonly"

    def delta(self, p_mm, context):
        p = np.asarray(p_mm)
        bad = np.flatnonzero(p[:, 0] > 50.0)
        if len(bad):
            err = OutOfVolumeError("outside the map")
            err.point_index = int(bad[0])
            raise err
        return np.zeros_like(p)


def test_map_refusal_by_point_index_is_placed_on_its_line():
    text = "G21 G90\nG0 X10 Y10 Z10\nG1 X40 F300\nG1 X45\n(comment)\nG1 X80\nM30\n"
    eng = StaticEngine(np.eye(3), [0.0, 0.0, 0.0], VOLUME)
    with pytest.raises(OutOfVolumeError) as exc:
        correct_text(text, eng, Setup(), CorrectOptions(added=[IndexOnlyMap()]), path="part.nc")
    assert (exc.value.path, exc.value.lineno) == ("part.nc", 6)


def test_cli_extrapolate_linear_reaches_the_parametric_engine(tmp_path):
    prog = tmp_path / "out.nc"
    prog.write_text(OUTSIDE)
    got = {}
    for mode in ("clamp", "linear"):
        out = tmp_path / f"{mode}.nc"
        r = invoke(["correct", prog, "-c", PARAMETRIC, "--extrapolate", mode, "-o", out])
        assert r.exit_code == 0, r.output
        assert "1 points outside the calibrated volume were extrapolated" in r.output
        got[mode] = ends(out.read_text())[1]
    eng = load_calibration(PARAMETRIC).engine.with_options(extrapolate="linear")
    target = np.array([[335.0, 10.0, 10.0]])
    np.testing.assert_allclose(got["linear"], (target + eng.correction(target, np.zeros((1, 3))).q)[0], atol=6e-5)
    assert np.abs(got["linear"] - got["clamp"]).max() > 0.005


def test_segmented_output_does_not_depend_on_the_chunk_size():
    eng = load_calibration(PARAMETRIC).engine
    text = (ROOT / "samples" / "pocket.nc").read_text()
    outs = [correct_text(text, eng, Setup(), CorrectOptions(chunk_lines=c))[0] for c in (None, 3)]
    assert outs[0] == outs[1]
    assert outs[0].count("\n") > text.count("\n") + 10  # moves were split (into few exact arcs and chords)
