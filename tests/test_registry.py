"""The method registry: a new method is its module and one register() call, and the fit
command takes its --method choices and method options from the registry."""

import inspect
import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from postproc.calfile import load_calibration
from postproc.calibration.measurements import (
    Measurements,
    format_measurements,
    read_measurement_files,
)
from postproc.cli import main
from postproc.engine import registry
from postproc.engine.base import Engine, FitResult, InverseResult, check_points, check_tool_vectors
from postproc.engine.registry import FitOption, Method
from postproc.metrology.tables_fit import tables_fitter


# -- a throwaway method: the machine is off by one constant translation t -------------
class TranslationEngine(Engine):
    """p = q + r + t."""

    method = "translation"
    affine = True

    def __init__(self, t_mm, volume_mm) -> None:
        super().__init__(volume_mm)
        self.t = np.asarray(t_mm, dtype=float)

    def forward(self, q, r=None, context=None):
        q = check_points(q, "q")
        return q + check_tool_vectors(r, len(q)) + self.t

    def inverse(self, p, r=None, context=None):
        p = check_points(p, "p")
        return InverseResult(p - check_tool_vectors(r, len(p)) - self.t, np.zeros(len(p)),
                             np.zeros(len(p), dtype=int))

    def model_to_dict(self):
        return {"t_mm": self.t.tolist()}

    @classmethod
    def model_from_dict(cls, model, volume_mm):
        return cls(model["t_mm"], volume_mm)


def fit_translation(measurements, *, shrink: float = 0.0, **options) -> FitResult:
    """t = sum(m - q - r) / (n + shrink): the mean offset, pulled towards 0 by ``shrink``."""
    meas = Measurements.concat(list(measurements))
    d = meas.m - meas.q - meas.r
    engine = TranslationEngine(d.sum(axis=0) / (len(d) + shrink), np.vstack([meas.q.min(0), meas.q.max(0)]))
    return FitResult(engine=engine, residuals_mm=meas.m - engine.forward(meas.q, meas.r),
                     report=[f"translation fit on {len(d)} points"])


TRANSLATION = Method(
    "translation", f"{__name__}:TranslationEngine", f"{__name__}:fit_translation",
    options=(FitOption("shrink", "--shrink", "float", default=0.0, minimum=0, metavar="N",
                       help="Translation method: pull the offset towards zero as N more points at zero would."),))


@pytest.fixture
def translation():
    registry.register(TRANSLATION)
    try:
        yield TRANSLATION
    finally:
        registry.unregister("translation")


@pytest.fixture
def points(tmp_path):
    rng = np.random.default_rng(41)
    q = rng.uniform(0, 300, (25, 3))
    t = np.array([0.012, -0.034, 0.005])
    m = q + t + rng.normal(0, 0.002, q.shape)
    path = tmp_path / "points.csv"
    path.write_text(format_measurements(Measurements(q=q, m=m, r=np.zeros_like(q))))
    (read,) = read_measurement_files([str(path)], None)  # as written (to the file's decimals)
    return path, read.q, read.m


def test_a_registered_method_is_fitted_by_the_fit_command_with_its_own_option(translation, points, tmp_path):
    path, q, m = points
    out = tmp_path / "t.json"
    res = CliRunner().invoke(main, ["fit", str(path), "--method", "translation", "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert "translation fit on 25 points" in res.output
    cal = load_calibration(out)
    assert cal.method == "translation"
    np.testing.assert_allclose(cal.engine.t, np.mean(m - q, axis=0), atol=1e-12)
    # its option, with its value passed to its fitter
    res = CliRunner().invoke(main, ["fit", str(path), "-m", "translation", "--shrink", "5", "-o", str(out)])
    assert res.exit_code == 0, res.output
    np.testing.assert_allclose(load_calibration(out).engine.t, np.sum(m - q, axis=0) / 30, atol=1e-12)
    # the option belongs to that method only
    res = CliRunner().invoke(main, ["fit", str(path), "-m", "static", "--shrink", "5", "-o", str(tmp_path / "s.json")])
    assert res.exit_code == 2
    assert "--shrink applies to the translation method only (this fit is static)" in res.output
    help_text = CliRunner().invoke(main, ["fit", "--help"]).output
    assert "[static|interval|grid|parametric|translation]" in help_text
    assert "--shrink N" in help_text


def test_the_registered_engine_corrects_a_program(translation, points, tmp_path):
    path, q, m = points
    cal = tmp_path / "t.json"
    assert CliRunner().invoke(main, ["fit", str(path), "-m", "translation", "-o", str(cal)]).exit_code == 0
    t = load_calibration(cal).engine.t
    src = tmp_path / "p.nc"
    src.write_text("G21 G90\nG0 X100 Y100 Z100\nG1 X150 Y120 F500\nM30\n")
    out = tmp_path / "p_corrected.nc"
    res = CliRunner().invoke(main, ["correct", str(src), "-c", str(cal), "-o", str(out)])
    assert res.exit_code == 0, res.output
    body = [ln for ln in out.read_text().splitlines() if ln.startswith(("G0", "G1"))]
    a, b = np.array([100.0, 100.0, 100.0]) - t, np.array([150.0, 120.0, 100.0]) - t  # targets moved by -t
    assert body == [f"G0 X{a[0]:.4f} Y{a[1]:.4f} Z{a[2]:.4f}", f"G1 X{b[0]:.4f} Y{b[1]:.4f} F500"]  # Z stays modal


def test_without_its_registration_the_method_is_not_a_choice(points, tmp_path):
    path, _, _ = points
    res = CliRunner().invoke(main, ["fit", str(path), "-m", "translation", "-o", str(tmp_path / "t.json")])
    assert res.exit_code == 2
    assert "'translation' is not one of" in res.output
    assert "--shrink" not in CliRunner().invoke(main, ["fit", "--help"]).output


def test_an_option_declared_twice_must_be_declared_alike():
    clash = Method("clash", f"{__name__}:TranslationEngine", f"{__name__}:fit_translation",
                   options=(FitOption("step", "--step", "float", help="x"),))
    with pytest.raises(ValueError, match="--step is declared otherwise by method grid"):
        registry.register(clash)
    other_flag = Method("clash", f"{__name__}:TranslationEngine", f"{__name__}:fit_translation",
                        options=(FitOption("step", "--lattice-step", "text", help="x"),))
    with pytest.raises(ValueError, match="clashes with step"):
        registry.register(other_flag)
    assert "clash" not in registry.METHODS


# -- the declarations agree with the code they describe --------------------------------
def test_the_fit_command_offers_the_registered_methods_and_options():
    cmd = main.get_command(None, "fit")
    params = {max(p.opts, key=len): p for p in cmd.params}
    assert list(params["--method"].type.choices) == registry.fit_methods()
    assert registry.fit_methods() == ["static", "interval", "grid", "parametric"]
    for flag, (opt, _methods) in registry.fit_options().items():
        assert params[flag].help == opt.help


def test_each_option_default_and_choices_are_the_fitters_own():
    from postproc.engine import grid, parametric

    for name, method in registry.METHODS.items():
        if not method.fitter:
            continue
        fit_params = inspect.signature(registry.fitter(name)).parameters
        engine_params = inspect.signature(registry.engine_class(name).__init__).parameters
        for opt in method.options:
            # a fitter keyword, or an engine setting the fitter passes on
            where = fit_params if opt.keyword in fit_params else engine_params
            assert opt.keyword in where, (name, opt.keyword)
            default = where[opt.keyword].default
            assert opt.default == (None if default is inspect.Parameter.empty else default), (name, opt.keyword)
            if opt.tables:
                assert "options" in inspect.signature(tables_fitter(name)).parameters
    opts = {opt.keyword: opt for opt, _ in registry.fit_options().values()}
    assert opts["model"].choices == grid.MODELS
    assert opts["order"].choices == parametric.ORDERS
    assert opts["solver"].choices == parametric.SOLVERS


def test_refit_options_fit_the_same_partition_again():
    rng = np.random.default_rng(5)
    axes = [np.linspace(0, 200, 5), np.linspace(0, 150, 4), np.linspace(0, 100, 3)]
    q = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    m = q * (1 + 1e-4) + rng.normal(0, 0.001, q.shape)
    meas = [Measurements(q=q, m=m, r=np.zeros_like(q))]
    interval = registry.fitter("interval")(meas, intervals="X=0,60,200;Y=2;Z=1").engine
    options = registry.refit_options(interval)
    assert options == {"intervals": "X=0.000,60.000,200.000;Y=0.000,75.000,150.000;Z=0.000,100.000"}
    again = registry.fitter("interval")(meas, **options).engine
    assert json.dumps(again.model_to_dict()["edges_mm"]) == json.dumps(interval.model_to_dict()["edges_mm"])
    lattice = registry.fitter("grid")(meas).engine
    assert registry.refit_options(lattice) == {"step": "50,50,50"}
    assert registry.refit_options(registry.fitter("static")(meas).engine) == {}
    assert registry.option_flag("intervals") == "--intervals"
    assert registry.option_flag("border_blend_mm") == "--border-blend"


ROOT = Path(__file__).parents[1]
SIX = str(ROOT / "samples" / "s500_static_6points.csv")
TABLES = str(ROOT / "calibrations" / "s500_tables.csv")


@pytest.mark.parametrize(("args", "message"), [
    ([SIX, "-m", "static", "--intervals", "X=2"],
     "--intervals applies to the interval method only (this fit is static); add --method interval"),
    ([SIX, "--screw-pitch", "X=5"], "--screw-pitch applies to the grid method only (this fit is static)"),
    ([SIX, "--order", "exact"], "--order applies to the parametric method only (this fit is static)"),
    ([TABLES, "--knot-spacing", "20"],
     "--knot-spacing applies to parametric fits from point measurements, not to axis error tables"),
    ([TABLES, "-m", "grid"], "axis error tables make a parametric calibration; drop --method or use parametric"),
    (["--base", str(ROOT / "calibrations" / "s500_static.json"), SIX, "--effect", "backlash:X", "--step", "10"],
     "--base keeps the calibration as it is; drop --step"),
], ids=["intervals-static", "screw-pitch-static", "order-static", "knots-tables", "grid-tables", "step-base"])
def test_an_option_the_fit_does_not_take_is_refused(tmp_path, args, message):
    out = tmp_path / "c.json"
    res = CliRunner().invoke(main, ["fit", *args, "-o", str(out)])
    assert res.exit_code == 2, res.output
    assert message in res.output
    assert not out.exists()
