"""Point measurements (formats.md section 1): laser tracker, probing, any 3D instrument."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from postproc.calibration.csvfile import (
    CsvTable,
    check_position_span,
    format_csv,
    length_scale,
    read_csv,
)
from postproc.errors import MeasurementError


@dataclass
class Measurements:
    """What a fitter fits: measured points (formats.md section 1), in mm.

    Commanded ``q``, measured ``m`` and tool vectors ``r`` (N, 3). ``direction`` (N, 3)
    holds the approach direction of each axis (1, -1, 0) or is None when the file has
    no dir columns. ``context`` maps every other numeric column (``t``, ``temp*``,
    ``load``, anything else) to an (N,) array. Files are read by
    :func:`read_measurements`.
    """

    q: np.ndarray
    m: np.ndarray
    r: np.ndarray
    direction: np.ndarray | None = None
    context: dict[str, np.ndarray] = field(default_factory=dict)
    path: str = ""
    meta: dict[str, str] = field(default_factory=dict)
    linenos: np.ndarray | None = None
    has_tool_columns: bool = True

    def __len__(self) -> int:
        return len(self.q)

    def context_full(self) -> dict[str, np.ndarray]:
        """Context including the approach directions as ``dirx``, ``diry``, ``dirz``.

        A ``0`` (the axis did not move on the way to this point) is replaced by the
        axis's last approach direction in file order, as formats.md defines it
        (:func:`carried_directions`); rows before an axis's first move stay 0 (unknown).
        """
        ctx = dict(self.context)
        if self.direction is not None:
            carried = carried_directions(self.direction)
            for j, name in enumerate(("dirx", "diry", "dirz")):
                ctx[name] = carried[:, j]
        return ctx

    def unknown_direction_rows(self) -> np.ndarray:
        """(N,) True where some axis has no approach state yet (0 before its first move)."""
        if self.direction is None:
            return np.zeros(len(self), dtype=bool)
        return np.any(carried_directions(self.direction) == 0, axis=1)

    def without_rows(self, drop) -> Measurements:
        """The measurements without the rows ``drop`` (indices). Approach directions are
        carried first (a 0 takes the last move's direction, :func:`carried_directions`),
        so leaving a row out does not change what the others' 0 means."""
        keep = np.ones(len(self), dtype=bool)
        keep[np.asarray(list(drop), dtype=int)] = False
        direction = None if self.direction is None else carried_directions(self.direction)[keep]
        return Measurements(q=self.q[keep], m=self.m[keep], r=self.r[keep], direction=direction,
                            context={k: np.asarray(v)[keep] for k, v in self.context.items()}, path=self.path,
                            meta=dict(self.meta), linenos=None if self.linenos is None else self.linenos[keep],
                            has_tool_columns=self.has_tool_columns)

    @staticmethod
    def concat(items: list[Measurements]) -> Measurements:
        """Several files at once: context columns present in only some files are dropped."""
        if len(items) == 1:
            return items[0]
        common = set.intersection(*(set(m.context) for m in items))
        directions = [m.direction for m in items if m.direction is not None]
        direction = np.vstack(directions) if len(directions) == len(items) else None
        return Measurements(
            q=np.vstack([m.q for m in items]),
            m=np.vstack([m.m for m in items]),
            r=np.vstack([m.r for m in items]),
            direction=direction,
            context={k: np.concatenate([m.context[k] for m in items]) for k in sorted(common)},
            path=",".join(m.path for m in items),
            meta={},
            linenos=None,
        )


def carried_directions(direction: np.ndarray) -> np.ndarray:
    """Approach directions (N, 3) with each ``0`` replaced by the last non-zero value
    above it in the same column: the axis did not move, so its backlash state is that of
    its last move (formats.md section 1). Leading zeros stay 0: the state is unknown."""
    d = np.asarray(direction, dtype=float)
    if d.size == 0:
        return d.copy()
    n = len(d)
    rows = np.arange(n)[:, None]
    last = np.where(d != 0, rows, -1)
    last = np.maximum.accumulate(last, axis=0)
    out = np.where(last >= 0, d[np.maximum(last, 0), np.arange(d.shape[1])], 0.0)
    return out

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
