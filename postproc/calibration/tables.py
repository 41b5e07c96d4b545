"""Axis error tables and squareness files (formats.md section 2): readers and writers.

The data are :class:`postproc.calibration.axis_tables.AxisTables` and
:class:`~postproc.calibration.axis_tables.Squareness`, in mm and rad. ``read_tables`` reads one
complete tables file; ``partial_parts`` and ``merge_parts`` read files that give only
the components that were measured and put them together (what ``postproc fit`` does
with several tables files, ISO 230-2 runs and TF5280 files, see
:mod:`postproc.metrology.tables_fit`). ``format_tables`` / ``format_squareness`` write
the formats.md text, ``write_tables`` both files atomically.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from postproc.calibration.axis_tables import AXES, COLUMNS, SQUARENESS_NAMES, AxisTables, Squareness
from postproc.calibration.csvfile import (
    CsvTable,
    angle_scale,
    check_position_span,
    error_scale,
    format_csv,
    length_scale,
    read_csv,
)
from postproc.constants import MIN_TABLE_SPACING_MM
from postproc.errors import MeasurementError
from postproc.fileio import atomic_write_texts

TABLES_MAGIC = "postproc axis error tables v1"
SQUARENESS_MAGIC = "postproc squareness v1"

_LENGTH_UNITS = {"mm": 1.0, "um": 1e-3}
_ANGLE_UNITS = {"rad": 1.0, "urad": 1e-6, "arcsec": np.pi / (180.0 * 3600.0)}


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
        close = np.flatnonzero(np.diff(x) < MIN_TABLE_SPACING_MM)
        if len(close):
            k = idx[close[0] + 1]
            raise MeasurementError(
                f"axis {ax}: position {x[close[0] + 1] / lscale:g} is {x[close[0] + 1] - x[close[0]]:.3g} mm from the "
                f"previous row of {ax} ({x[close[0]] / lscale:g}): table positions are at least "
                f"{MIN_TABLE_SPACING_MM * 1000:g} um apart", path=path, lineno=table.linenos[k],
                col=table.col_starts[k][jpos],
                hint="check the position (a typing mistake?) and the '# units:' line")
        out[ax] = (x, values[idx], table)
    return out


def _union_positions(xs: list[np.ndarray]) -> np.ndarray:
    """The union of the sources' positions, one node where two lie closer than
    MIN_TABLE_SPACING_MM (runs in mm and a table in um give 31.4 and 31.400000000000002):
    the first of them stays."""
    x = np.unique(np.concatenate(xs))
    keep = [0]
    for k in range(1, len(x)):
        if x[k] - x[keep[-1]] >= MIN_TABLE_SPACING_MM:
            keep.append(k)
    return x[keep]


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
    for ax in tables.axes:
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


def write_tables(tables_path, squareness_path, tables: AxisTables, squareness: Squareness,
                 comments: list[str] | None = None) -> None:
    """Write the tables and squareness files (mm, rad) atomically, both or neither."""
    atomic_write_texts({squareness_path: format_squareness(squareness, comments=comments),
                        tables_path: format_tables(tables, comments=comments)})


# -- tables that give only some components ------------------------------------------

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


def partial_parts(table: CsvTable) -> dict[str, TablePart]:
    measured = np.array([c in table.header for c in COLUMNS])
    return {ax: TablePart(x, e, measured, table.path) for ax, (x, e, _) in _axis_rows(table, partial=True).items()}


def merge_parts(parts: list[dict[str, TablePart]]) -> tuple[AxisTables, list[str]]:
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
            for j in map(int, np.flatnonzero(part.measured)):
                if j in owner:
                    raise MeasurementError(
                        f"axis {ax} is given in two sources for {COLUMNS[j]} ({owner[j].source} and {part.source})",
                        path=part.source, hint=f"give each component of {ax} once (drop {COLUMNS[j]} from one file)",
                    )
                owner[j] = part
        x = _union_positions([p.x for p in mine])
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
