"""Beckhoff TwinCAT 3 CNC TF5280 volumetric compensation: component errors in the ISG
CSV format (infosys, TF5280 "ISG CSV format" and "Units of measure").

A header line names the columns: the argument (the axis position ``X``, ``Y`` or
``Z``, mm) and the component errors in ISO 230-1 names, ``E<direction><axis>``
(``EXX`` positioning of X, ``EYX`` and ``EZX`` its straightness, ``EAX``, ``EBX``,
``ECX`` its roll, pitch and yaw); one record per row below it, values separated by
blanks; ``//`` starts a comment line; ``#`` alone is a file break after which a new
header follows. Lengths are in mm, angles in rad. The compensation list
(``volcomp*.lis``) names the file with ``file[j]`` / ``file_format[j] ISG_CSV``.

This is the same information as formats.md's axis error tables, so the volumetric
part can go to the control as a whole. What the file does not carry here: the
squareness (TF5280 holds it as position errors, which this export leaves to the
program correction) and the backlash effects (the axis backlash parameters of the
CNC, or the program correction). The component errors are postproc's effective
ones (tool point relative to the workpiece, all axes counted on the tool side):
set the kinematic chain and ``workpiece_axes`` of the compensation list to match.

Signs: every value is an error, actual minus nominal (formats.md), the quantity an
interferometer reads and ISO 230-1 names, which TF5280's compensation takes away. So
the compensation list leaves ``negate`` unset (``negate XYZ`` would add every error
instead of removing it) and ``alternative_model`` at 0 (FALSE): the standard ISO 230
model, all error motions of an axis counted on the tool side, is the one postproc
fitted. The TF5280 manual does not print the sign of the compensation value against
the file's errors; the comment lines say how to check it once on the control (the
compensation value at a position has the opposite sign of EXX there). Both settings are written in the file's comment lines and in
the notes. The round trip reads the file back as TF5280's ISG CSV reader does (comment
lines, file breaks, blank-separated records) and requires every value back to the
digits written.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from postproc.calibration.axis_tables import AXES, COLUMNS
from postproc.calibration.tables import TablePart
from postproc.errors import CalibrationError, MeasurementError
from postproc.metrology.controllers.axis import AxisErrors
from postproc.metrology.controllers.base import Export
from postproc.metrology.controllers.formats import Settings
from postproc.metrology.controllers.roundtrip import check_round_trip

#: Significant digits of the values written; a value read back agrees to this.
DIGITS = 9
#: Comment lines naming the compensation list's sign settings for these values.
SIGN_SETTINGS = ("negate: leave unset (no axis): the values are errors, actual - nominal (ISO 230-1), which the "
                 "compensation takes away; check once on the control: the compensation value at a position must "
                 "have the opposite sign of EXX there, else set negate XYZ",
                 "alternative_model: 0 (FALSE): the standard ISO 230 model, every axis's error motions counted "
                 "on the tool side")

_COMPONENT = re.compile(r"^E([XYZABC])([XYZ])$")


def _num(v: float) -> str:
    s = f"{v:.{DIGITS}g}"
    return "0" if float(s) == 0 else s


def export_beckhoff(axis_errors: list[AxisErrors], *, name: str = "calibration") -> Export:
    exp = Export({})
    lines = [f"// postproc calibration {name}: TF5280 component errors (ISO 230-1 names), mm and rad",
             "// effective errors of the tool point relative to the workpiece, all axes on the tool side",
             *(f"// compensation list: {line}" for line in SIGN_SETTINGS)]
    blocks = []
    for e in axis_errors:
        x = e.nodes()
        values = e.base.axis_errors(e.axis, x)
        header = [e.axis] + [f"{c}{e.axis}" for c in COLUMNS]
        block = [" ".join(header)] + [" ".join(_num(v) for v in (xi, *row)) for xi, row in zip(x, values, strict=True)]
        blocks.append("\n".join(block))
        exp.columns |= {(e.axis, c) for c in COLUMNS}
        exp.notes.append(f"{e.axis}: {len(x)} records over {x[0]:.3f}..{x[-1]:.3f} mm, all six component errors")
        if e.backlash:
            exp.notes.append(f"{e.axis}: backlash:{e.axis} is not a component error: it stays in the program "
                             "correction (leave the CNC's backlash compensation of this axis off)")
    sq = axis_errors[0].base.squareness.as_dict() if axis_errors else {}
    lines.append("// squareness (rad, formats.md names), not written as TF5280 position errors: "
                 + " ".join(f"{k}={v:.6g}" for k, v in sq.items()))
    text = "\n".join(lines) + "\n" + "\n#\n".join(blocks) + "\n"
    # round trip: the file read back as an ISG CSV reader does, every record, every column
    back: dict[str, TablePart] = {}
    for read_block in _isg_blocks(text):
        axis, part = _isg_part(read_block, "volcomp.csv")
        back[axis] = part
    for e in axis_errors:
        part = back[e.axis]
        want = e.base.axis_errors(e.axis, part.x)
        for k, c in enumerate(COLUMNS):
            # DIGITS significant digits of the largest value of the column
            resolution = float(np.abs(want[:, k]).max()) * 10.0 ** (1 - DIGITS)
            check_round_trip(e.axis, f"beckhoff {c}{e.axis}", part.x, {"both": part.values[:, k]},
                             {"both": want[:, k]}, resolution)
    exp.files["volcomp.csv"] = text
    exp.notes.append("compensation list: file[0] volcomp.csv, file_format[0] ISG_CSV; "
                     "the squareness stays in the program correction")
    exp.notes += [f"compensation list: {line}" for line in SIGN_SETTINGS]
    return exp


def read_isg_parts(path) -> dict[str, TablePart]:
    """Component errors of X, Y, Z from an ISG CSV file, as table parts (mm, rad)."""
    path = str(path)
    try:
        text = Path(path).read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise MeasurementError(f"cannot read file: {exc}", path=path) from None
    parts: dict[str, TablePart] = {}
    for block in _isg_blocks(text):
        axis, part = _isg_part(block, path)
        if axis in parts:
            raise CalibrationError(f"axis {axis} is given in two blocks", path=path)
        parts[axis] = part
    return parts


def _isg_blocks(text: str) -> list[list[tuple[int, str]]]:
    """The non-empty blocks of (line number, line) between '#' file breaks, comments left out."""
    blocks: list[list[tuple[int, str]]] = [[]]
    for lineno, line in enumerate(text.splitlines(), 1):
        body = line.strip()
        if not body or body.startswith("//"):
            continue
        if body == "#":
            blocks.append([])
            continue
        blocks[-1].append((lineno, body))
    return [b for b in blocks if b]


def _isg_columns(head: str, head_line: int, path: str) -> tuple[str, dict[int, int]]:
    """The argument axis of a block's header and its component columns (header index ->
    formats.md column index)."""
    names = head.split()
    args = [n for n in names if n in AXES]
    comps = [n for n in names if n not in AXES]
    if not args and comps:
        raise MeasurementError(f"position errors ({', '.join(comps)}) are not read: give squareness in a "
                               "formats.md squareness file", path=path, lineno=head_line, col=1)
    if len(args) != 1:
        raise MeasurementError(f"header {head!r}: one argument column (X, Y or Z) expected",
                               path=path, lineno=head_line, col=1,
                               hint="component errors depending on two axes are not read")
    axis = args[0]
    cols = {}
    for j, n in enumerate(names):
        if n == axis:
            continue
        m = _COMPONENT.match(n)
        if not m or m.group(2) != axis:
            raise MeasurementError(f"column {n!r} is not a component error of {axis} (E<X|Y|Z|A|B|C>{axis})",
                                   path=path, lineno=head_line, col=head.find(n) + 1)
        cols[j] = COLUMNS.index(f"E{m.group(1)}")
    return axis, cols


def _isg_part(block: list[tuple[int, str]], path: str) -> tuple[str, TablePart]:
    """One block: its axis and the columns it gives, sorted by position."""
    head_line, head = block[0]
    names = head.split()
    axis, cols = _isg_columns(head, head_line, path)
    rows = []
    for lineno, body in block[1:]:
        cells = body.split()
        if len(cells) != len(names):
            raise MeasurementError(f"row has {len(cells)} values, the header has {len(names)}",
                                   path=path, lineno=lineno, col=1)
        try:
            rows.append([float(c) for c in cells])
        except ValueError:
            raise MeasurementError(f"{body!r} holds a value that is not a number", path=path,
                                   lineno=lineno, col=1) from None
    if len(rows) < 2:
        raise MeasurementError(f"axis {axis}: fewer than 2 records", path=path, lineno=head_line, col=1)
    a = np.array(rows)
    order = np.argsort(a[:, names.index(axis)], kind="stable")
    a = a[order]
    x = a[:, names.index(axis)]
    if np.any(np.diff(x) <= 0):
        raise MeasurementError(f"axis {axis}: a position is repeated", path=path, lineno=head_line, col=1)
    values = np.zeros((len(x), 6))
    measured = np.zeros(6, bool)
    for j, k in cols.items():
        values[:, k] = a[:, j]
        measured[k] = True
    return axis, TablePart(x, values, measured, path)


def from_settings(axis_errors: list[AxisErrors], s: Settings) -> Export:
    """:func:`export_beckhoff` with ``export``'s settings (the registered builder)."""
    return export_beckhoff(axis_errors, name=s.name)
