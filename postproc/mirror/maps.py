"""Measured correction maps: ``[B, Z, value]`` (or any one or two of X,Y,Z,A,B,C).

A map holds values measured or computed at nodes of one or two machine coordinates
and adds them, interpolated onto the program's reference points, along one axis of
the commanded position. File layout (a formats.md CSV)::

    # postproc correction map v1
    # units: length=mm          (mm | um: applies to the values and to X, Y, Z columns)
    # apply: Y                  (axis along which the value is added: X, Y or Z)
    # sign: +1                  (optional, +1 or -1: delta = sign * value)
    # outside: refuse           (optional, refuse | clamp)
    B,Z,value
    0.0,100.0,0.0123
    ...

Rotary coordinates (A, B, C) are in degrees as programmed. On a regular grid the
map is bilinear; on scattered nodes it is linear on a Delaunay triangulation. A
program point outside the map is refused (:class:`OutOfVolumeError` naming the
point's line when the context carries ``lineno``) unless ``outside: clamp`` is set
in the file or ``load_map(path, outside="clamp")`` is asked for; clamping holds the
edge value (nearest node for points beyond a scattered map's hull).

The object returned by :func:`load_map` has ``.name`` and ``.delta(p_mm, context)``
(mm, (N, 3)), the interface of the correction pipeline's ``added`` list: the delta is
added to the commanded position after the geometric engine's inverse.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from postproc.calibration.csvfile import CsvTable, format_csv, length_scale, read_csv
from postproc.errors import MeasurementError, OutOfVolumeError, PostprocError

MAGIC = "postproc correction map v1"
LINEAR_AXES = ("X", "Y", "Z")
ROTARY_AXES = ("A", "B", "C")
COORD_NAMES = LINEAR_AXES + ROTARY_AXES
OUTSIDE_MODES = ("refuse", "clamp")

# Slack on the map's bounds (mm or degrees): a program point written on the map's
# edge and re-read from text with 4-decimal rounding must still count as inside.
MAP_EDGE_SLACK = 1e-6

# Two node coordinates closer than this (mm or degrees) are the same grid line; map
# files carry at most 6 decimals, so 1e-9 only merges true duplicates.
NODE_MERGE_TOL = 1e-9

# A rotary map whose span plus one grid step reaches 360 deg (within this, degrees)
# covers the full circle and is closed periodically.
FULL_CIRCLE_TOL_DEG = 1e-6

# Decimals written for map values (mm): 0.1 nm, far below any machine resolution.
VALUE_DECIMALS = 7
COORD_DECIMALS = 6


@dataclass
class CorrectionMap:
    """Values (mm) at nodes of one or two coordinates, added along ``apply_axis``.

    ``coords``: coordinate names, e.g. ``("B", "Z")``; ``nodes``: (M, k) node
    coordinates (mm or degrees); ``values_mm``: (M,); ``sign``: +1 or -1;
    ``outside``: "refuse" or "clamp".
    """

    name: str
    coords: tuple[str, ...]
    nodes: np.ndarray
    values_mm: np.ndarray
    apply_axis: str = "Y"
    sign: float = 1.0
    outside: str = "refuse"
    path: str | None = None
    linenos: np.ndarray | None = None
    meta: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.nodes = np.asarray(self.nodes, dtype=float).reshape(len(self.values_mm), -1)
        self.values_mm = np.asarray(self.values_mm, dtype=float)
        self.coords = tuple(self.coords)
        if self.apply_axis not in LINEAR_AXES:
            raise MeasurementError(f"apply axis {self.apply_axis!r} is not one of X, Y, Z", path=self.path)
        if self.outside not in OUTSIDE_MODES:
            raise MeasurementError(f"outside mode {self.outside!r} is not refuse or clamp", path=self.path)
        self._interp = _Interpolant(self)

    # -- the pipeline interface -------------------------------------------------------
    def delta(self, p_mm, context: Mapping | None = None) -> np.ndarray:
        """(N, 3) mm to add to the commanded positions of points ``p_mm``."""
        p = np.asarray(p_mm, dtype=float).reshape(-1, 3)
        out = np.zeros((len(p), 3))
        out[:, LINEAR_AXES.index(self.apply_axis)] = self.sign * self.values_at(
            map_coordinates(self.coords, p, context), _linenos(context, len(p))
        )
        return out

    # -- evaluation -----------------------------------------------------------------
    @property
    def regular(self) -> bool:
        return self._interp.grid is not None

    @property
    def bounds(self) -> np.ndarray:
        """(2, k) lowest and highest node coordinate."""
        return np.vstack([self.nodes.min(axis=0), self.nodes.max(axis=0)])

    def values_at(self, coords, linenos: Sequence[int] | np.ndarray | None = None) -> np.ndarray:
        """Map value (mm, before ``sign``) at (N, k) coordinates; refuse or clamp outside."""
        x = np.asarray(coords, dtype=float).reshape(-1, len(self.coords))
        return self._interp(x, linenos)

    def shifted(self, offsets: Mapping[str, float], name: str | None = None) -> CorrectionMap:
        """The same map with node coordinate ``c`` moved to ``c + offsets[c]``."""
        nodes = self.nodes.copy()
        for c, off in offsets.items():
            if c in self.coords:
                nodes[:, self.coords.index(c)] += float(off)
        return replace(self, nodes=nodes, name=name or self.name)

    def with_values(self, values_mm, name: str | None = None) -> CorrectionMap:
        return replace(self, values_mm=np.asarray(values_mm, dtype=float), name=name or self.name)


@dataclass
class ConstantCorrection:
    """The same delta everywhere along one axis (e.g. the semi-finish allowance)."""

    name: str
    apply_axis: str
    value_mm: float
    sign: float = 1.0

    def delta(self, p_mm, context: Mapping | None = None) -> np.ndarray:
        p = np.asarray(p_mm, dtype=float).reshape(-1, 3)
        out = np.zeros((len(p), 3))
        out[:, LINEAR_AXES.index(self.apply_axis)] = self.sign * self.value_mm
        return out


@dataclass
class SumCorrection:
    """Several corrections added together (each with its own axis and sign)."""

    name: str
    parts: list

    def delta(self, p_mm, context: Mapping | None = None) -> np.ndarray:
        p = np.asarray(p_mm, dtype=float).reshape(-1, 3)
        out = np.zeros((len(p), 3))
        for part in self.parts:
            out += part.delta(p, context)
        return out


def _linenos(context: Mapping | None, n: int):
    if not context or "lineno" not in context:
        return None
    ln = np.broadcast_to(np.asarray(context["lineno"]), (n,))
    return ln


def map_coordinates(coords: Sequence[str], p_mm: np.ndarray, context: Mapping | None) -> np.ndarray:
    """(N, k) values of the named coordinates: X, Y, Z from the points, A, B, C from context."""
    n = len(p_mm)
    out = np.empty((n, len(coords)))
    for j, c in enumerate(coords):
        if c in LINEAR_AXES:
            out[:, j] = p_mm[:, LINEAR_AXES.index(c)]
        else:
            if not context or c not in context or context[c] is None:
                raise PostprocError(
                    f"the correction map needs the rotary axis {c}, which the program does not give",
                    hint=f"use a map over coordinates the program drives, or program the {c} axis",
                )
            out[:, j] = np.broadcast_to(np.asarray(context[c], dtype=float), (n,))
    return out


class _Interpolant:
    """Bilinear on a regular grid, Delaunay-linear on scattered nodes, np.interp in 1-D."""

    def __init__(self, m: CorrectionMap) -> None:
        self.m = m
        self.k = len(m.coords)
        self.grid: Callable[[np.ndarray], np.ndarray] | None = None  # the regular grid's interpolant
        self.on_grid = False  # nodes on a regular grid (in 1-D always)
        self.period = [360.0 if c in ROTARY_AXES else None for c in m.coords]
        nodes, values = m.nodes, m.values_mm
        self.lo = nodes.min(axis=0)
        self.hi = nodes.max(axis=0)
        self.closed = [False] * self.k
        if self.k == 1:
            order = np.argsort(nodes[:, 0])
            self.axes = [nodes[order, 0]]
            self.vals = values[order]
            self.axes, self.vals, self.closed[0] = self._close(0, self.axes, self.vals)
            self.on_grid = True
            return
        axes = [_unique(nodes[:, j]) for j in range(self.k)]
        if np.prod([len(a) for a in axes]) == len(values) and all(len(a) >= 2 for a in axes):
            idx = [_nearest_index(a, nodes[:, j]) for j, a in enumerate(axes)]
            grid = np.full([len(a) for a in axes], np.nan)
            grid[tuple(idx)] = values
            if np.all(np.isfinite(grid)):
                # grid lines at the mean of the merged coordinates they stand for
                axes = [np.bincount(ix, weights=nodes[:, j]) / np.bincount(ix)
                        for j, ix in enumerate(idx)]
                for j in range(self.k):
                    axes, grid, self.closed[j] = self._close(j, axes, grid)
                from scipy.interpolate import RegularGridInterpolator

                self.axes = axes
                self.grid = RegularGridInterpolator(tuple(axes), grid, method="linear", bounds_error=False,
                                                    fill_value=None)
                self.on_grid = True
                return
        from scipy.interpolate import LinearNDInterpolator, NearestNDInterpolator
        from scipy.spatial import QhullError

        try:
            self.scattered = LinearNDInterpolator(nodes, values)
        except QhullError:
            raise MeasurementError(
                "the map's nodes lie on a line: a two-coordinate map needs nodes spread in both",
                path=m.path,
                hint="give nodes on at least two rows, or write a one-coordinate map (e.g. B,value)",
            ) from None
        self.nearest = NearestNDInterpolator(nodes, values)

    def _close(self, j: int, axes, vals):
        """Close a rotary axis that covers the full circle by repeating its first line at +360."""
        a = axes[j]
        if self.period[j] is None or len(a) < 2:
            return axes, vals, False
        step = a[1] - a[0]
        if abs((a[-1] - a[0]) + step - 360.0) > FULL_CIRCLE_TOL_DEG or not np.allclose(np.diff(a), step):
            return axes, vals, False
        axes = list(axes)
        axes[j] = np.append(a, a[0] + 360.0)
        first = np.take(vals, [0], axis=j)
        vals = np.concatenate([vals, first], axis=j)
        self.hi[j] = a[0] + 360.0
        return axes, vals, True

    def _wrap(self, x: np.ndarray) -> np.ndarray:
        """Bring rotary angles into the map's range modulo 360 when that puts them inside."""
        x = x.copy()
        for j, per in enumerate(self.period):
            if per is None:
                continue
            col = x[:, j]
            out = (col < self.lo[j] - MAP_EDGE_SLACK) | (col > self.hi[j] + MAP_EDGE_SLACK)
            if np.any(out):
                wrapped = self.lo[j] + np.mod(col - self.lo[j], per)
                use = out & (wrapped <= self.hi[j] + MAP_EDGE_SLACK)
                col[use] = wrapped[use]
        return x

    def __call__(self, x: np.ndarray, linenos) -> np.ndarray:
        x = self._wrap(x)
        outside = np.any((x < self.lo - MAP_EDGE_SLACK) | (x > self.hi + MAP_EDGE_SLACK), axis=1)
        xc = np.clip(x, self.lo, self.hi)
        if self.k == 1:
            vals = np.interp(xc[:, 0], self.axes[0], self.vals)
        elif self.grid is not None:
            vals = self.grid(xc)
        else:
            vals = self.scattered(xc)
            hull_out = ~np.isfinite(vals)
            if np.any(hull_out):
                outside = outside | hull_out
                vals[hull_out] = self.nearest(xc[hull_out])
        if np.any(outside) and self.m.outside == "refuse":
            i = int(np.flatnonzero(outside)[0])
            self._refuse(x, i, int(outside.sum()), linenos)
        return vals

    def _refuse(self, x, i, count, linenos):
        m = self.m
        where = ", ".join(f"{c}={x[i, j]:.4f}" for j, c in enumerate(m.coords))
        span = ", ".join(f"{c} {self.lo[j]:.4f}..{self.hi[j]:.4f}" for j, c in enumerate(m.coords))
        more = f" (and {count - 1} more point(s))" if count > 1 else ""
        lineno = int(linenos[i]) if linenos is not None else None
        shape = "" if self.on_grid else " (or outside the hull of its scattered nodes)"
        err = OutOfVolumeError(
            f"program point {where} is outside the correction map {m.name} ({span}){shape}{more}",
            lineno=lineno,
            hint="measure the map over the whole program, or allow edge clamping "
            "('# outside: clamp' in the map file) if holding the edge value is acceptable",
        )
        err.point_index = i  # which of the points given: lets a caller name the program line
        raise err


def _nearest_index(a: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Index of the element of sorted ``a`` nearest to each ``v``."""
    i = np.clip(np.searchsorted(a, v), 1, len(a) - 1)
    return np.where(np.abs(v - a[i - 1]) <= np.abs(a[i] - v), i - 1, i)


def _unique(a: np.ndarray) -> np.ndarray:
    s = np.sort(a)
    keep = np.concatenate([[True], np.diff(s) > NODE_MERGE_TOL])
    return s[keep]


# -- reading and writing -------------------------------------------------------------


def _meta_error(table: CsvTable, key: str, msg: str, hint: str) -> MeasurementError:
    lineno = next((i + 1 for i, c in enumerate(_comment_lines(table.path)) if c.startswith(key)), None)
    return MeasurementError(msg, path=table.path, lineno=lineno, col=1, hint=hint)


def _comment_lines(path: str) -> list[str]:
    try:
        lines = Path(path).read_text(encoding="utf-8-sig").splitlines()
    except (OSError, UnicodeDecodeError):
        return []
    out = []
    for line in lines:
        if not line.startswith("#") and line.strip():
            break
        out.append(line.lstrip("#").strip())
    return out


def map_from_table(table: CsvTable, *, name: str | None = None, outside: str | None = None) -> CorrectionMap:
    """Build a :class:`CorrectionMap` from a read CSV table (see the module doc)."""
    if not table.comments or table.comments[0].strip() != MAGIC:
        raise MeasurementError(
            "not a correction map (first line is not '# postproc correction map v1')",
            path=table.path, lineno=1, col=1,
            hint="start the file with '# postproc correction map v1', then '# units:' and '# apply:' lines",
        )
    if "value" not in table.header:
        raise MeasurementError(f"no 'value' column (header: {','.join(table.header)})",
                               path=table.path, lineno=table.header_lineno, col=1,
                               hint="the header is e.g. 'B,Z,value' or 'X,Y,value'")
    coords = tuple(h for h in table.header if h != "value")
    bad = [c for c in coords if c not in COORD_NAMES]
    if bad or not 1 <= len(coords) <= 2:
        raise MeasurementError(
            f"map coordinates {','.join(coords)}: expected one or two of {','.join(COORD_NAMES)}",
            path=table.path, lineno=table.header_lineno, col=1,
            hint="the header is e.g. 'B,Z,value' (rotary table and vertical axis) or 'X,Y,value'",
        )
    if len(table.rows) < 2:
        raise MeasurementError("a map needs at least two nodes", path=table.path, lineno=table.header_lineno)
    scale = length_scale(table)
    units = table.meta.get("units", "")
    if "angle=" in units and "angle=deg" not in units.replace(" ", ""):
        raise _meta_error(table, "units", f"map angle unit in {units!r}: rotary coordinates are in degrees",
                          "write 'angle=deg' or leave the angle unit out")
    apply = table.meta.get("apply", "").strip().upper()
    if apply not in LINEAR_AXES:
        raise _meta_error(table, "apply", f"'# apply:' is {apply or 'missing'}; it must name X, Y or Z",
                          "add '# apply: Y' (the axis along which the value is added: the spindle axis)")
    try:
        sign = float(table.meta.get("sign", "1"))
    except ValueError:
        sign = 0.0
    if sign not in (1.0, -1.0):
        raise _meta_error(table, "sign", f"'# sign:' must be +1 or -1, got {table.meta.get('sign')!r}",
                          "write '# sign: +1' or '# sign: -1'")
    mode = (outside or table.meta.get("outside", "refuse")).strip().lower()
    if mode not in OUTSIDE_MODES:
        raise _meta_error(table, "outside", f"'# outside:' must be refuse or clamp, got {mode!r}",
                          "write '# outside: refuse' (default) or '# outside: clamp'")
    nodes = np.column_stack([
        table.numeric(c) * (scale if c in LINEAR_AXES else 1.0) for c in coords
    ])
    values = table.numeric("value") * scale
    linenos = np.asarray(table.linenos)
    _check_duplicates(nodes, linenos, table.path)
    return CorrectionMap(
        name=name or Path(table.path).stem,
        coords=coords,
        nodes=nodes,
        values_mm=values,
        apply_axis=apply,
        sign=sign,
        outside=mode,
        path=table.path,
        linenos=linenos,
        meta=dict(table.meta),
    )


def _check_duplicates(nodes: np.ndarray, linenos: np.ndarray, path: str) -> None:
    key = np.round(nodes / NODE_MERGE_TOL).astype(np.int64) if np.all(np.abs(nodes) < 1e9) else nodes
    _, first, counts = np.unique(key, axis=0, return_index=True, return_counts=True)
    if np.any(counts > 1):
        j = int(first[np.argmax(counts > 1)])
        dup = np.flatnonzero(np.all(key == key[j], axis=1))
        raise MeasurementError(
            f"node given twice (lines {', '.join(str(int(linenos[d])) for d in dup)})",
            path=path, lineno=int(linenos[dup[1]]), col=1,
            hint="average repeated measurements into one value per node",
        )


def load_map(path, *, outside: str | None = None, name: str | None = None) -> CorrectionMap:
    """Read a correction map file; ``outside`` ("refuse"|"clamp") overrides the file's."""
    return map_from_table(read_csv(path), name=name, outside=outside)


def format_map(m: CorrectionMap, *, comments: Sequence[str] = (), units: str = "mm") -> str:
    """Render a map in the file format (values in ``units``: mm or um)."""
    scale = {"mm": 1.0, "um": 1e3}[units]
    meta = [MAGIC, f"units: length={units}" + (" angle=deg" if any(c in ROTARY_AXES for c in m.coords) else ""),
            f"apply: {m.apply_axis}", f"sign: {'+1' if m.sign > 0 else '-1'}"]
    if m.outside != "refuse":
        meta.append(f"outside: {m.outside}")
    meta += list(comments)
    vdec = VALUE_DECIMALS - (3 if units == "um" else 0)
    rows = []
    for node, v in zip(m.nodes, m.values_mm, strict=True):
        cells = [_fixed(x * (scale if c in LINEAR_AXES else 1.0), COORD_DECIMALS) for c, x in zip(m.coords, node, strict=True)]
        rows.append([*cells, _fixed(v * scale, vdec)])
    return format_csv(meta, [*m.coords, "value"], rows)


def _fixed(x: float, decimals: int) -> str:
    s = f"{x:.{decimals}f}"
    return s[1:] if s.startswith("-") and float(s) == 0.0 else s


def save_map(path, m: CorrectionMap, *, comments: Sequence[str] = (), units: str = "mm") -> None:
    from postproc.calfile import atomic_write_text

    atomic_write_text(path, format_map(m, comments=comments, units=units))


def parse_direction(text: str) -> tuple[str, float]:
    """``"+Y"`` / ``"-Y"`` / ``"Y"`` -> ("Y", +1.0) / ("Y", -1.0) / ("Y", +1.0)."""
    t = text.strip().upper()
    sign = -1.0 if t.startswith("-") else 1.0
    axis = t.lstrip("+-")
    if axis not in LINEAR_AXES:
        raise ValueError(f"{text!r}: expected +X, -X, +Y, -Y, +Z or -Z")
    return axis, sign
