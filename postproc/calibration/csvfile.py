"""The CSV layout shared by every formats.md file.

``#`` lines before the header are metadata (``# key: value`` pairs are read, other
comment text is kept as free text); a header row is required; column names are
case-sensitive; ``.`` is the decimal point; UTF-8.

Files written by spreadsheets and instrument software in other locales are read as
well: the separator is taken from the header row (``,``, ``;`` or tab), and with
``;`` or tab a ``,`` inside a number is its decimal comma (``0,0125``). A UTF-8 byte
order mark is skipped.
"""

from __future__ import annotations

import csv
import io
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from postproc.errors import MeasurementError

LENGTH_TO_MM = {"mm": 1.0, "um": 1e-3}
ANGLE_TO_RAD = {"rad": 1.0, "urad": 1e-6, "arcsec": np.pi / (180.0 * 3600.0)}


#: Separators recognised in the header row, in order of preference.
SEPARATORS = (";", "\t", ",")
_DECIMAL_COMMA = re.compile(r"^\s*[-+]?\d*,\d+(?:[eE][-+]?\d+)?\s*$")


def sniff_separator(header_line: str) -> str:
    """``;`` or tab when the header row holds one (a ``,`` is then a decimal comma), else ``,``."""
    for sep in SEPARATORS[:2]:
        if sep in header_line:
            return sep
    return ","


@dataclass
class CsvTable:
    path: str
    meta: dict[str, str]
    comments: list[str]
    header: list[str]
    rows: list[list[str]]
    linenos: list[int]  # source line of each row
    col_starts: list[list[int]] = field(default_factory=list)  # 1-based column of each cell
    separator: str = ","
    decimal_comma: bool = False

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
                    hint=self.missing_hint(name),
                )
            return np.full(len(self.rows), float(default))
        j = self.header.index(name)
        out = np.empty(len(self.rows))
        for i, row in enumerate(self.rows):
            cell = row[j].strip()
            try:
                out[i] = float(cell.replace(",", ".") if self.decimal_comma else cell)
            except ValueError:
                raise MeasurementError(
                    f"column {name!r}: {cell!r} is not a number",
                    path=self.path,
                    lineno=self.linenos[i],
                    col=self.col_starts[i][j] if self.col_starts else None,
                    hint="write plain numbers (no units in cells), with '.' as the decimal point "
                         "(or ',' when the columns are separated by ';' or tabs)",
                ) from None
            if not np.isfinite(out[i]):
                raise MeasurementError(
                    f"column {name!r}: {cell!r} is not a finite number",
                    path=self.path,
                    lineno=self.linenos[i],
                    col=self.col_starts[i][j] if self.col_starts else None,
                )
        return out

    def missing_hint(self, name: str) -> str:
        """What to do about a missing column: its case, or the separator, or the format."""
        near = [h for h in self.header if h.lower() == name.lower()]
        if near:
            return f"column names are case-sensitive: write {name!r}, not {near[0]!r}"
        return "see the formats section of the README for the columns this file needs"

    header_lineno: int = 0
    #: metadata key -> (line number, line text) of its ``# key: value`` line
    meta_lines: dict[str, tuple[int, str]] = field(default_factory=dict)


def _cell_starts(line: str, n: int, sep: str = ",") -> list[int]:
    """1-based start column of each cell (quotes are not expected here)."""
    starts, pos = [1], 0
    for _ in range(n - 1):
        pos = line.find(sep, pos)
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
    sep = sniff_separator(lines[i])
    header = [h.strip() for h in next(csv.reader([lines[i]], delimiter=sep))]
    if len(set(header)) != len(header):
        dup = sorted({h for h in header if header.count(h) > 1})
        raise MeasurementError(f"duplicate column(s) {', '.join(dup)}", path=path, lineno=header_lineno, col=1)
    rows, linenos, starts = [], [], []
    for k in range(i + 1, len(lines)):
        line = lines[k]
        if not line.strip() or line.startswith("#"):
            continue
        row = next(csv.reader([line], delimiter=sep))
        if len(row) != len(header):
            named = {",": "','", ";": "';'", "\t": "tab"}[sep]
            raise MeasurementError(
                f"row has {len(row)} cells, the header has {len(header)} (separator {named}, from the header row)",
                path=path,
                lineno=k + 1,
                col=1,
            )
        rows.append(row)
        linenos.append(k + 1)
        starts.append(_cell_starts(line, len(row), sep))
    decimal_comma = sep != "," and any(_DECIMAL_COMMA.match(c) for row in rows for c in row)
    table = CsvTable(path, meta, comments, header, rows, linenos, starts, sep, decimal_comma)
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
    lineno, line = table.meta_lines.get("units", (None, ""))
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


#: No machine axis travels less than this: positions spanning less, read in the stated
#: unit, mean that the unit is wrong (typically 'length=um' for positions in mm).
MIN_PLAUSIBLE_SPAN_MM = 1.0
#: ... nor more than this (100 m): positions in um read as mm.
MAX_PLAUSIBLE_SPAN_MM = 100_000.0


def check_position_span(table: CsvTable, positions_mm, what: str) -> None:
    """Refuse positions whose extent is implausible for a machine axis in the stated
    units, naming the ``# units:`` line (or the header, when there is none)."""
    x = np.asarray(positions_mm, dtype=float)
    if x.size < 2:
        return
    span = float(np.ptp(x))
    if span == 0 or MIN_PLAUSIBLE_SPAN_MM <= span <= MAX_PLAUSIBLE_SPAN_MM:
        return
    units = parse_units(table)
    unit = units.get("length", "mm")
    spec = table.meta.get("units")
    place = _units_place(table, f"length={unit}") if spec else {"lineno": table.header_lineno, "col": 1}
    stated = f"'# units: {spec}'" if spec else "no '# units:' line (mm assumed)"
    if span < MIN_PLAUSIBLE_SPAN_MM:
        hint = ("if the positions are in mm and the errors in um, write '# units: length=mm error=um' "
                "('length' applies to positions and errors alike unless 'error' is given)")
    else:
        hint = "if the positions are in micrometres, write '# units: length=um'"
    raise MeasurementError(
        f"{what} span {span:g} mm as read with {stated}: implausible for a machine axis "
        f"({MIN_PLAUSIBLE_SPAN_MM:g} mm to {MAX_PLAUSIBLE_SPAN_MM / 1000:g} m)",
        path=table.path, hint=hint, **place,
    )


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
