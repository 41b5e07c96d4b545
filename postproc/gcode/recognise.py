"""What kind of program this is: a lathe's, or another controller's than the one chosen.

postproc corrects milling machines. A lathe program is refused by name, with the words
that marked it, before a line is corrected: U/W words (incremental X/Z
of a Fanuc-style lathe), ``G50`` with S, X or Z (spindle clamp or coordinate setting),
``G7`` (LinuxCNC diameter mode), turning cycles ``G70``-``G76`` after ``G96`` (constant
surface speed), or an arc in X and Z with centre words I and K in a program that never
positions Y (a lathe reads G18 by default and writes X as a diameter).

A line that only another dialect's programs hold (a Sinumerik ``%_N_..._MPF`` header or
``DEF``, an Okuma ``$NAME.MIN%`` header, a Fadal ``N1 O2`` header, ...) is refused naming
the dialect to choose (item 6): the marks are data, :attr:`Dialect.marks`.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

from postproc.errors import UnsupportedGcodeError


class LatheProgramError(UnsupportedGcodeError):
    """A lathe program: postproc corrects milling machines only."""


LATHE_HINT = "correct lathe programs with the lathe's own compensation"
UVW_HINT = "; a milling program that uses U/V/W as axes is read with --dialect linuxcnc"


def lathe_message(marks: list[str]) -> str:
    return ("lathe program: postproc corrects milling machines only; marked as a lathe program by "
            + ", ".join(marks))


@dataclass
class LatheMarks:
    """The weak marks of a lathe program met so far (each alone is also a mill's)."""

    weak: list[str] = field(default_factory=list)

    def note(self, mark: str) -> None:
        if len(self.weak) < 4 and mark not in self.weak:
            self.weak.append(mark)

    def refusal(self, strong: str, path: str | None, lineno: int, col: int) -> LatheProgramError:
        hint = LATHE_HINT + (UVW_HINT if strong[:1] in ("U", "W") else "")
        return LatheProgramError(lathe_message([strong, *self.weak]), path=path, lineno=lineno, col=col, hint=hint)


def foreign_dialect(line: str, chosen: str) -> tuple[str, str, str] | None:
    """``(dialect name, its title, the construct)`` when ``line`` holds a mark that only
    another dialect's programs hold; None otherwise (also for the chosen dialect's own)."""
    from postproc.gcode.dialect import DIALECTS

    if not any(c in line for c in "%$;=ODdN"):
        return None
    for d in DIALECTS.values():
        if d.name == chosen:
            continue
        for pattern, construct in d.marks:
            if _compiled(pattern).search(line):
                return d.name, d.title, construct
    return None


_CACHE: dict[str, re.Pattern[str]] = {}


def _compiled(pattern: str) -> re.Pattern[str]:
    p = _CACHE.get(pattern)
    if p is None:
        p = _CACHE[pattern] = re.compile(pattern)
    return p


#: bytes read from the start of a program to choose its dialect
HEAD_BYTES = 4096


def dialect_of_file(path: str, chosen: str) -> str:
    """The dialect to read ``path`` in: ``chosen``, or, for ``generic``, the dialect whose
    header lines (:attr:`Dialect.chosen_by`, e.g. Sinumerik's ``%_N_..._MPF``) open it."""
    from postproc.gcode.dialect import DIALECTS, get
    from postproc.gcode.lexer import split_lines

    if not get(chosen).yields_to_headers:
        return chosen
    try:
        with open(path, "rb") as fh:
            head = fh.read(HEAD_BYTES).decode("utf-8", errors="replace")
    except OSError:
        return chosen  # the reader names the problem
    # its opening lines as the reader numbers them (a form feed is a blank inside a line)
    lines = split_lines(head.lstrip("\ufeff"))[:3]
    for d in DIALECTS.values():
        if d.chosen_by and any(_compiled(p).match(line) for p in d.chosen_by for line in lines):
            return d.name
    return chosen
