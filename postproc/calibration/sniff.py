"""Tell which formats.md file a path holds, from its magic line or its header."""

from __future__ import annotations

import re

from postproc.calibration.csvfile import sniff_separator
from postproc.errors import MeasurementError

KINDS = {
    "postproc measurements v1": "measurements",
    "postproc axis error tables v1": "tables",
    "postproc squareness v1": "squareness",
    "postproc iso230 runs v1": "runs",
}


def sniff(path) -> str:
    """Return "measurements", "tables", "squareness", "runs" (ISO 230-2 interferometer runs)
    or "isg" (Beckhoff TF5280 component errors in the ISG CSV format, read as tables)."""
    path = str(path)
    try:
        with open(path, encoding="utf-8-sig") as fh:
            head = [fh.readline() for _ in range(50)]
    except OSError as exc:
        raise MeasurementError(f"cannot read file: {exc.strerror}", path=path) from None
    except UnicodeDecodeError as exc:
        raise MeasurementError(f"not UTF-8 text ({exc.reason})", path=path) from None
    for line in head:
        if line.startswith("#"):
            body = line[1:].strip()
            if body in KINDS:
                return KINDS[body]
            continue
        if not line.strip() or line.startswith("//"):  # '//': a comment of the TF5280 ISG CSV format
            continue
        words = line.split()
        if words and any(re.fullmatch(r"E[XYZABC][XYZ]", w) for w in words) and not re.search("[,;\t]", line):
            return "isg"
        cols = {c.strip() for c in line.split(sniff_separator(line))}
        if {"X", "Y", "Z", "mx", "my", "mz"} <= cols:
            return "measurements"
        if {"axis", "target", "run", "direction", "deviation"} <= cols:
            return "runs"
        if {"axis", "position"} <= cols:
            return "tables"
        if {"name", "value"} <= cols:
            return "squareness"
        break
    raise MeasurementError(
        "cannot tell what this file holds: not point measurements, axis error tables, squareness or "
        "interferometer runs",
        path=path,
        lineno=1,
        col=1,
        hint=f"start it with one of: {'; '.join('# ' + k for k in KINDS)}",
    )
