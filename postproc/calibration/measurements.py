"""Point measurements (formats.md section 1): laser tracker, probing, any 3D instrument."""

from __future__ import annotations

import numpy as np

from postproc.calibration.csvfile import (
    CsvTable,
    check_position_span,
    format_csv,
    length_scale,
    read_csv,
)
from postproc.engine.base import Measurements, carried_directions
from postproc.errors import MeasurementError

__all__ = ["Measurements", "carried_directions", "format_measurements", "measurements_from_table",
           "read_measurement_files", "read_measurements"]

MAGIC = "postproc measurements v1"
LENGTH_COLUMNS = ("X", "Y", "Z", "mx", "my", "mz", "tx", "ty", "tz")
KNOWN = set(LENGTH_COLUMNS) | {"dirx", "diry", "dirz"}


def measurements_from_table(table: CsvTable) -> Measurements:
    table.require_rows("measurement rows", "give one measured point per row after the header")
    scale = length_scale(table)
    cols = {c: table.numeric(c) * scale for c in ("X", "Y", "Z", "mx", "my", "mz")}
    q = np.column_stack([cols["X"], cols["Y"], cols["Z"]])
    widest = int(np.argmax(np.ptp(q, axis=0)))
    check_position_span(table, q[:, widest], f"the commanded positions ({'XYZ'[widest]}, the widest axis)")
    tool = {c: table.numeric(c, default=0.0) * scale for c in ("tx", "ty", "tz")}
    direction = None
    if any(table.has(c) for c in ("dirx", "diry", "dirz")):
        direction = np.column_stack([table.numeric(c, default=0.0) for c in ("dirx", "diry", "dirz")])
        bad = ~np.isin(direction, (-1.0, 0.0, 1.0))
        if bad.any():
            i, j = np.argwhere(bad)[0]
            name = ("dirx", "diry", "dirz")[j]
            raise MeasurementError(
                f"column {name!r}: {direction[i, j]:g} is not 1, -1 or 0",
                path=table.path,
                lineno=table.linenos[i],
                col=table.col_starts[i][table.header.index(name)],
            )
    context = {}
    for name in table.header:
        if name in KNOWN:
            continue
        try:
            context[name] = table.numeric(name)
        except MeasurementError:
            continue  # a text column is kept out of the numeric context
    return Measurements(
        q=np.column_stack([cols["X"], cols["Y"], cols["Z"]]),
        m=np.column_stack([cols["mx"], cols["my"], cols["mz"]]),
        r=np.column_stack([tool["tx"], tool["ty"], tool["tz"]]),
        direction=direction,
        context=context,
        path=table.path,
        meta=table.meta,
        linenos=np.asarray(table.linenos),
        has_tool_columns=any(table.has(c) for c in ("tx", "ty", "tz")),
    )


def read_measurements(path) -> Measurements:
    return measurements_from_table(read_csv(path))


def read_measurement_files(paths, tool_vector=None) -> list[Measurements]:
    """Read several files; ``tool_vector`` (3,) fills in files that have no tx,ty,tz columns."""
    data = [read_measurements(p) for p in paths]
    if tool_vector is not None:
        for d in data:
            if not d.has_tool_columns:
                d.r[:] = np.asarray(tool_vector, dtype=float)
    return data


def format_measurements(meas: Measurements, *, comments: list[str] | None = None, decimals: int = 6) -> str:
    """Render in the formats.md form (lengths in mm)."""
    header = ["X", "Y", "Z", "mx", "my", "mz", "tx", "ty", "tz"]
    cols = [meas.q, meas.m, meas.r]
    if meas.direction is not None:
        header += ["dirx", "diry", "dirz"]
    names = list(meas.context)
    header += names
    fmt = f"{{:.{decimals}f}}"

    def num(v: float) -> str:
        s = fmt.format(v)
        return s[1:] if s.startswith("-") and float(s) == 0 else s

    rows = []
    for i in range(len(meas)):
        row = [num(v) for c in cols for v in c[i]]
        if meas.direction is not None:
            row += [str(int(v)) for v in meas.direction[i]]
        row += [repr(float(meas.context[n][i])) for n in names]
        rows.append(row)
    return format_csv([MAGIC, "units: length=mm", *(comments or [])], header, rows)
