"""Expansion of parameters, expressions, O-word control, subprograms and macros.

A streaming preprocessor that runs before the modal interpreter and turns a program
that uses LinuxCNC parameters/O-words or Fanuc M98/M99 and custom macro B into a
*flat* program: every executed line once per execution, expressions evaluated to
numbers, control lines consumed. A line holding no expression, parameter or control
is yielded with its original bytes (``SourceLine.original``).

LinuxCNC control flow is executed the way ``interp_o_word.cc`` does it: one global
"skipping to o-word NAME" state, a table of o-word positions filled as they are met,
``executed_if`` / ``doing_break`` / ``doing_continue`` flags, subroutines found in the
file (forward search) or as ``<name>.ngc`` on the subroutine path. Fanuc/Haas
programs (``dialect="fanuc"``/``"haas"``, or ``"generic"`` when the program uses
macro B statements) are executed with Fanuc's rules: subprograms ``O1000 ... M99``
found by number anywhere in the file, ``M98`` sharing local variables, ``G65``
opening a new local level with the arguments of Argument specification I, ``GOTO``
searching forward then from the start of the program, vacant variables.

Values that only the running machine knows (probe results, current position and
tool, HAL pins, Fanuc system variables, retained #500-#999, coordinate-system
parameters not set by the program) are refused with ``path:line:col``.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path
from typing import Any

from postproc.errors import GcodeSyntaxError, PostprocError
from postproc.gcode.dialect import get as get_dialect
from postproc.gcode.expand_flow import Flow
from postproc.gcode.expand_state import (
    ExpansionError as ExpansionError,  # the public error of expand()
)
from postproc.gcode.expand_state import Stop, oname
from postproc.gcode.expand_syntax import (
    CANDIDATE,
    Block,
    SourceLine,
    Unit,
    Word,
    candidate_lines,
    first_code_line,
    is_fanuc,
    parse_block,
    plain_value,
    strip_comments,
)
from postproc.gcode.expr import (
    NULL,
    format_number,
)
from postproc.gcode.lexer import scan_words
from postproc.limits import (
    DEFAULT_MAX_ITERATIONS,
    LINES_PER_ITERATION,
    ResourceLimitError,
    flat_program_too_long,
)

# The flat program of the dry run (max_lines_out) is held, and yielded instead of running
# the expansion again, up to this many lines (about 150 bytes each: 30 MB); a longer
# one is run again.
KEPT_LINES = 200_000
_M_SPECIAL = (2.0, 30.0, 97.0, 98.0, 99.0)
_G_SPECIAL = (65.0, 66.0)
_LINE_END = re.compile(r"(\r\n|\n|\r)$")

# ---------------------------------------------------------------------------
# Public types
# ---------------------------------------------------------------------------




def needs_expansion(lines: Sequence[str], dialect: str = "generic") -> bool:
    """True when a line uses parameters, expressions, O-word control or subprograms.

    A program-number line (``O1234``, ``:1234``) or ``%`` alone does not count:
    :func:`expand` would yield such a program unchanged up to its M2/M30.
    """
    candidates = candidate_lines(lines)
    fanuc = is_fanuc(lines, dialect, candidates)
    for k in candidates:
        line = lines[k]
        code = strip_comments(line)
        if not CANDIDATE.search(code):
            continue
        try:
            b = parse_block(line, fanuc=fanuc, path=None, lineno=k + 1,
                            nested_comments=not get_dialect(dialect).nested_comment_error)
        except PostprocError:
            if "#" in code or "[" in code:
                return True  # a broken expression: let expand() report it with its place
            continue  # not G-code an expansion would touch (e.g. text after the program end)
        if b.oword is not None:
            if b.oword.kw == "" and not any(True for _ in b.items) and first_code_line(lines) == k:
                continue
            return True
        if b.macro is not None or not b.plain:
            return True
        for w in b.words:
            v = plain_value(w)
            if (w.letter == "M" and v in ((97.0, 98.0, 99.0) if fanuc else (98.0, 99.0))) or (
                    w.letter == "G" and v in (65.0, 66.0)):
                return True
    return False



class _Expander(Flow):
    """The expansion's line driver: each line of the running unit read, its statements
    executed by the layers below, and the flat program's lines yielded."""

    # -- main loop ----------------------------------------------------------
    def run(self) -> Iterator[SourceLine]:
        percent_open = False
        first_code = True
        while True:
            unit = self.unit
            if self.idx >= len(unit.lines):
                self._end_of_file()
                return
            idx = self.idx
            self.idx += 1
            self.cur_idx = idx
            self.unit_cur = unit
            self.executed += 1
            if self.executed > self.max_lines:
                raise self._too_many_lines()
            if self.skipping_o is not None or self.skipping_to_sub is not None:
                self._skipped_line(unit, idx)
                continue
            own = self._dialect_line(unit, idx, unit.lines[idx], first_code)
            if own is not None:
                yield from own
                continue
            kind = unit.kinds[idx]
            if kind is None:
                kind = unit.kinds[idx] = _line_kind(unit, idx)
            if kind is _PERCENT:
                if unit is self.main:  # a subprogram file's own tape marks stay out of the flat program
                    yield unit.source_line(idx)
                    if percent_open:
                        return
                    percent_open = True
                continue
            if kind is not _STATEMENT:  # a line of plain words (most CAM output), or none: as it is
                first_code = first_code and kind is _NO_WORDS
                yield unit.source_line(idx)
                continue
            line = unit.lines[idx]
            b = self._block_of(unit, idx, line)
            if first_code and unit is self.main and _opens_program(b):
                first_code = False
                yield SourceLine(idx + 1, unit.path, line, True)
                continue
            if b.program_number is not None:
                if len(self.frames) == 1:
                    return  # the main program ran into the next program in the file
                continue
            first_code = first_code and not (b.items or b.oword or b.macro)
            try:
                if b.oword is not None:
                    self._oword(b, b.oword)
                elif b.macro is not None:
                    self._macro(b, b.macro)
                else:
                    yield from self._block(b, line)
            except Stop:
                break  # the program's end (M2/M30, M99 ending the main program)
        yield from self._closing_percent()

    def _block_of(self, unit: Unit, idx: int, line: str) -> Block:
        """The parsed block of line ``idx``; a line the parser cannot read that holds a
        construct the dialect refuses by name (its ``refused`` list, as the interpreter reads
        it) is refused in those words."""
        try:
            return unit.block(idx)
        except GcodeSyntaxError:
            for pattern, construct, instead in self.d.refused:
                m = re.search(pattern, line)
                if m:
                    raise self.refuse(m.start() + 1, f"{self.d.title.split(' ')[0]} {construct.format(*m.groups())}",
                                      hint=instead) from None
            raise

    def _dialect_line(self, unit: Unit, idx: int, line: str, first_code: bool) -> tuple[SourceLine, ...] | None:
        """The lines a line of the dialect's own forms leaves in the flat program, or None for
        any other line: its header ("$NAME.MIN%", the interpreter's header forms) as it is
        in the main program (a subprogram file's header stays out), nothing for a CALL O or
        RTS statement (the flat program holds the subprogram's lines)."""
        if self.header_forms and any(p.match(line) for p in self.header_forms):
            return (SourceLine(idx + 1, unit.path, line, True),) if unit is self.main and first_code else ()
        if self.d.call_o_statement and self._okuma_statement(line):
            return ()
        return None

    def _okuma_statement(self, line: str) -> bool:
        """Run ``CALL O<name> [Q<n>]`` (the subprogram from the program's own file, then from
        the .SSB/.SUB/.LIB files beside the program and on the subroutine path) or its ``RTS``
        (:mod:`postproc.gcode.okuma`); whether ``line`` was one of them."""
        from postproc.gcode import okuma

        if okuma.RTS.match(line):
            fr = self.frames[-1]
            if fr.call_type != "call-o":
                raise self.error(1, "Okuma RTS outside a subprogram called with CALL O..",
                                 hint="end the main program with M02 or M30")
            if fr.repeats_left > 0 and fr.start_unit is not None:
                self.count_iteration(1)
                fr.repeats_left -= 1
                self.unit, self.idx = fr.start_unit, fr.start_idx
            else:
                self._leave(fr)
            return True
        call = okuma.read_call(line)
        if call is None:
            bad = okuma.BAD_CALL.match(line)
            if bad is not None:
                raise self.refuse(bad.start(1) + 1, f"Okuma CALL {bad.group(1)}: a subprogram name is O and letters "
                                  "or digits, looked up in the subprogram files by name, never as a path",
                                  hint="call the subprogram by its name, and give its file's folder with "
                                  "--subroutine-path")
            return False
        if call.arguments:
            raise self.refuse(call.col, f"Okuma CALL O{call.name} with arguments ({call.arguments}): the "
                              "subprogram's local variables are not read",
                              hint="post the subprogram with numbers in place of its variables, called without "
                              "arguments")
        k = okuma.name_line(self.main.lines, call.name)
        unit = self.main
        if k is None:
            folders = ([Path(self.main.path).parent] if self.main.path else []) + self.subroutine_path
            found = okuma.find(call.name, folders)
            if found is None:
                raise self.error(call.col, f"Okuma CALL O{call.name}: subprogram O{call.name} not found in the "
                                 "program or in a .SSB/.SUB/.LIB file beside it or on --subroutine-path",
                                 hint="give the folder of the file that holds it with --subroutine-path")
            unit, k = self.load_file(found[0]), found[1]
        if call.repeats > 0:
            self._enter("call-o", f"O{call.name}", unit, k + 1, call.repeats - 1)
        return True

    def _too_many_lines(self) -> ResourceLimitError:
        return ResourceLimitError(
            f"the program runs more than {self.max_lines} lines: an endless loop or recursion? (the bound "
            f"is {LINES_PER_ITERATION} lines for each pass --max-iterations allows)", path=self.unit_cur.path,
            lineno=self.cur_idx + 1, col=1,
            hint="check the loop conditions and subprogram returns, or raise --max-iterations")

    def _skipped_line(self, unit: Unit, idx: int) -> None:
        """A line met while skipping (LinuxCNC): only the o-word line the skip is looking
        for ends it (``skipping_to_sub``: the sub or label called; ``skipping_o``: the
        o-word that closes the skipped block)."""
        if self.fanuc or not unit.maybe_oword(idx):
            return
        b = unit.block(idx)
        if b.oword is None:
            return
        target = self.skipping_to_sub or self.skipping_o
        if b.oword.name == target and (self.skipping_to_sub is None or b.oword.kw in ("sub", "")):
            self._oword(b, b.oword)

    def _closing_percent(self) -> Iterator[SourceLine]:
        """After the program's end: the main file's closing '%' line, when it comes later
        in the file."""
        last = _last_code_line(self.main.lines)
        if last is not None and self.main.lines[last].strip().startswith("%") and last > self.cur_idx:
            yield SourceLine(last + 1, self.main.path, self.main.lines[last], True)

    def _end_of_file(self) -> None:
        if self.defining_sub is not None and self.skipping_o == self.defining_sub:
            unit, idx = self.skip_from or (self.unit, self.idx)
            name = self.defining_sub
            raise GcodeSyntaxError(
                f"'o{oname(name)} sub' has no matching 'o{oname(name)} endsub'",
                path=unit.path, lineno=idx + 1, col=1,
                hint=f"end the subroutine with 'o{oname(name)} endsub'")
        skipping = self.skipping_to_sub if self.skipping_to_sub is not None else self.skipping_o
        if skipping is not None:
            unit, idx = self.skip_from or (self.unit, self.idx)
            if self.skipping_to_sub is not None:
                raise GcodeSyntaxError(
                    f"subroutine o{oname(skipping)} not found: neither in the file nor as {skipping}.ngc on "
                    "the subroutine path", path=unit.path, lineno=idx + 1, col=1,
                    hint=f"define 'o{oname(skipping)} sub' in the file or put {skipping}.ngc on --subroutine-path")
            ow = unit.block(idx).oword
            kw = ow.kw if ow is not None else ""
            raise GcodeSyntaxError(
                f"'o{oname(skipping)} {kw}': the file ended before the o{oname(skipping)} line that closes it",
                path=unit.path, lineno=idx + 1, col=1,
                hint="close the block with its matching o-word line (endif, endwhile, endrepeat, while)")
        self._refuse_open_block()
        if len(self.frames) > 1:
            fr = self.frames[-1]
            raise GcodeSyntaxError(
                f"subprogram {fr.sub_name} ended without its return (endsub/M99)",
                path=fr.call_path, lineno=fr.call_lineno, col=1,
                hint="end the subprogram with 'o<name> endsub' or M99")

    def _refuse_open_block(self) -> None:
        """The file ran to its end (no M2/M30, no closing '%') inside an o-word loop or if
        that no line of it closes: refused, as rs274 refuses such a file ("File ended with
        no percent sign or program end"); a truncated file most often. (A block left
        open by M2 inside it ends the program as on the controller, and is not refused.)"""
        unit = self.unit
        closers = {"while": ("endwhile",), "repeat": ("endrepeat",), "if": ("endif",), "do": ("while",)}
        for name, op in self.offsets.items():
            if op.unit is not unit or op.kind not in closers:
                continue
            closed = any(unit.maybe_oword(k) and (ow := unit.block(k).oword) is not None and ow.name == name
                         and ow.kw in closers[op.kind] for k in range(op.idx + 1, len(unit.lines)))
            if not closed:
                raise GcodeSyntaxError(
                    f"'o{oname(name)} {op.kind}' is never closed: the file ends inside it, with no M2/M30 or "
                    "closing '%' before", path=unit.path, lineno=op.idx + 1, col=1,
                    hint=f"close it with its o{oname(name)} {closers[op.kind][0]} line (is the file complete?)")

    # -- ordinary blocks ------------------------------------------------------
    def _block(self, b: Block, line: str) -> Iterator[SourceLine]:
        unit, idx = self.unit_cur, self.cur_idx
        if b.settings_only and not b.slash:  # settings alone (most lines of a loop's body): nothing to write
            self._item_values(b)
            return
        if len(b.items) == 1 and len(self.frames) > 1 and b.plain and b.items[0].letter == "M" and (
                float(b.items[0].raw) == 99.0):  # M99 alone, ending a subprogram's pass
            self._m99(None)
            return
        if b.plain:
            m_codes = [float(w.raw) for w in b.items if w.letter == "M"]
            g_codes = [float(w.raw) for w in b.items if w.letter == "G"]
            if not any(m in self.call_m_codes for m in m_codes) and 65.0 not in g_codes and (
                    66.0 not in g_codes):
                yield SourceLine(idx + 1, unit.path, line, True)
                if any(m in (2.0, 30.0) for m in m_codes):
                    raise Stop
                return
        if b.slash and b.assigns:
            raise self.refuse(1, "a parameter setting on a block-delete ('/') line: whether it runs depends on "
                              "the operator's block-delete switch", hint="remove the '/' or the setting")
        values = self._item_values(b)
        words = [(w, v) for w, v in zip(b.items, values, strict=True) if isinstance(w, Word)]
        by_letter: dict[str, list[float]] = {}
        for w, v in words:
            if v is not NULL:
                by_letter.setdefault(w.letter, []).append(v)
        m_codes = by_letter.get("M", [])
        g_codes = by_letter.get("G", [])
        call = None
        drop: set[int] = set()
        if any(m in self.call_m_codes for m in m_codes) or 65.0 in g_codes:
            call, drop = self._call_words(words, m_codes, g_codes)
        if 66.0 in g_codes:
            w = next(w for w, v in words if w.letter == "G" and v == 66.0)
            raise self.refuse(w.col, "G66 modal macro call is not supported",
                              hint="call the macro with G65 at each position")
        edits, kept = self._edits(b, words, drop)
        if kept or (not b.assigns and call is None):
            if edits:
                text = _apply_edits(line, edits)
                yield SourceLine(idx + 1, unit.path, text, False)
            else:
                yield SourceLine(idx + 1, unit.path, line, True)
        if any(m in (2.0, 30.0) for m in m_codes) or (99.0 in m_codes and call is None and len(self.frames) == 1):
            raise Stop
        if call is not None:
            call()

    def _item_values(self, b: Block) -> list:
        """The value of each item of ``b`` in source order: a word's number (or NULL), None
        for a setting. Settings are applied after the line (rs274ngc), each one at once in Fanuc."""
        values: list = []
        self.pending = []
        self.pending_names = set()
        for it in b.items:
            if isinstance(it, Word):
                values.append(float(it.raw) if it.node is None else self._value(it.node))
                continue
            v = self._value(it.node)
            if v is not NULL and not self.fanuc:
                v = float(v)
            self._queue_setting(it, v)
            values.append(None)
            if self.fanuc:
                self._apply_pending()
        self._apply_pending()
        return values

    def _edits(self, b: Block, words: list[tuple[Word, Any]], drop: set[int]) -> tuple[list[tuple[int, int, str]], int]:
        """How the line of ``b`` is rewritten (``(start, end, text)`` replacements: computed
        values written, settings, vacant words and the call words ``drop`` removed) and the
        number of words it keeps besides N."""
        edits: list[tuple[int, int, str]] = []
        kept = 0
        for k, (w, v) in enumerate(words):
            if k in drop or v is NULL:
                edits.append((w.letter_at, w.span[1], ""))
                continue
            if w.letter != "N":
                kept += 1
            if w.node is not None:
                if not math.isfinite(v):
                    raise self.error(w.col, f"value of {w.letter} is not a finite number")
                edits.append((w.span[0], w.span[1], format_number(v, w.letter)))
        for a in b.assigns:
            edits.append((a.span[0], a.span[1], ""))
        return edits, kept



# What a line is to the main loop (Unit.kinds, found once a line): plain words, yielded as
# they are; blanks and comments only, idem; a '%' line; anything else, parsed as a Block.
_WORDS, _NO_WORDS, _PERCENT, _STATEMENT = "words", "no words", "percent", "statement"


def _line_kind(unit: Unit, idx: int) -> str:
    """What line ``idx`` of ``unit`` is to :meth:`_Expander.run` (the scanner's fast path)."""
    line = unit.lines[idx]
    words = scan_words(line)
    if words is not None and not any(
            letter == "O" or (letter == "M" and float(num) in _M_SPECIAL)
            or (letter == "G" and float(num) in _G_SPECIAL) for letter, num, *_ in words):
        return _WORDS if words else _NO_WORDS
    if line.strip().startswith("%"):
        return _PERCENT
    return _STATEMENT


def _opens_program(b: Block) -> bool:
    """A program-number line (Fanuc ``O1234``, ``:1234``) or a bare LinuxCNC ``o100``."""
    return b.program_number is not None or (b.oword is not None and b.oword.kw == "")





def _apply_edits(line: str, edits: list[tuple[int, int, str]]) -> str:
    out = []
    pos = 0
    for a, b, rep in sorted(edits):
        if rep == "":
            while a > pos and line[a - 1] in " \t":  # take the blanks before a removed item
                a -= 1
        out.append(line[pos:a])
        out.append(rep)
        pos = b
    out.append(line[pos:])
    text = "".join(out)
    m = _LINE_END.search(text)
    ending = m.group(1) if m else ""
    body = text[: len(text) - len(ending)]
    if line[:1] not in " \t":
        body = body.lstrip(" \t")
    if not body.strip():
        body = ""
    return body + ending


def _last_code_line(lines: list[str]) -> int | None:
    for k in range(len(lines) - 1, -1, -1):
        if lines[k].strip():
            return k
    return None


def expand(lines: Iterable[str], *, path: str | None = None, dialect: str = "generic",
           subroutine_path: Sequence[Path] = (), max_lines: int | None = None,
           max_iterations: int = DEFAULT_MAX_ITERATIONS,
           variables: dict[int, float] | None = None, max_lines_out: int | None = None) -> Iterator[SourceLine]:
    """Execute the program's control flow and yield the flat program line by line.

    ``lines`` are the source lines with their endings (e.g. from
    :func:`postproc.gcode.lexer.split_lines`). Raises :class:`GcodeSyntaxError` for
    malformed constructs and :class:`ExpansionError` for refused ones, both with
    ``path:line:col``; :class:`postproc.limits.ResourceLimitError` beyond
    ``max_iterations`` loop passes and subprogram calls in all, or ``max_lines`` lines
    run (default :data:`~postproc.limits.LINES_PER_ITERATION` a pass, at least 50 million).
    ``variables``: machine-state values given by the user (``--var``), read where the
    program reads the controller's state (probe results never).

    ``max_lines_out``: the most lines the corrected program may have
    (:meth:`postproc.limits.Limits.output_lines`); when given, the program is first run
    through without yielding anything, counting its lines (and holding them, up to
    :data:`KEPT_LINES`: they are then yielded without running it again), and refused
    (:class:`~postproc.limits.ResourceLimitError`, ``--max-output-lines``) when the flat
    program alone passes that bound, before any line of it is corrected: a loop that
    writes moves is refused at the expansion's speed, not the correction's.
    """
    if max_lines is None:
        max_lines = max(50_000_000, LINES_PER_ITERATION * max_iterations)
    if get_dialect(dialect).block_syntax != "iso":  # Sinumerik labels, GOTO, IF/WHILE/FOR/REPEAT
        from postproc.gcode.sinumerik_expand import expand_sinumerik

        return (SourceLine(k + 1, file, text, original)
                for k, file, text, original in expand_sinumerik(list(lines), path, max_lines, subroutine_path))
    lines = list(lines)
    if max_lines_out is not None:
        dry = _Expander(lines, path, dialect, subroutine_path, max_lines, max_iterations)
        dry.seed(variables or {})
        kept: list[SourceLine] | None = []  # the flat program, while it is short enough to hold
        for n, sl in enumerate(dry.run(), start=1):
            if n > max_lines_out:
                raise flat_program_too_long(max_lines_out, sl.path, sl.lineno)
            if kept is not None:
                kept.append(sl)
                if n >= KEPT_LINES:
                    kept = None
        if kept is not None:
            return iter(kept)  # (the run again would yield the same lines)
    ex = _Expander(lines, path, dialect, subroutine_path, max_lines, max_iterations)
    ex.seed(variables or {})
    return ex.run()
