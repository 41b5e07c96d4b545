"""Writing numbers and editing lines without touching anything else.

Numbers are fixed point with explicit decimals, never exponent notation and never
``-0``; a line is edited only at the spans of the words that change, so every other
byte (spacing, comments, N numbers, line ending) is copied as it was.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterator
from itertools import chain, islice
from typing import TYPE_CHECKING, TypeAlias

from postproc import __version__
from postproc.gcode.numfmt import fmt as fmt  # the one formatter (compiled), re-exported
from postproc.gcode.runwords import edit_line as edit_line  # the one line editor, re-exported
from postproc.gcode.state import DWELL, RAPID

if TYPE_CHECKING:
    from postproc.gcode.interp import Cycle, Move
    from postproc.gcode.source import Setup

#: a G0/G1 step of an expanded canned cycle (cycle_lines): motion, from, to (machine mm),
#: the axes it names, whether it carries the block's F word
CycleStep: TypeAlias = tuple[int, tuple[float, float, float], tuple[float, float, float], tuple[int, ...], bool]

HEADER_TAG = "(postproc "
HEADER_MARK = " corrected "


def decimals_of(number_text: str) -> int:
    """Digits after the point in a word's raw number text (``"1.50"`` -> 2)."""
    _, dot, frac = number_text.partition(".")
    return len(frac) if dot else 0


def line_ending(line: str) -> str:
    if line.endswith("\r\n"):
        return "\r\n"
    if line.endswith("\n"):
        return "\n"
    if line.endswith("\r"):
        return "\r"
    return ""


def new_line_ending(line: str) -> str:
    """The ending of a line written beside ``line`` (a split move's pieces, a cycle's steps,
    a comment moved onto its own line, the header): ``line``'s own, but a lone CR becomes
    CR LF. A lone CR is how a CR CR LF ending reads here (the CR, then an empty line), and
    LinuxCNC ends a block only at LF: lines joined by CR alone would be one block to it."""
    ending = line_ending(line)
    return "\r\n" if ending == "\r" else ending or "\n"


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
    code = line.split("(", 1)[0].split(";", 1)[0]
    # every letter lower case (and at least one): the code part equals its lower case
    # and differs from its upper case
    lower = code.islower()
    return sep, lower


def header_line(name: str, sha256: str, tolerance_mm: float, setup_note: str, ending: str) -> str:
    """The one-line header of earlier versions (still read by :func:`is_header` and ``diff``)."""
    clean = "".join("[" if c == "(" else "]" if c == ")" else c for c in name if c.isprintable())[:60]
    text = (f"{HEADER_TAG}{__version__}{HEADER_MARK}with calibration {clean} sha256 {sha256} "
            f"tolerance {tolerance_mm:g} mm{'; ' + setup_note if setup_note else ''})")
    return text + (ending or "\n")


# -- the header of several short lines ---------------------------------------------------
# Every line is "(POSTPROC <WORDS>)": upper case, letters, digits, blanks and ". - +" only,
# so that every dialect reads it (no ";" or "," that a Fanuc link alarms on, no lower case,
# none longer than the shortest line any controller reads). The first line carries the
# version and CORRECTED: it marks the program as corrected.
HEADER_PREFIX = "(POSTPROC "
HEADER_LINE_CHARS = 96  # inside every dialect's line (generic: 127); the sha256 line needs 82
# a dialect without parenthesis comments (Sinumerik) reads the same lines as ";POSTPROC ..."
_HEADER_OPEN = re.compile(r"\s*(?:\(POSTPROC \S+ CORRECTED\)|;POSTPROC \S+ CORRECTED)\s*$", re.IGNORECASE)
_HEADER_ANY = re.compile(r"\s*(?:\(POSTPROC [A-Z0-9 .+\-]*\)|;POSTPROC [A-Z0-9 .+\-]*)\s*$", re.IGNORECASE)
# O1234, :1234, N1 O2 (Fadal), or Sinumerik's ;$PATH= line after its %_N_..._MPF
_PROGRAM_NUMBER = re.compile(r"[ \t]*(?:(?:[Nn][ \t]*\d+[ \t]*)?[Oo][ \t]*\d+|:[ \t]*\d+)[ \t]*(?:\([^)]*\)[ \t]*)*"
                             r"(?:;[^\r\n]*)?(?:\r\n|\n|\r)?$|[ \t]*;[ \t]*\$PATH[ \t]*=")
# the tape mark, or Okuma's file header $NAME.MIN% that stands in its place
_TAPE_MARK = re.compile(r"%|\$[^\r\n%]*%[ \t]*(?:\r\n|\n|\r)?$")
_HEADER_SAFE = re.compile(r"[^A-Z0-9 .+\-]")


def _safe(text: str) -> str:
    """Upper case, only letters, digits, blanks and ``. - +`` (others become blanks), blanks squeezed."""
    return " ".join(_HEADER_SAFE.sub(" ", text.upper()).split())


def _num(v: float) -> str:
    """The shortest text that reads back as the same float, without an exponent."""
    v = float(v)
    if not math.isfinite(v):
        raise ValueError(f"cannot write {v} into a header")
    text = repr(v)
    if "e" in text or "E" in text:
        text = f"{v:.17f}".rstrip("0").rstrip(".")
    if text.endswith(".0"):
        text = text[:-2]
    return "0" if text in ("-0", "") else text


def _setup_parts(setup_note: str, setup: Setup | None) -> list[str]:
    """The setup note as header words, one entry per part (offsets, tools, start, ...).
    With the ``setup`` itself, its numbers are written from it, exactly."""
    if setup is None:
        return _note_parts(setup_note, False, False)
    return _note_parts(setup_note, True, bool(getattr(setup, "home", None))) + _exact_parts(setup)


def _note_parts(setup_note: str, exact: bool, home: bool) -> list[str]:
    """The parts of the setup note; with ``exact``, those the setup writes (offsets,
    tools, start, tool vector; G28/G30 when it has ``home``) are left out."""
    parts: list[str] = []
    for raw in (p.strip() for p in setup_note.split(";") if p.strip()) if setup_note else ():
        m = re.fullmatch(r"(G5[0-9.]+|G15H\d+|E\d+)=([-+0-9.eE]+),([-+0-9.eE]+),([-+0-9.eE]+)", raw)
        if m:
            if not exact:
                parts.append(f"OFFSET {m.group(1)} X{_num(float(m.group(2)))} Y{_num(float(m.group(3)))} "
                             f"Z{_num(float(m.group(4)))}")
        elif raw.startswith("tools "):
            if not exact:
                pairs = [item.split("=") for item in raw[6:].split(",") if "=" in item]
                parts.append("TOOL LENGTHS " + " ".join(f"H{int(float(h))} {_num(float(v))}" for h, v in pairs))
        elif raw.startswith("start "):
            if not exact:
                parts.append("START " + " ".join(item for item in raw[6:].split(",") if item))
        elif (re.match(r"G(28|30)=", raw) and exact and home) or raw.lower().startswith("expanded"):
            continue  # written from the setup, exactly; the EXPANDED line of header_lines says it
        elif raw.startswith("tool vector "):
            if not exact:
                vals = raw[12:].split(",")
                parts.append("TOOL VECTOR " + " ".join(f"{a}{_num(float(v))}" for a, v in zip("XYZ", vals, strict=False)))
        else:
            parts.append(_safe(raw))
    return parts


def _exact_parts(setup: Setup) -> list[str]:
    """Offsets, tool lengths, start, G28/G30 positions and tool vector, from the setup."""
    parts: list[str] = []
    offs = setup.offsets or {}
    for k in sorted(offs):
        v = offs[k]
        if isinstance(v, dict):
            v = (v.get("X", 0.0), v.get("Y", 0.0), v.get("Z", 0.0))
        parts.append(f"OFFSET {_safe(k)} " + " ".join(f"{a}{_num(x)}" for a, x in zip("XYZ", v, strict=True)))
    if setup.tool_lengths:
        parts.append("TOOL LENGTHS " + " ".join(f"H{int(h)} {_num(v)}" for h, v in sorted(setup.tool_lengths.items())))
    if setup.start:
        from postproc.gcode.interp import start_position

        pos = start_position(setup.start)
        parts.append("START " + " ".join(f"{a}{_num(v)}" for a, v in zip("XYZ", pos, strict=True) if v == v))
    for name, v in sorted((getattr(setup, "home", None) or {}).items()):
        v = v if isinstance(v, dict) else dict(zip("XYZ", v, strict=True))
        parts.append(f"{_safe(name)} " + " ".join(f"{a}{_num(x)}" for a, x in sorted(v.items())))
    if getattr(setup, "variables", None):
        parts.append("VARIABLES " + " ".join(f"{int(k)} {_num(v)}" for k, v in sorted(setup.variables.items())))
    if setup.tool_vector is not None:
        parts.append("TOOL VECTOR " + " ".join(f"{a}{_num(x)}" for a, x in zip("XYZ", setup.tool_vector, strict=True)))
    return parts


_KEYWORDS = {"TOOL LENGTHS": 2, "VARIABLES": 1, "TOOL VECTOR": 2, "OFFSET": 2, "START": 1, "CALIBRATION": 1, "SHA256": 1,
             "MAP": 1}


def _wrap(words: str, width: int) -> list[str]:
    """Split header words into lines of at most ``width`` characters, comment marks included.
    A continued line repeats the part's keyword (``TOOL LENGTHS``, ``OFFSET G54``, ...), so
    each line reads on its own."""
    items = words.split()
    if not items:
        return []
    keep = next((n for k, n in _KEYWORDS.items() if words.startswith(k + " ")), 0)
    lead = " ".join(items[:keep])
    room = width - len(HEADER_PREFIX) - 1
    lines: list[str] = []
    cur = ""
    body = items[keep:] if keep else items
    if words.startswith(("TOOL LENGTHS ", "VARIABLES ")):  # "H1 100.5", "5405 12.5": a pair stays on one line
        body = [" ".join(body[i:i + 2]) for i in range(0, len(body), 2)]
    for w in body:
        base = lead if keep else ""
        while len(w) > room - len(base) - 1:  # a word longer than a line (a long name): cut it
            cut = max(1, room - len(base) - 1)
            if cur:
                lines.append(cur)
                cur = ""
            lines.append(f"{base} {w[:cut]}".strip())
            w = w[cut:]
        if not cur:
            cur = f"{base} {w}".strip()
        elif len(cur) + 1 + len(w) <= room:
            cur += " " + w
        else:
            lines.append(cur)
            cur = f"{base} {w}".strip()
    if cur:
        lines.append(cur)
    return [f"{HEADER_PREFIX}{t})" for t in lines]


def header_lines(dialect: str, calibration: tuple[str, str], tolerance_mm: float, setup_note: str, ending: str,
                 expanded: bool = False, setup: Setup | None = None, cycles_expanded: bool = False) -> list[str]:
    """The comment lines that open every corrected program (and mark it as corrected).

    Each is a short ``(POSTPROC ...)`` comment that ``dialect`` accepts (length, case,
    characters; checked line by line). They carry the version, the calibration's name and
    sha256 (``calibration``), the tolerance, the setup (``setup_note`` as the pipeline writes it; when
    ``setup`` is given, offsets, tool lengths, start and tool vector are written from it
    exactly), EXPANDED when subprograms or macros were expanded and CYCLES EXPANDED when
    canned cycles are written as their moves (``--cycles expand``).
    Each line ends with ``ending`` (``"\r\n"`` for a lone ``"\r"``).
    """
    from postproc.gcode import dialect as dialects

    d = dialects.get(dialect)
    width = min(HEADER_LINE_CHARS, d.max_line_chars)
    # a lone carriage return ends no line for LinuxCNC or Grbl (they read up to "\n"): the
    # header would join the next line. "\r\n" ends a line for every reader.
    end = "\r\n" if ending == "\r" else (ending or "\n")
    body = [f"{HEADER_PREFIX}{_safe(__version__)} CORRECTED)"]
    cal_name, cal_sha = calibration
    body += _wrap("CALIBRATION " + (_safe(cal_name) or "UNNAMED"), width)
    body += _wrap("SHA256 " + _safe(cal_sha), width)
    body += _wrap(f"TOLERANCE {_num(tolerance_mm)} MM", width)
    expanded = expanded or any(p.strip().lower().startswith("expanded") for p in (setup_note or "").split(";"))
    for part in _setup_parts(setup_note, setup):
        body += _wrap(part, width)
    if expanded:
        body += _wrap("EXPANDED SUBPROGRAMS LOOPS AND MACROS", width)
    if cycles_expanded:
        body += _wrap("CYCLES EXPANDED", width)
    if not d.paren_comments:
        body = [";" + line[1:-1] for line in body]
    for k, line in enumerate(body, start=1):
        dialects.check_output_line(d, line, path="<header>", lineno=k)
    return [line + end for line in body]


def is_header(line: str) -> bool:
    """Is ``line`` a postproc header line? The old one-line header, or any line of the new
    one (``(POSTPROC ...)``, in any case)."""
    s = line.lstrip("\ufeff \t")
    if s.startswith(HEADER_TAG) and HEADER_MARK in s:
        return True
    return s[:10].upper() in (HEADER_PREFIX, ";POSTPROC ") and bool(_HEADER_ANY.match(s))


def is_header_start(line: str) -> bool:
    """The line that opens a header: the old one-line header or ``(POSTPROC <version> CORRECTED)``."""
    s = line.lstrip("\ufeff \t")
    return (s.startswith(HEADER_TAG) and HEADER_MARK in s) or bool(_HEADER_OPEN.match(s))


def start_lines(it: Iterator[str]) -> tuple[list[str], int]:
    """The first lines of a program, read from ``it`` (one past those kept), and how many of
    them stay before the header: blank lines before a '%' tape mark (LinuxCNC wants '%'
    first of the non-blank lines), the '%' and the program number (O1234, O0001 (NAME),
    :1234), which Fanuc and Haas controls need first. The one rule for where ``correct``
    writes its header and where ``diff`` and :func:`split_header` find it."""
    head = list(islice(it, 1))
    keep = 0
    while len(head) > keep and not head[keep].lstrip("\ufeff").strip() and keep < 20:
        keep += 1
        head.extend(islice(it, 1))
    if len(head) > keep and _TAPE_MARK.match(head[keep].lstrip("\ufeff").strip()):
        keep += 1
        head.extend(islice(it, 1))
    elif keep:
        keep = 0  # blank lines without a '%' after them: the header goes first as before
    if len(head) > keep and _PROGRAM_NUMBER.match(head[keep].lstrip("\ufeff")):
        keep += 1
        head.extend(islice(it, 1))
    return head, keep


def header_run(it: Iterator[str]) -> tuple[list[str], list[str], str | None]:
    """Read from ``it`` the lines :func:`start_lines` keeps before the header, the run of
    header lines after them (several headers for a program corrected more than once), and
    the first line after those (None at the end): ``(kept, header, after)``. ``it`` goes
    on after that line."""
    head, keep = start_lines(it)
    header: list[str] = []
    for line in chain(head[keep:], it):
        if not is_header(line):
            return head[:keep], header, line
        header.append(line)
    return head[:keep], header, None


def split_header(text: str) -> tuple[list[str], str]:
    """``(header lines, the rest)`` of a corrected program's text (:func:`header_run`;
    the lines kept before the header stay in the rest)."""
    from postproc.gcode.lexer import split_lines

    it = iter(split_lines(text))  # as the reader numbers them: a form feed is a blank inside a line
    kept, header, after = header_run(it)
    return header, "".join(kept + ([] if after is None else [after]) + list(it))


def cycle_lines(line: str, mv: Move, c: Cycle, retract: bool = True) -> list[str | CycleStep]:
    """The lines a canned cycle block (``line``, its Move ``mv`` and Cycle ``c``) is written
    as when expanded (``--cycles expand``), in order: the text of a line that moves nothing
    (the block's modal words, G98/G99 unless not ``retract``, and before-motion words, a G4 dwell), or ``(kind, prev, q, axes,
    first_feed)`` for a G0/G1 step from ``prev`` to ``q`` (machine mm) naming ``axes``
    (those that change), with the block's F word when ``first_feed``. ``diff`` reads an
    original's cycle blocks so when the corrected program says CYCLES EXPANDED."""
    ending = new_line_ending(line)
    sep, lower = style_of(line)
    sep = sep or " "
    out: list[str | CycleStep] = []
    # the block's modal words, its G98/G99 when ``retract`` (a cycle kept later in the
    # program uses the retract mode; with every cycle expanded, none does) and the words
    # acting before its motion, on a line of their own
    modes = [f"G{w.number}" for w in mv.words if w.letter == "G" and w.number.lstrip("0") in ("98", "99")]
    prefix = mv.prefix_words + (modes if retract else [])
    if prefix:
        text = sep.join(prefix)
        out.append((text.lower() if lower else text) + ending)
    prev = mv.q0
    feed_done = False
    for kind, q in c.steps:
        if kind == DWELL:
            text = f"G4{sep}P{fmt(q[0], 4).rstrip('0').rstrip('.') or '0'}"
            out.append((text.lower() if lower else text) + ending)
            continue
        first_feed = kind != RAPID and not feed_done
        feed_done = feed_done or first_feed
        out.append((kind, prev, q, tuple(k for k in range(3) if q[k] != prev[k]), first_feed))
        prev = q
    return out


def limit_pattern(dialect: str) -> re.Pattern[str]:
    """A pattern that finds, in a text of lines, the first one that may pass ``dialect``'s
    limits (longer than its characters of words, or of line): :func:`fit_line` decides."""
    from postproc.gcode import dialect as dialects

    d = dialects.get(dialect)
    n = min(d.max_line_chars, d.max_word_chars or d.max_line_chars)
    return re.compile(rf"^[^\n]{{{n + 1},}}", re.M)


def _over_limit(d, body: str) -> tuple[int, str] | None:
    """``(column, what)`` where ``body`` (a line without its ending) passes ``d``'s line
    or word limit, else None."""
    from postproc.gcode import dialect as dialects

    count = len(body.encode("utf-8", errors="surrogateescape"))
    if count > d.max_line_chars:
        return d.max_line_chars + 1, f"line of {count} characters, more than {d.title} reads ({d.max_line_chars})"
    if d.max_word_chars is not None:
        spans, pos = [], 0
        for start, text, kind in dialects.comments_of(body.rstrip("\r")):
            spans.append((pos, start))
            pos = len(body) if kind in (";", "unclosed") else start + len(text) + 2
        spans.append((pos, len(body)))
        cols = [k for a, b in spans for k in range(a, b) if body[k] > " "]
        if len(cols) > d.max_word_chars:
            return cols[d.max_word_chars] + 1, (f"{len(cols)} characters of words on one line, more than {d.title} "
                                                f"holds ({d.max_word_chars})")
    return None


def fit_line(dialect: str, line: str) -> tuple[list[str], tuple[int, str] | None]:
    """The lines a written ``line`` (with its ending) becomes under ``dialect``'s limits:
    ``[line]`` when it is within them; its comments on a line of their own before its
    words when that brings both within them (a controller acts on a block's comments
    before its motion, so they mean the same there); else ``[line]`` and the column and
    reason of the excess (the caller refuses it)."""
    from postproc.gcode import dialect as dialects

    d = dialects.get(dialect)
    ending = line_ending(line)
    body = line[:len(line) - len(ending)]
    over = _over_limit(d, body)
    if over is None:
        return [line], None
    comments = [(start, body[start:] if kind in (";", "unclosed") else body[start:start + len(text) + 2])
                for start, text, kind in dialects.comments_of(body) if kind != "nested"]
    if not comments:
        return [line], over
    words = body
    for start, text in reversed(comments):
        words = words[:start] + words[start + len(text):]
    words = re.sub(r"[ \t]+", " ", words).strip(" \t")
    note = " ".join(text for _s, text in comments)
    end = new_line_ending(line)
    if not words or _over_limit(d, words) or _over_limit(d, note):
        return [line], over
    return [note + end, words + ending], None


def drill_cycle_lines(line: str, call_line: bool, mv: Move | None, cyc: Move | None,
                      motion: int | None) -> list[str | CycleStep | None]:
    """The lines a Sinumerik block that calls a drilling cycle, or runs the modal one, is
    written as (``--cycles expand``): the call as a ``;`` comment, or None for the block
    itself (a position block, ``mv``), then the cycle ``cyc``'s steps as :func:`cycle_lines`
    gives them (a dwell as ``G4 F<s>``), then the program's G1/G2/G3 again when ``motion``
    is not G0 (the cycle restores the G codes). ``diff`` reads an original so."""
    out: list[str | CycleStep | None] = []
    if call_line:
        out.append(";" + line)
    elif mv is not None:
        out.append(None)
    if cyc is None or cyc.cycle is None:
        return out
    ending = new_line_ending(line)
    sep, lower = style_of(line)
    sep = sep or " "
    prev = cyc.q0
    for kind, q in cyc.cycle.steps:
        if kind == DWELL and isinstance(q[0], str):  # a line of the cycle written as it is (F, M5, SPOS=)
            out.append((q[0].lower() if lower else q[0]) + ending)
            continue
        if kind == DWELL:
            text = f"G4{sep}F{fmt(q[0], 3).rstrip('0').rstrip('.') or '0'}"
            out.append((text.lower() if lower else text) + ending)
            continue
        moved = tuple(k for k in range(3) if q[k] != prev[k])
        if moved:
            out.append((kind, prev, q, moved, False))
            prev = q
    if motion is not None and motion != RAPID:
        text = f"G{motion // 10}"  # the program's G1/G2/G3 again after the cycle's G0 retract
        out.append((text.lower() if lower else text) + ending)
    return out
