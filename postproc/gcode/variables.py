"""Machine-state variables given on the command line (``--var``, ``--vars FILE``).

A program that reads what only the controller holds (Haas tool life ``#5405``, retained
common variables ``#500``-``#999``, LinuxCNC's stored offsets ``#5221``) is expanded with
the values given here; the header of the corrected program records them. A probe result
(``#5061``-``#5069``: G38 in LinuxCNC, the G31 skip position in Fanuc and Haas) is never
taken from here: a program that depends on what it will measure cannot be corrected
ahead of time.

Files read: a LinuxCNC parameter file (``linuxcnc.var``: ``5221 10.000000`` per line) or a
Fanuc/Haas macro-variable listing (``#500 = 12.5``, ``#500 12.5``, ``N500 12.5``,
``500,12.5``); blank lines, ``%``, ``O`` program-number lines and comments (``;``, ``(...)``)
are skipped.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

from postproc.errors import PostprocError

#: probe results: LinuxCNC G38 (#5061-#5069, interp_convert.cc), Fanuc/Haas G31 skip
#: positions (#5061-#5066, and the rotary axes after them)
PROBE_RESULTS = range(5061, 5070)
PROBE_MESSAGE = ("#{0} is a probe result: a program that depends on what it will measure cannot be corrected "
                 "ahead of time")
PROBE_HINT = "post the program without the probing cycle, or correct the part after probing with measured offsets"

_ENTRY = re.compile(r"^\s*[#Nn]?\s*(\d+)\s*(?:=|,|\s)\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*$")
_SKIP = re.compile(r"^\s*(?:%.*|[Oo]\s*\d+.*|)$")


def parse_var(text: str) -> tuple[int, float]:
    """``"5405=12.5"`` or ``"#5405=12.5"`` -> (5405, 12.5); raises ValueError with the reason."""
    name, sep, value = text.partition("=")
    name = name.strip().lstrip("#")
    try:
        index, number = int(name), float(value)
    except ValueError:
        raise ValueError(f"{text!r}: expected NUMBER=VALUE, e.g. 5405=12.5") from None
    if not sep or index < 1 or not math.isfinite(number):
        raise ValueError(f"{text!r}: expected NUMBER=VALUE with a variable number from 1 and a finite value")
    if index in PROBE_RESULTS:
        raise ValueError(PROBE_MESSAGE.format(index))
    return index, number


def read_vars(path: str | Path) -> dict[int, float]:
    """The variables of a LinuxCNC ``.var`` file or a Fanuc/Haas macro-variable listing.
    Probe results in the file are left out (they are never taken as known)."""
    try:
        text = Path(path).read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise PostprocError(f"cannot read the variables file: {exc.strerror}", path=str(path)) from None
    values: dict[int, float] = {}
    for lineno, raw in enumerate(text.splitlines(), start=1):
        body = re.sub(r"\([^)]*\)", "", raw.split(";", 1)[0])
        if _SKIP.match(body):
            continue
        m = _ENTRY.match(body)
        if m is None:
            raise PostprocError(f"{raw.strip()!r} is not a variable number and its value", path=str(path),
                                lineno=lineno, hint="write one variable a line: 5405 12.5 (or #5405 = 12.5)")
        index, value = int(m.group(1)), float(m.group(2))
        if index not in PROBE_RESULTS and math.isfinite(value):
            values[index] = value
    return values
