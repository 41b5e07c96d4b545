"""Okuma OSP subprogram statements: ``CALL O<name> [Q<n>]`` and the subprogram's ``RTS``.

Okuma OSP-P Programming Manual (Mill), "Subprograms": a subprogram starts with its name,
``O`` and letters or digits (``OCHCK``, ``O1000``), and ends with ``RTS``; ``CALL O<name>``
runs it, ``Q<n>`` times with ``Q`` (once without). Subprograms are kept in their own files
(``.SSB`` system, ``.SUB`` user, ``.LIB`` library subprograms), several to a file; a
program file may hold subprograms after its main program too. The local-variable arguments
a CALL may set (``CALL OABC PX=10``) are read by the subprogram's variable expressions,
which postproc does not read: such a call is refused, naming them.

Lookups stay inside the folders given: a name is letters and digits only, and it is
searched for as a subprogram's name line in the files of those folders, never opened as
a path.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from postproc.gcode.lexer import split_lines

#: ``CALL O<name>`` (after an optional sequence name ``N...``), the rest of the block after it
CALL = re.compile(r"(?i)^(\s*(?:N\w+\s+)?)CALL\s*O([A-Z0-9]+)(?![A-Z0-9_.])([^(\r\n]*)")
#: a CALL whose name is not letters and digits (``CALL O../A``): refused, never looked up
BAD_CALL = re.compile(r"(?i)^\s*(?:N\w+\s+)?CALL\s*(O?[^\s(]*)")
#: ``RTS``: the subprogram's end
RTS = re.compile(r"(?i)^\s*(?:N\w+\s+)?RTS\b")
#: the repeat count ``Q<n>`` of a call
_REPEATS = re.compile(r"(?i)^\s*Q\s*(\d+)\s*$")
#: a subprogram's name line: ``O<name>`` alone (a comment may follow)
_NAME = r"(?i)^\s*O{}\s*(?:\(.*)?$"
#: the files subprograms are kept in (any case)
SUB_EXTENSIONS = (".ssb", ".sub", ".lib")


@dataclass(frozen=True)
class Call:
    """A ``CALL O<name>`` statement: the name (upper case), its repeats, the column of CALL,
    and the text of arguments after it other than ``Q`` (empty when none)."""

    name: str
    repeats: int
    col: int
    arguments: str


def read_call(line: str) -> Call | None:
    """The CALL statement of ``line``, or None when it holds none."""
    m = CALL.match(line)
    if m is None:
        return None
    rest = m.group(3).strip()
    q = _REPEATS.match(rest)
    return Call(m.group(2).upper(), int(q.group(1)) if q else 1, len(m.group(1)) + 1, "" if q or not rest else rest)


def name_line(lines: list[str], name: str) -> int | None:
    """The index of the line that starts subprogram ``O<name>`` in ``lines``, or None."""
    pattern = re.compile(_NAME.format(re.escape(name)))
    return next((k for k, ln in enumerate(lines) if pattern.match(ln)), None)


def find(name: str, folders: list[Path]) -> tuple[Path, int] | None:
    """The file and the name line of subprogram ``O<name>`` among the subprogram files
    (:data:`SUB_EXTENSIONS`) of ``folders``, searched in order, or None."""
    for folder in folders:
        try:
            files = sorted(p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in SUB_EXTENSIONS)
        except OSError:
            continue
        for f in files:
            raw = f.read_bytes()
            lines = split_lines(raw.decode("utf-8", errors="surrogateescape").lstrip("\ufeff"))
            k = name_line(lines, name)
            if k is not None:
                return f, k
    return None
