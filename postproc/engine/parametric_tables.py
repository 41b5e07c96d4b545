"""Axis error tables and squareness (formats.md section 2): data, readers, writers.

``AxisTables`` holds, for each axis X, Y, Z, the table positions (mm, strictly
increasing) and the six error columns ``EX, EY, EZ`` (mm) and ``EA, EB, EC`` (rad)
at those positions. ``Squareness`` holds ``EC0Y, EB0Z, EA0Z`` (rad). Signs are the
formats.md ones (the effective 21-parameter model).

``fit_tables`` turns table files into a :class:`ParametricEngine` calibration; it is
what ``postproc fit TABLES.csv [--squareness SQ.csv]`` calls. ``synthetic_tables``
builds the tables of a known machine with seed-000 magnitudes for tests and demos.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from postproc.calibration.csvfile import (
    CsvTable,
    angle_scale,
    check_position_span,
    error_scale,
    format_csv,
    length_scale,
    read_csv,
)
from postproc.errors import CalibrationError, MeasurementError

AXES = ("X", "Y", "Z")
COLUMNS = ("EX", "EY", "EZ", "EA", "EB", "EC")
LINEAR_COLUMNS = COLUMNS[:3]
ANGULAR_COLUMNS = COLUMNS[3:]
SQUARENESS_NAMES = ("EC0Y", "EB0Z", "EA0Z")
TABLES_MAGIC = "postproc axis error tables v1"
SQUARENESS_MAGIC = "postproc squareness v1"

#: Seed 000, Table 1: the ten control points (x_d/y_d/z_d, mm) of the S500 experiments.
SEED_CONTROL_POINTS_MM = (
    (230, 230, 230), (110, 170, 185), (170, 125, 200), (198, 196, 140), (130, 140, 106),
    (50, 50, 50), (133, 198, 176), (80, 112, 118), (162, 168, 210), (108, 136, 168),
)
#: Seed 000, Tables 3 and 4: the six points (X/Y/Z, mm) where the orders were compared.
SEED_ORDER_POINTS_MM = (
    (60, 50, 50), (120, 170, 190), (180, 130, 200), (140, 140, 110), (200, 200, 140), (80, 110, 120),
)

_LENGTH_UNITS = {"mm": 1.0, "um": 1e-3}
_ANGLE_UNITS = {"rad": 1.0, "urad": 1e-6, "arcsec": np.pi / (180.0 * 3600.0)}


@dataclass
class AxisTables:
    """Per-axis error tables: ``position_mm[axis]`` (n,), ``errors[axis]`` (n, 6).

    Error columns are ``EX, EY, EZ`` in mm and ``EA, EB, EC`` in rad.
    """

    position_mm: dict[str, np.ndarray]
    errors: dict[str, np.ndarray]
    path: str | None = None

    def __post_init__(self) -> None:
        pos, err = {}, {}
        for ax in AXES:
            if ax not in self.position_mm or ax not in self.errors:
                raise CalibrationError(f"axis error tables have no {ax} axis", path=self.path)
            x = np.asarray(self.position_mm[ax], dtype=float)
            e = np.asarray(self.errors[ax], dtype=float)
            if x.ndim != 1 or len(x) < 2 or e.shape != (len(x), 6):
                raise CalibrationError(
                    f"{ax} table: expected at least 2 positions and (n, 6) errors, "
                    f"got positions {x.shape} and errors {e.shape}",
                    path=self.path,
                )
            if not (np.all(np.isfinite(x)) and np.all(np.isfinite(e))):
                raise CalibrationError(f"{ax} table holds a value that is not finite", path=self.path)
            if np.any(np.diff(x) <= 0):
                raise CalibrationError(f"{ax} table positions are not strictly increasing", path=self.path)
            pos[ax], err[ax] = x, e
        self.position_mm, self.errors = pos, err

    @property
    def volume_mm(self) -> np.ndarray:
        """Calibrated volume: the table ranges, [[xmin, ymin, zmin], [xmax, ymax, zmax]]."""
        return np.array([[self.position_mm[a][0] for a in AXES], [self.position_mm[a][-1] for a in AXES]])

    def column(self, axis: str, name: str) -> np.ndarray:
        return self.errors[axis][:, COLUMNS.index(name)]

    def scaled(self, angle_factor: float = 1.0, length_factor: float = 1.0) -> AxisTables:
        """A copy with the angular (and/or linear) columns multiplied by a factor."""
        f = np.array([length_factor] * 3 + [angle_factor] * 3)
        return AxisTables(dict(self.position_mm), {a: self.errors[a] * f for a in AXES}, self.path)

    def to_dict(self) -> dict:
        out = {}
        for ax in AXES:
            d = {"position_mm": self.position_mm[ax].tolist()}
            for j, c in enumerate(COLUMNS):
                d[f"{c}_{'mm' if j < 3 else 'rad'}"] = self.errors[ax][:, j].tolist()
            out[ax] = d
        return out

    @classmethod
    def from_dict(cls, data: dict) -> AxisTables:
        pos, err = {}, {}
        for ax in AXES:
            if ax not in data:
                raise CalibrationError(f"parametric model has no {ax} table")
            d = data[ax]
            pos[ax] = np.asarray(d["position_mm"], dtype=float)
            err[ax] = np.column_stack(
                [np.asarray(d[f"{c}_{'mm' if j < 3 else 'rad'}"], dtype=float) for j, c in enumerate(COLUMNS)]
            )
        return cls(pos, err)


@dataclass
class Squareness:
    """Squareness errors in rad: EC0Y (Y to X), EB0Z (Z to X), EA0Z (Z to Y)."""

    EC0Y: float = 0.0
    EB0Z: float = 0.0
    EA0Z: float = 0.0
    path: str | None = field(default=None, compare=False)

    def as_dict(self) -> dict[str, float]:
        return {n: float(getattr(self, n)) for n in SQUARENESS_NAMES}

    def scaled(self, factor: float) -> Squareness:
        return Squareness(*(getattr(self, n) * factor for n in SQUARENESS_NAMES), path=self.path)


# -- reading ------------------------------------------------------------------------


def _meta_lineno(table: CsvTable, key: str) -> int | None:
    """Line number of the ``# key: ...`` metadata line, to place a unit error."""
    try:
        lines = Path(table.path).read_text(encoding="utf-8-sig").splitlines()
    except (OSError, UnicodeDecodeError):
        return None
    for i, line in enumerate(lines[: table.header_lineno]):
        if line.startswith("#") and line[1:].strip().startswith(f"{key}:"):
            return i + 1
    return None


def read_tables(path) -> AxisTables:
    """Read an axis error tables file (formats.md section 2) into mm / rad."""
    return tables_from_csv(read_csv(path))


def tables_from_csv(*tables: CsvTable) -> AxisTables:
    """AxisTables from one or several parsed tables files (each axis in exactly one)."""
    return _merge_tables([_axis_rows(t) for t in tables], list(tables))


def _axis_rows(table: CsvTable, partial: bool = False) -> dict[str, tuple[np.ndarray, np.ndarray, CsvTable]]:
    """The rows of each axis present in one tables file, checked, in mm / rad.

    ``partial``: error columns may be missing (the components that were not
    measured); they are read as zero. At least one error column is still required.
    """
    path = table.path
    try:
        lscale, escale, ascale = length_scale(table), error_scale(table), angle_scale(table)
    except MeasurementError as exc:
        raise exc.at(lineno=_meta_lineno(table, "units")) from None
    required = ("axis", "position") if partial else ("axis", "position", *COLUMNS)
    if partial and not any(c in table.header for c in COLUMNS):
        raise MeasurementError(
            f"no error column (header: {','.join(table.header)})", path=path, lineno=table.header_lineno, col=1,
            hint="axis error tables need axis,position and at least one of EX,EY,EZ,EA,EB,EC",
        )
    for name in required:
        if name not in table.header:
            raise MeasurementError(
                f"required column {name!r} is missing (header: {','.join(table.header)})",
                path=path, lineno=table.header_lineno, col=1,
                hint="axis error tables need the columns axis,position,EX,EY,EZ,EA,EB,EC",
            )
    jaxis = table.header.index("axis")
    jpos = table.header.index("position")
    axes = []
    for i, row in enumerate(table.rows):
        name = row[jaxis].strip()
        if name not in AXES:
            raise MeasurementError(
                f"axis {name!r} is not one of X, Y, Z", path=path, lineno=table.linenos[i],
                col=table.col_starts[i][jaxis], hint="write the axis as an upper-case X, Y or Z",
            )
        axes.append(name)
    position = table.numeric("position") * lscale
    values = (np.column_stack([table.numeric(c, default=0.0) for c in COLUMNS]) if table.rows
              else np.zeros((0, 6)))
    values[:, :3] *= escale
    values[:, 3:] *= ascale
    axes_arr = np.array(axes)
    out = {}
    for ax in AXES:
        idx = np.flatnonzero(axes_arr == ax)
        if len(idx) == 0:
            continue
        if len(idx) < 2:
            raise MeasurementError(
                f"axis {ax} has 1 row; each axis needs at least 2",
                path=path, lineno=table.linenos[idx[0]], col=1,
                hint="give each axis at least the two ends of its travel",
            )
        x = position[idx]
        check_position_span(table, x, f"axis {ax}: positions")
        bad = np.flatnonzero(np.diff(x) <= 0)
        if len(bad):
            k = idx[bad[0] + 1]
            raise MeasurementError(
                f"axis {ax}: position {x[bad[0] + 1] / lscale:g} does not increase "
                f"(previous row of {ax} has {x[bad[0]] / lscale:g})",
                path=path, lineno=table.linenos[k], col=table.col_starts[k][jpos],
                hint="list each axis's rows in strictly increasing position, without repeats",
            )
        out[ax] = (x, values[idx], table)
    return out


def _merge_tables(parts: list[dict], tables: list[CsvTable]) -> AxisTables:
    """One AxisTables from the axes of one or several files (each axis in exactly one)."""
    found: dict[str, tuple] = {}
    for part in parts:
        for ax, (x, e, table) in part.items():
            if ax in found:
                raise MeasurementError(
                    f"axis {ax} is given in two tables files ({found[ax][2].path} and {table.path})",
                    path=table.path, lineno=table.header_lineno, col=1,
                    hint="give each axis's table once",
                )
            found[ax] = (x, e, table)
    for ax in AXES:
        if ax not in found:
            table = tables[-1]
            raise MeasurementError(
                f"axis {ax} has no rows; the tables need each of X, Y and Z",
                path=table.path, lineno=table.linenos[-1] if table.linenos else table.header_lineno, col=1,
                hint="add the missing axis's interferometer table (at least 2 rows)",
            )
    return AxisTables({a: found[a][0] for a in AXES}, {a: found[a][1] for a in AXES},
                      path=",".join(t.path for t in tables))


def read_squareness(path) -> Squareness:
    """Read a squareness file (formats.md section 2): rows EC0Y, EB0Z, EA0Z in rad."""
    table = read_csv(path)
    path = table.path
    try:
        ascale = angle_scale(table)
    except MeasurementError as exc:
        raise exc.at(lineno=_meta_lineno(table, "units")) from None
    for name in ("name", "value"):
        if name not in table.header:
            raise MeasurementError(
                f"required column {name!r} is missing (header: {','.join(table.header)})",
                path=path, lineno=table.header_lineno, col=1, hint="a squareness file has the columns name,value",
            )
    values = table.numeric("value") * ascale
    jname = table.header.index("name")
    found: dict[str, float] = {}
    for i, row in enumerate(table.rows):
        name = row[jname].strip()
        if name not in SQUARENESS_NAMES:
            raise MeasurementError(
                f"squareness {name!r} is not one of {', '.join(SQUARENESS_NAMES)}",
                path=path, lineno=table.linenos[i], col=table.col_starts[i][jname],
            )
        if name in found:
            raise MeasurementError(f"squareness {name} is given twice", path=path,
                                   lineno=table.linenos[i], col=table.col_starts[i][jname])
        found[name] = float(values[i])
    missing = [n for n in SQUARENESS_NAMES if n not in found]
    if missing:
        raise MeasurementError(
            f"squareness {', '.join(missing)} missing", path=path,
            lineno=table.linenos[-1] if table.linenos else table.header_lineno, col=1,
            hint="give all three of EC0Y, EB0Z, EA0Z (write 0 for one that was not measured)",
        )
    return Squareness(**found, path=path)


def squareness_path_for(tables_path) -> Path:
    """``tables.csv`` -> ``tables_squareness.csv`` (formats.md's default companion)."""
    p = Path(tables_path)
    return p.with_name(f"{p.stem}_squareness{p.suffix or '.csv'}")


# -- writing ------------------------------------------------------------------------


def _num(v: float) -> str:
    """Shortest text that reads back to the same float; never '-0.0'."""
    v = float(v)
    return "0" if v == 0 else repr(v)


def format_tables(tables: AxisTables, *, length_unit: str = "mm", angle_unit: str = "rad",
                  comments: list[str] | None = None) -> str:
    """Render tables in the formats.md form, in the units asked for."""
    if length_unit not in _LENGTH_UNITS or angle_unit not in _ANGLE_UNITS:
        raise ValueError(f"units {length_unit!r}/{angle_unit!r}: choose mm|um and rad|urad|arcsec")
    ls, as_ = _LENGTH_UNITS[length_unit], _ANGLE_UNITS[angle_unit]
    rows = []
    for ax in AXES:
        for x, e in zip(tables.position_mm[ax], tables.errors[ax], strict=True):
            rows.append([ax, _num(x / ls)] + [_num(v / ls) for v in e[:3]] + [_num(v / as_) for v in e[3:]])
    meta = [TABLES_MAGIC, f"units: length={length_unit} angle={angle_unit}", *(comments or [])]
    return format_csv(meta, ["axis", "position", *COLUMNS], rows)


def format_squareness(squareness: Squareness, *, angle_unit: str = "rad",
                      comments: list[str] | None = None) -> str:
    if angle_unit not in _ANGLE_UNITS:
        raise ValueError(f"angle unit {angle_unit!r}: choose rad|urad|arcsec")
    rows = [[n, _num(getattr(squareness, n) / _ANGLE_UNITS[angle_unit])] for n in SQUARENESS_NAMES]
    return format_csv([SQUARENESS_MAGIC, f"units: angle={angle_unit}", *(comments or [])], ["name", "value"], rows)


# -- a known machine for tests and demos --------------------------------------------


def synthetic_tables(seed: int = 0, *, travel_mm: float = 315.0, step_mm: float = 15.0,
                     noise_mm: float = 0.0, noise_rad: float = 0.0) -> tuple[AxisTables, Squareness]:
    """Tables of a smooth machine with seed-000 magnitudes (STAN S500-like).

    Positioning errors of 0.9-1.3 mm/m with a slow bow and a few micrometres of
    waviness, straightness bows of 10-30 um, angular errors of 20-80 urad with some
    waviness, squareness of 100-300 urad: over a 315 mm cube with a 100 mm tool the
    uncorrected |error| is about 0.1-0.45 mm, as in seed 000, Table 1. Every function
    is zero at position 0 (where an interferometer run is zeroed). Optional Gaussian
    noise imitates the instrument.
    """
    rng = np.random.default_rng(seed)
    x = np.arange(0.0, travel_mm + step_mm / 2, step_mm)
    s = x / travel_mm
    pos, err = {}, {}
    for k, ax in enumerate(AXES):
        cols = np.zeros((len(x), 6))
        for j in range(3):
            period = rng.uniform(40.0, 90.0)
            phase = rng.uniform(0, 2 * np.pi)
            wave = np.sin(2 * np.pi * x / period + phase) - np.sin(phase)
            if j == k:  # positioning: scale error, bow, waviness
                cols[:, j] = (rng.choice([-1, 1]) * rng.uniform(0.9e-3, 1.3e-3) * x
                              + rng.uniform(-20e-3, 20e-3) * s**2 + rng.uniform(1e-3, 4e-3) * wave)
            else:  # straightness: bow, small trend, waviness
                cols[:, j] = (rng.choice([-1, 1]) * rng.uniform(10e-3, 30e-3) * s**2
                              + rng.uniform(-3e-5, 3e-5) * x + rng.uniform(0.5e-3, 2e-3) * wave)
        for j in range(3, 6):
            period = rng.uniform(60.0, 150.0)
            phase = rng.uniform(0, 2 * np.pi)
            wave = np.sin(2 * np.pi * x / period + phase) - np.sin(phase)
            cols[:, j] = (rng.choice([-1, 1]) * rng.uniform(20e-6, 80e-6) * s
                          + rng.uniform(3e-6, 10e-6) * wave)
        if noise_mm or noise_rad:
            cols[1:, :3] += rng.normal(0.0, noise_mm, (len(x) - 1, 3))
            cols[1:, 3:] += rng.normal(0.0, noise_rad, (len(x) - 1, 3))
        pos[ax], err[ax] = x.copy(), cols
    sq = Squareness(*(rng.choice([-1, 1]) * rng.uniform(100e-6, 300e-6) for _ in range(3)))
    return AxisTables(pos, err), sq


# -- postproc fit TABLES.csv --------------------------------------------------------

#: options of ``fit_tables`` that go to the engine
ENGINE_OPTIONS = ("order", "solver", "interpolation", "extrapolate", "astatic")


def fit_tables(paths, squareness=None, runs=None, **options):
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
    ignored.
    """
    from postproc.engine.base import FitResult
    from postproc.engine.parametric import ParametricEngine

    if isinstance(paths, str | Path):
        paths = [paths]
    paths = [str(p) for p in paths]
    runs = [str(p) for p in (runs or [])]
    parts = [_table_parts(p) for p in paths]
    report = [f"parametric model from axis error tables: {', '.join(paths)}"] if paths else []
    effects: list[dict] = []
    for p in runs:
        part, effect_dicts, lines = _parts_from_runs(p)
        parts.append(part)
        effects += effect_dicts
        report += lines
    tables, merge_report = _merge_parts(parts)
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
    return FitResult(engine=engine, residuals_mm=np.zeros((0, 3)), report=report, info=info, effects=effects)


# -- tables that give only some components, and ISO 230-2 runs ------------------------

#: An axis that no file measured gets zero errors over -this..+this mm, so that its
#: table (which says nothing about that axis) does not limit the calibrated volume.
UNMEASURED_HALF_RANGE_MM = 10_000.0


@dataclass
class TablePart:
    """The columns one source gives for one axis: positions, values (n, 6), which columns."""

    x: np.ndarray
    values: np.ndarray
    measured: np.ndarray  # (6,) bool
    source: str


def _table_parts(path: str) -> dict[str, TablePart]:
    """The parts of one tables file: formats.md section 2, or a TF5280 ISG CSV file."""
    from postproc.calibration.sniff import sniff

    if sniff(path) == "isg":
        from postproc.metrology.controllers.beckhoff import read_isg_parts

        return read_isg_parts(path)
    return _partial_parts(read_csv(path))


def _partial_parts(table: CsvTable) -> dict[str, TablePart]:
    measured = np.array([c in table.header for c in COLUMNS])
    return {ax: TablePart(x, e, measured, table.path) for ax, (x, e, _) in _axis_rows(table, partial=True).items()}


def _parts_from_runs(path: str) -> tuple[dict[str, TablePart], list[dict], list[str]]:
    """ISO 230-2 runs -> the positioning column (bidirectional mean deviation) of each
    axis and a backlash effect with the reversal values B_i along the axis."""
    from postproc.effects import get_effect
    from postproc.metrology.iso230 import evaluate
    from postproc.metrology.runs import read_runs

    runs = read_runs(path)
    results = evaluate(runs)
    parts, effects, report = {}, [], []
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
        report.append(f"{ax}: ISO 230-2 runs {path}: {len(b)} targets over {res.target_mm[0]:.3f}..{res.target_mm[-1]:.3f} mm; "
                      f"E{COLUMNS[k][1]} (positioning) = mean bidirectional deviation, M {f['M'] * 1000:.2f} um")
        if ref == 0.0:
            report.append(f"{ax}: no reversal in the runs (every B_i is 0): no backlash effect")
        else:
            effect = get_effect(f"backlash:{ax}", config={"position_mm": res.target_mm.tolist(),
                                                          "shape": (b / ref).tolist()}, params={"b_mm": ref})
            effects.append(effect.to_dict())
            report.append(f"{ax}: backlash:{ax} from the reversal values B_i: {effect.describe()}; "
                          f"mean reversal {f['B_mean'] * 1000:+.2f} um")
        report += [f"warning: {w}" for w in res.warnings]
    return parts, effects, report


def _merge_parts(parts: list[dict[str, TablePart]]) -> tuple[AxisTables, list[str]]:
    """One AxisTables from partial sources: each column of each axis from at most one
    source, on the union of the sources' positions (a column is interpolated linearly
    between its own positions and held at its end values beyond them); columns nobody
    measured are zero and reported, an axis nobody measured is zero over a wide range."""
    report, pos, err = [], {}, {}
    for ax in AXES:
        mine = [p[ax] for p in parts if ax in p]
        if not mine:
            pos[ax] = np.array([-UNMEASURED_HALF_RANGE_MM, UNMEASURED_HALF_RANGE_MM])
            err[ax] = np.zeros((2, 6))
            report.append(f"{ax}: not measured: all six components taken as zero "
                          f"(table over +-{UNMEASURED_HALF_RANGE_MM:g} mm so it does not limit the volume)")
            continue
        owner: dict[int, TablePart] = {}
        for part in mine:
            for j in np.flatnonzero(part.measured):
                if j in owner:
                    raise MeasurementError(
                        f"axis {ax} is given in two sources for {COLUMNS[j]} ({owner[j].source} and {part.source})",
                        path=part.source, hint=f"give each component of {ax} once (drop {COLUMNS[j]} from one file)",
                    )
                owner[j] = part
        x = np.unique(np.concatenate([p.x for p in mine]))
        values = np.zeros((len(x), 6))
        for j, part in owner.items():
            values[:, j] = np.interp(x, part.x, part.values[:, j])
            if len(mine) > 1 and (part.x[0] > x[0] or part.x[-1] < x[-1]):
                report.append(f"{ax}: {COLUMNS[j]} ({part.source}) covers {part.x[0]:.3f}..{part.x[-1]:.3f} mm: "
                              f"held at its end values out to {x[0]:.3f}..{x[-1]:.3f} mm")
        missing = [COLUMNS[j] for j in range(6) if j not in owner]
        if missing:
            report.append(f"{ax}: {', '.join(missing)} not measured: taken as zero")
        pos[ax], err[ax] = x, values
    return AxisTables(pos, err), report
