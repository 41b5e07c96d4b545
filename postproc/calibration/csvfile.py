"""The CSV layout shared by every formats.md file.

``#`` lines before the header are metadata (``# key: value`` pairs are read, other
comment text is kept as free text); a header row is required; column names are
case-sensitive; ``.`` is the decimal point; UTF-8.
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from postproc.errors import MeasurementError

LENGTH_TO_MM = {"mm": 1.0, "um": 1e-3}
ANGLE_TO_RAD = {"rad": 1.0, "urad": 1e-6, "arcsec": np.pi / (180.0 * 3600.0)}


@dataclass
class CsvTable:
    path: str
    meta: dict[str, str]
    comments: list[str]
    header: list[str]
    rows: list[list[str]]
    linenos: list[int]  # source line of each row
    col_starts: list[list[int]] = field(default_factory=list)  # 1-based column of each cell

    def has(self, name: str) -> bool:
        return name in self.header

    def require_rows(self, what: str, hint: str | None = None) -> None:
        """Refuse a file whose header is followed by no rows, naming the header line."""
        if not self.rows:
            raise MeasurementError(f"no {what}", path=self.path, lineno=self.header_lineno, hint=hint)

    def text(self, name: str) -> list[str]:
        j = self.header.index(name)
        return [row[j] for row in self.rows]

    def numeric(self, name: str, default: float | None = None) -> np.ndarray:
        """Column ``name`` as floats; a cell that is not a number is an error with its place."""
        if name not in self.header:
            if default is None:
                raise MeasurementError(
                    f"required column {name!r} is missing (header: {','.join(self.header)})",
                    path=self.path,
                    lineno=self.header_lineno,
                    col=1,
                    hint="column names are case-sensitive; see the formats section of the README",
                )
            return np.full(len(self.rows), float(default))
        j = self.header.index(name)
        out = np.empty(len(self.rows))
        for i, row in enumerate(self.rows):
            cell = row[j].strip()
            try:
                out[i] = float(cell)
            except ValueError:
                raise MeasurementError(
                    f"column {name!r}: {cell!r} is not a number",
                    path=self.path,
                    lineno=self.linenos[i],
                    col=self.col_starts[i][j] if self.col_starts else None,
                    hint="use '.' as the decimal point and plain numbers (no units in cells)",
                ) from None
            if not np.isfinite(out[i]):
                raise MeasurementError(
                    f"column {name!r}: {cell!r} is not a finite number",
                    path=self.path,
                    lineno=self.linenos[i],
                    col=self.col_starts[i][j] if self.col_starts else None,
                )
        return out

    header_lineno: int = 0


def _cell_starts(line: str, n: int) -> list[int]:
    """1-based start column of each comma-separated cell (quotes are not expected here)."""
    starts, pos = [1], 0
    for _ in range(n - 1):
        pos = line.find(",", pos)
        if pos < 0:
            break
        pos += 1
        starts.append(pos + 1)
    return starts + [starts[-1]] * (n - len(starts))


def read_csv_text(text: str, path: str) -> CsvTable:
    lines = text.splitlines()
    meta: dict[str, str] = {}
    meta_lines: dict[str, tuple[int, str]] = {}  # key -> (line number, line text)
    comments: list[str] = []
    i = 0
    while i < len(lines) and (lines[i].startswith("#") or not lines[i].strip()):
        body = lines[i][1:].strip() if lines[i].startswith("#") else ""
        if body:
            comments.append(body)
            key, sep, value = body.partition(":")
            if sep and key.strip() and " " not in key.strip():
                meta[key.strip()] = value.strip()
                meta_lines[key.strip()] = (i + 1, lines[i])
        i += 1
    if i >= len(lines):
        raise MeasurementError("no header row", path=path, lineno=max(i, 1), col=1,
                               hint="the first line that is not a '#' comment must name the columns")
    header_lineno = i + 1
    header = [h.strip() for h in next(csv.reader([lines[i]]))]
    if len(set(header)) != len(header):
        dup = sorted({h for h in header if header.count(h) > 1})
        raise MeasurementError(f"duplicate column(s) {', '.join(dup)}", path=path, lineno=header_lineno, col=1)
    rows, linenos, starts = [], [], []
    for k in range(i + 1, len(lines)):
        line = lines[k]
        if not line.strip() or line.startswith("#"):
            continue
        row = next(csv.reader([line]))
        if len(row) != len(header):
            raise MeasurementError(
                f"row has {len(row)} cells, the header has {len(header)}",
                path=path,
                lineno=k + 1,
                col=1,
            )
        rows.append(row)
        linenos.append(k + 1)
        starts.append(_cell_starts(line, len(row)))
    table = CsvTable(path, meta, comments, header, rows, linenos, starts)
    table.header_lineno = header_lineno
    table.meta_lines = meta_lines
    return table


def read_csv(path) -> CsvTable:
    path = str(path)
    try:
        raw = Path(path).read_bytes()
    except OSError as exc:
        raise MeasurementError(f"cannot read file: {exc.strerror}", path=path) from None
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise MeasurementError(f"not UTF-8 text ({exc.reason})", path=path) from None
    return read_csv_text(text, path)


def _units_place(table: CsvTable, text: str) -> dict:
    """``lineno``/``col`` of ``text`` on the ``# units:`` line, for an error there."""
    lineno, line = getattr(table, "meta_lines", {}).get("units", (None, ""))
    if lineno is None:
        return {}
    col = line.find(text, line.find(":") + 1) if text else -1
    return {"lineno": lineno, "col": col + 1 if col >= 0 else None}


def parse_units(table: CsvTable) -> dict[str, str]:
    """``# units: length=mm angle=rad`` -> {"length": "mm", "angle": "rad"}."""
    spec = table.meta.get("units", "")
    units: dict[str, str] = {}
    for item in spec.replace(",", " ").split():
        key, sep, value = item.partition("=")
        if not sep:
            raise MeasurementError(f"units entry {item!r} is not key=value", path=table.path,
                                   **_units_place(table, item),
                                   hint="write e.g. '# units: length=mm angle=rad'")
        units[key.strip()] = value.strip()
    return units


def length_scale(table: CsvTable, default: str = "mm") -> float:
    unit = parse_units(table).get("length", default)
    if unit not in LENGTH_TO_MM:
        raise MeasurementError(f"length unit {unit!r} is not one of mm, um", path=table.path,
                               **_units_place(table, f"length={unit}"),
                               hint="write '# units: length=mm' or 'length=um'")
    return LENGTH_TO_MM[unit]


def error_scale(table: CsvTable, default: str = "mm") -> float:
    """Scale of the error columns: ``error=mm|um`` when given, else the ``length`` unit.

    formats.md section 2: ``length`` applies to positions and errors alike unless
    ``error`` is given for the error columns (``# units: length=mm error=um``).
    """
    units = parse_units(table)
    if "error" not in units:
        return length_scale(table, default)
    unit = units["error"]
    if unit not in LENGTH_TO_MM:
        raise MeasurementError(f"error unit {unit!r} is not one of mm, um", path=table.path,
                               **_units_place(table, f"error={unit}"),
                               hint="write '# units: length=mm error=um' (positions in mm, errors in um)")
    return LENGTH_TO_MM[unit]


def angle_scale(table: CsvTable, default: str = "rad") -> float:
    unit = parse_units(table).get("angle", default)
    if unit not in ANGLE_TO_RAD:
        raise MeasurementError(f"angle unit {unit!r} is not one of rad, urad, arcsec", path=table.path,
                               **_units_place(table, f"angle={unit}"),
                               hint="write '# units: angle=rad', 'angle=urad' or 'angle=arcsec'")
    return ANGLE_TO_RAD[unit]


def format_csv(meta_lines: list[str], header: list[str], rows) -> str:
    """Render a formats.md CSV (meta lines without the leading '# ')."""
    out = io.StringIO()
    for m in meta_lines:
        out.write(f"# {m}\n")
    out.write(",".join(header) + "\n")
    for row in rows:
        out.write(",".join(row) + "\n")
    return out.getvalue()
