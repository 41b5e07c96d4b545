"""A parametric calibration from interferometer measurements: ``postproc fit TABLES.csv``.

The sources are axis error tables (formats.md section 2, complete or giving only the
components that were measured), Beckhoff TF5280 component error files (ISG CSV) and
ISO 230-2 runs (formats.md section 3, evaluated by :mod:`postproc.metrology.iso230`):
each gives some columns of some axes, :func:`postproc.calibration.tables.merge_parts`
puts them together, and the result is a :class:`ParametricEngine` with, from runs, a
backlash effect per axis.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from postproc.calibration.axis_tables import AXES, COLUMNS, Squareness
from postproc.calibration.csvfile import read_csv
from postproc.calibration.sniff import sniff
from postproc.calibration.tables import (
    TablePart,
    merge_parts,
    partial_parts,
    read_squareness,
    squareness_path_for,
)
from postproc.effects import get_effect
from postproc.engine.base import FitResult
from postproc.engine.parametric import ParametricEngine
from postproc.errors import CalibrationError, MeasurementError
from postproc.metrology.controllers.beckhoff import read_isg_parts
from postproc.metrology.iso230 import evaluate
from postproc.metrology.outliers import RULE, runs_outliers, runs_without
from postproc.metrology.runs import read_runs

#: options of ``fit_tables`` that go to the engine
ENGINE_OPTIONS = ("order", "solver", "interpolation", "extrapolate", "astatic")


def tables_fitter(method: str):
    """The function making a ``method`` calibration from axis error tables, called as
    ``fit(tables_paths, squareness=..., runs=..., **options)`` (the methods
    :func:`postproc.engine.registry.tables_methods` names)."""
    fitters = {"parametric": fit_tables}
    if method not in fitters:
        from postproc.engine.registry import tables_methods

        raise CalibrationError(f"method {method!r} is not made from axis error tables",
                               hint=f"choose one of: {', '.join(tables_methods())}")
    return fitters[method]


def fit_tables(paths, squareness=None, runs=None, keep_outliers: bool = False, **options) -> FitResult:
    """Calibration from axis error tables (+ squareness): a ParametricEngine FitResult.

    ``paths``: one tables file or several; a file may give only the components that
    were measured (missing columns are zero and reported), and each component of
    each axis comes from one file. ``runs``: ISO 230-2 runs files (formats.md
    section 3): each gives its axes' positioning column (the mean bidirectional
    deviation) and a backlash effect with the reversal values B_i along the axis.
    An axis that no file gives has zero errors. ``squareness``:
    the squareness file; by default ``<first tables file>_squareness.csv`` when it
    exists, otherwise squareness is taken as zero and the report says so. Options
    ``order``, ``solver``, ``interpolation``, ``extrapolate``, ``astatic`` go to the
    engine; options meant for point fits (e.g. ``knot_spacing``) are reported as
    ignored. Readings of the runs beyond the outlier rule (:mod:`postproc.metrology.outliers`)
    are left out and listed, unless ``keep_outliers``; the calibration's fit information
    records both lists (``export`` reads them).
    """
    if isinstance(paths, str | Path):
        paths = [paths]
    paths = [str(p) for p in paths]
    runs = [str(p) for p in (runs or [])]
    parts = [_table_parts(p) for p in paths]
    report = [f"parametric model from axis error tables: {', '.join(paths)}"] if paths else []
    effects: list[dict] = []
    excluded: list[dict] = []
    kept: list[dict] = []
    for p in runs:
        part, effect_dicts, lines, found = _parts_from_runs(p, keep_outliers)
        parts.append(part)
        effects += effect_dicts
        report += lines
        (kept if keep_outliers else excluded).extend(o.to_json() for o in found)
    tables, merge_report = merge_parts(parts)
    report += merge_report
    if squareness is None and paths and squareness_path_for(paths[0]).exists():
        squareness = squareness_path_for(paths[0])
    if squareness is not None:
        sq = read_squareness(squareness)
        sq_source = str(squareness)
    else:
        sq, sq_source = Squareness(), None
        looked = f" (looked for {squareness_path_for(paths[0])})" if paths else ""
        report.append(f"no squareness file{looked}: squareness taken as zero; give it with --squareness")
    engine_opts = {k: v for k, v in options.items() if k in ENGINE_OPTIONS and v is not None}
    ignored = sorted(k for k, v in options.items() if k not in ENGINE_OPTIONS and v is not None)
    if ignored:
        report.append(f"option(s) {', '.join(ignored)} do not apply to axis error tables: ignored")
    engine = ParametricEngine(tables, sq, **engine_opts)
    for ax in AXES:
        e = tables.errors[ax]
        x = tables.position_mm[ax]
        report.append(
            f"{ax}: {len(x)} rows over {x[0]:.3f}..{x[-1]:.3f} mm; "
            f"max |EX,EY,EZ| {np.abs(e[:, :3]).max() * 1000:.2f} um, "
            f"max |EA,EB,EC| {np.abs(e[:, 3:]).max() * 1e6:.2f} urad"
        )
    report.append("squareness (urad): " + "  ".join(f"{k} {v * 1e6:+.2f}" for k, v in sq.as_dict().items()))
    report.append(f"order {engine.order}, solver {engine.solver}, interpolation {engine.interpolation}, "
                  f"outside the tables: {engine.extrapolate}")
    info = {"kind": "axis error tables", "sources": paths, "squareness_source": sq_source,
            "ignored_options": ignored}
    if runs:
        info["runs_sources"] = runs
        info["outliers"] = {"rule": RULE, "excluded": excluded, "kept": kept}
    return FitResult(engine=engine, residuals_mm=np.zeros((0, 3)), report=report, info=info, effects=effects)


def _table_parts(path: str) -> dict[str, TablePart]:
    """The parts of one tables file: formats.md section 2, or a TF5280 ISG CSV file."""
    if sniff(path) == "isg":
        return read_isg_parts(path)
    return partial_parts(read_csv(path))


def _parts_from_runs(path: str, keep_outliers: bool = False) -> tuple[dict[str, TablePart], list[dict], list[str],
                                                                      list]:
    """ISO 230-2 runs -> the positioning column (bidirectional mean deviation) of each
    axis and a backlash effect with the reversal values B_i along the axis; readings
    beyond the outlier rule are left out (listed in the report) unless ``keep_outliers``."""
    runs = read_runs(path)
    found = runs_outliers(runs)
    report = []
    if found:
        what = "kept (--keep-outliers)" if keep_outliers else "excluded"
        report.append(f"{path}: {len(found)} reading(s) beyond the outlier rule {what}:")
        report += [f"  {o.describe()}" for o in found]
        if not keep_outliers:
            runs = runs_without(runs, found)
    results = evaluate(runs)
    parts, effects = {}, []
    for ax, res in results.items():
        if ax not in AXES:
            line = int(runs.linenos[runs.axis == ax][0])
            raise MeasurementError(f"axis {ax!r}: runs of this axis cannot enter a calibration of X, Y, Z",
                                   path=path, lineno=line, col=1,
                                   hint="evaluate it with 'postproc iso230'; fit takes runs of X, Y and Z")
        if len(res.target_mm) < 2:
            raise MeasurementError(f"axis {ax}: runs at one target cannot give an error table",
                                   path=path, lineno=int(runs.linenos[runs.axis == ax][0]), col=1)
        k = AXES.index(ax)
        values = np.zeros((len(res.target_mm), 6))
        values[:, k] = res.mean
        measured = np.zeros(6, bool)
        measured[k] = True
        parts[ax] = TablePart(res.target_mm, values, measured, path)
        b = res.reversal
        ref = float(b[np.argmax(np.abs(b))])
        f = res.figures
        if not res.bidirectional:
            side = "+" if res.directions == (1,) else "-"
            tag = "up" if side == "+" else "down"
            report.append(f"{ax}: ISO 230-2 runs {path}: {len(b)} targets over {res.target_mm[0]:.3f}.."
                          f"{res.target_mm[-1]:.3f} mm, approached in {side} only; E{COLUMNS[k][1]} (positioning) "
                          f"= mean deviation in {side}, E{side} {f['E_' + tag] * 1000:.2f} um; no reversal measured: "
                          "no backlash effect (programs that approach in the other direction are not corrected "
                          "for it)")
        else:
            report.append(f"{ax}: ISO 230-2 runs {path}: {len(b)} targets over {res.target_mm[0]:.3f}.."
                          f"{res.target_mm[-1]:.3f} mm; E{COLUMNS[k][1]} (positioning) = mean bidirectional "
                          f"deviation, M {f['M'] * 1000:.2f} um")
        if res.bidirectional and ref == 0.0:
            report.append(f"{ax}: no reversal in the runs (every B_i is 0): no backlash effect")
        elif res.bidirectional:
            effect = get_effect(f"backlash:{ax}", config={"position_mm": res.target_mm.tolist(),
                                                          "shape": (b / ref).tolist()}, params={"b_mm": ref})
            effects.append(effect.to_dict())
            report.append(f"{ax}: backlash:{ax} from the reversal values B_i: {effect.describe()}; "
                          f"mean reversal {f['B_mean'] * 1000:+.2f} um")
        report += [f"warning: {w}" for w in res.warnings]
    return parts, effects, report, found
