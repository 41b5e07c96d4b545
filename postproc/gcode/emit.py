"""Writing numbers and editing lines without touching anything else.

Numbers are fixed point with explicit decimals, never exponent notation and never
``-0``; a line is edited only at the spans of the words that change, so every other
byte (spacing, comments, N numbers, line ending) is copied as it was.
"""

from __future__ import annotations

import math

from postproc import __version__

# half of the last written digit, by number of decimals (a program's numbers may carry
# any number of them; beyond 323 the half unit is below the smallest double, 0.0)
HALF_UNIT = {d: 0.5 * 10.0 ** (-d) for d in range(0, 330)}

HEADER_TAG = "(postproc "
HEADER_MARK = " corrected "


def fmt(value: float, decimals: int) -> str:
    """Fixed-point text of ``value`` with ``decimals`` digits; ``-0.000`` becomes ``0.000``."""
    text = "%.*f" % (decimals, value)  # noqa: UP031  (the fastest fixed-point formatting)
    if text[0] == "-" and not text.strip("-0."):
        return text[1:]
    if not math.isfinite(value):
        raise ValueError(f"cannot write {value} into a program")
    return text


def decimals_of(number_text: str) -> int:
    """Digits after the point in a word's raw number text (``"1.50"`` -> 2)."""
    _, dot, frac = number_text.partition(".")
    return len(frac) if dot else 0


def edit_line(line: str, edits: list[tuple[int, int, str]]) -> str:
    """Replace ``line[start:end]`` by text for each (start, end, text); spans must not overlap."""
    if not edits:
        return line
    out = []
    pos = 0
    if len(edits) > 1:
        edits = sorted(edits)
    for start, end, text in edits:
        out.append(line[pos:start])
        out.append(text)
        pos = end
    out.append(line[pos:])
    return "".join(out)


def line_ending(line: str) -> str:
    if line.endswith("\r\n"):
        return "\r\n"
    if line.endswith("\n"):
        return "\n"
    if line.endswith("\r"):
        return "\r"
    return ""


def removal_spans(line: str, words: list[tuple[int, int]]) -> list[tuple[int, int]]:
    """Spans deleting the words ``[(letter_pos, end), ...]`` and one run of blanks each:
    the blanks after a run of removed words, or before it when no word follows."""
    out = []
    runs: list[list[int]] = []
    for lpos, end in sorted(words):
        if runs and not line[runs[-1][1]:lpos].strip(" \t"):
            runs[-1][1] = end
        else:
            runs.append([lpos, end])
    for start, end in runs:
        stop = end
        while stop < len(line) and line[stop] in " \t":
            stop += 1
        if stop > end and stop < len(line) and line[stop] not in "\r\n;(":
            out.append((start, stop))
            continue
        while start > 0 and line[start - 1] in " \t":
            start -= 1
        out.append((start, end))
    return out


def style_of(line: str) -> tuple[str, bool]:
    """(separator between words, lower-case letters?) to match a line's own style."""
    sep = " " if (" " in line or "\t" in line) else ""
    letters = [c for c in line.split("(")[0].split(";")[0] if c.isalpha()]
    lower = bool(letters) and all(c.islower() for c in letters)
    return sep, lower


def header_line(name: str, sha256: str, tolerance_mm: float, setup_note: str, ending: str) -> str:
    """The comment that opens every corrected program (and marks it as corrected)."""
    clean = "".join("[" if c == "(" else "]" if c == ")" else c for c in name if c.isprintable())[:60]
    text = (f"{HEADER_TAG}{__version__}{HEADER_MARK}with calibration {clean} sha256 {sha256} "
            f"tolerance {tolerance_mm:g} mm{'; ' + setup_note if setup_note else ''})")
    return text + (ending or "\n")


def is_header(line: str) -> bool:
    s = line.lstrip()
    return s.startswith(HEADER_TAG) and HEADER_MARK in s
