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
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from postproc.errors import GcodeSyntaxError, PostprocError, UnsupportedGcodeError
from postproc.fileio import read_lines
from postproc.gcode.dialect import DIALECTS
from postproc.gcode.dialect import get as get_dialect
from postproc.gcode.expand_syntax import (
    CANDIDATE,
    Assign,
    Block,
    Macro,
    OWord,
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
    Env,
    evaluate,
    format_number,
    to_index,
)
from postproc.gcode.lexer import scan_words
from postproc.gcode.variables import PROBE_HINT, PROBE_MESSAGE, PROBE_RESULTS
from postproc.limits import (
    DEFAULT_MAX_ITERATIONS,
    LINES_PER_ITERATION,
    ResourceLimitError,
    flat_program_too_long,
)

# rs274ngc INTERP_SUB_PARAMS: #1..#30 are local to an o-word call.
LINUXCNC_SUB_PARAMS = 30
# rs274ngc RS274NGC_MAX_PARAMETERS: numbered parameters are #1..#5601.
LINUXCNC_MAX_PARAMETER = 5601
# rs274ngc INTERP_SUB_ROUTINE_LEVELS: call depth limit.
MAX_CALL_DEPTH = 10
# Fanuc local variables #1..#33 (one set per G65 macro level).
FANUC_LOCALS = 33

# Fanuc argument specification I (G65): address -> local variable number.
FANUC_ARGUMENTS_I = {
    "A": 1, "B": 2, "C": 3, "I": 4, "J": 5, "K": 6, "D": 7, "E": 8, "F": 9,
    "H": 11, "M": 13, "Q": 17, "R": 18, "S": 19, "T": 20, "U": 21, "V": 22,
    "W": 23, "X": 24, "Y": 25, "Z": 26,
}

# LinuxCNC read-only named parameters that hold machine or modal state.
_LINUXCNC_PREDEFINED = frozenset(
    """vmajor vminor line motion_mode plane ccomp metric imperial absolute incremental
    inverse_time units_per_minute units_per_rev coord_system tool_offset retract_r_plane
    retract_old_z spindle_rpm_mode spindle_css_mode ijk_absolute_mode lathe_diameter_mode
    lathe_radius_mode spindle_on spindle_cw mist flood speed_override feed_override
    adaptive_feed feed_hold feed rpm x y z a b c u v w abs_x abs_y abs_z abs_a abs_b abs_c
    abs_u abs_v abs_w current_tool current_pocket selected_tool selected_pocket task
    call_level remap_level task""".split()
)

# LinuxCNC numbered parameters whose value lives in the controller.
_LINUXCNC_MACHINE_RANGES = (
    (5061, 5070, "probe result (G38)"),
    (5161, 5390, "stored position or coordinate-system offset kept by the controller"),
    (5399, 5399, "M66 input result"),
    (5400, 5413, "current tool and its offsets"),
    (5420, 5428, "current position"),
    (5599, 5601, "controller flag"),
)



_M_SPECIAL = (2.0, 30.0, 97.0, 98.0, 99.0)
_G_SPECIAL = (65.0, 66.0)
_LINE_END = re.compile(r"(\r\n|\n|\r)$")

# ---------------------------------------------------------------------------
# Public types
# ---------------------------------------------------------------------------


class ExpansionError(UnsupportedGcodeError):
    """A program whose expansion is refused (machine state, runaway loop, ...)."""


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


# ---------------------------------------------------------------------------
# Execution
# ---------------------------------------------------------------------------


@dataclass
class _Offset:
    unit: Unit
    idx: int  # line index of the o-word
    kind: str
    repeat_count: int = -1


@dataclass
class _Frame:
    named: dict[str, float] = field(default_factory=dict)
    call_type: str = ""  # "", "oword", "m98", "g65", "call-o" (Okuma CALL O)
    ret_unit: Unit | None = None  # None only on the main program's frame, which never returns
    ret_idx: int = 0
    saved: list | None = None  # numbered locals of the caller (o-word call / G65)
    repeats_left: int = 0  # M98/G65 L count still to run after this pass
    start_unit: Unit | None = None  # set on M98/G65 frames (where their L repeats start)
    start_idx: int = 0
    sub_name: str | None = None
    call_lineno: int = 0
    call_path: str | None = None
    m98_loop_counter: int = -1  # LinuxCNC M98 L loop bookkeeping (on the caller's frame)


class _Stop(Exception):
    pass


_UNSET = object()  # no value yet (Fanuc's vacant NULL is a value)


class _Expander(Env):
    def __init__(self, lines: list[str], path: str | None, dialect: str,
                 subroutine_path: Sequence[Path], max_lines: int, max_iterations: int):
        if dialect not in DIALECTS:
            raise ValueError(f"unknown dialect {dialect!r}")
        self.dialect = dialect
        self.d = get_dialect(dialect)
        self.fanuc = is_fanuc(lines, dialect)
        self.nested = not self.d.nested_comment_error
        # M97 (Haas local subprogram: call to a sequence number) in the Fanuc-family dialects
        self.call_m_codes = (97.0, 98.0, 99.0) if self.fanuc else (98.0, 99.0)
        self.main = Unit(lines, path, self.fanuc, self.nested)
        self.subroutine_path = [Path(p) for p in subroutine_path]
        self.max_lines = max_lines
        self.max_iterations = max_iterations
        self.iterations = 0  # loop passes and subprogram calls so far
        self.files: dict[str, Unit] = {}
        # numbered parameters: LinuxCNC: index -> value (unset reads 0);
        # Fanuc: common/retained variables (locals live in the frames)
        self.params: dict[int, float] = {}
        self.globals: dict[str, float] = {"_value": 0.0, "_value_returned": 0.0}
        self.frames = [_Frame()]
        if self.fanuc:
            self.frames[0].saved = [NULL] * (FANUC_LOCALS + 1)
        # LinuxCNC o-word state (interp_o_word.cc)
        self.offsets: dict[str, _Offset] = {}
        self.skipping_o: str | None = None
        self.skipping_to_sub: str | None = None
        self.skip_from: tuple[Unit, int] | None = None
        self.executed_if = False
        self.doing_break = False
        self.doing_continue = False
        self.defining_sub: str | None = None
        self.pending: list[tuple[tuple, float]] = []
        self.pending_names: set[str] = set()
        # where we are
        self.unit = self.main
        self.idx = 0
        self.unit_cur = self.main
        self.cur_idx = 0
        self.cur_col = 0
        self.executed = 0
        # the dialect's own header lines ("$NAME.MIN%", Okuma): the interpreter's header forms
        self.header_forms = [re.compile(p) for p in self.d.header_forms]
        self._loop_ends: dict[tuple[int, int], int] = {}  # (unit, line) of a DO -> line of its END
        # Endless passes: ``version`` counts the changes of the state the expansion reads
        # (parameters, variables, frames, o-word table and counts); ``_passes`` holds it, with
        # the flags, at each jump back. A jump back that finds the same as at its last time
        # ran a whole pass that changed nothing: the program runs that pass for ever.
        self.version = 0
        self._passes: dict[tuple[int, int], tuple] = {}

    # -- places and errors ------------------------------------------------
    @property
    def lineno(self) -> int:
        return self.cur_idx + 1

    def error(self, col: int, message: str, hint: str | None = None) -> GcodeSyntaxError:
        return GcodeSyntaxError(message, path=self.unit_cur.path, lineno=self.lineno, col=col, hint=hint)

    def refuse(self, col: int, message: str, hint: str | None = None) -> ExpansionError:
        return ExpansionError(message, path=self.unit_cur.path, lineno=self.lineno, col=col, hint=hint)

    def count_iteration(self, col: int) -> None:
        """One more loop pass or subprogram call (the statement at column ``col`` of the line
        running); refused beyond ``max_iterations`` in all."""
        self.iterations += 1
        if self.iterations > self.max_iterations:
            raise ResourceLimitError(
                f"the program's loops and subprogram calls run more than {self.max_iterations:,} times in all "
                "(--max-iterations)", path=self.unit_cur.path, lineno=self.lineno, col=col,
                hint="check the loop's condition; raise --max-iterations if the program is meant to run this long")

    def will_repeat(self, count: int, col: int) -> None:
        """A loop or call (at column ``col`` of the line running) is to run ``count`` passes,
        each one an iteration: refused at once when they alone pass ``max_iterations``
        (``M98 P.. L99999999`` is refused at its call, not after ten million passes)."""
        if count > self.max_iterations - self.iterations:
            raise ResourceLimitError(
                f"this loop or call repeats {count:,} times: more than the {self.max_iterations:,} loop passes and "
                "subprogram calls allowed in all (--max-iterations)", path=self.unit_cur.path, lineno=self.lineno,
                col=col, hint="check the repeat count; raise --max-iterations if the program is meant to run this long")

    def _another_pass(self, col: int) -> None:
        """The statement at column ``col`` of the line running jumps back for one more pass
        of a loop: refused when the pass since its last jump changed nothing the program
        reads, for then every pass after it is the same, without end (``while [1]``, a GOTO
        back with no count). Found after two passes, where the bound on iterations takes
        millions."""
        here = (id(self.unit_cur), self.cur_idx)
        state = (self.version, len(self.frames), self.executed_if, self.doing_break, self.doing_continue,
                 self.skipping_o, self.skipping_to_sub, self.defining_sub)
        if self._passes.get(here) == state:
            raise ResourceLimitError(
                "endless loop: a pass of this loop changes nothing (no parameter, variable or count), so it "
                "runs the same pass for ever", path=self.unit_cur.path, lineno=self.cur_idx + 1, col=col,
                hint="check the loop's condition and what the loop changes; a program that is meant to repeat "
                     "until the operator stops it cannot be corrected as a flat program")
        self._passes[here] = state

    # -- parameters ---------------------------------------------------------
    def seed(self, variables: dict[int, float]) -> None:
        """Start with the machine-state values the user gave (locals #1-#33 are not the machine's)."""
        for index, value in variables.items():
            if index not in PROBE_RESULTS and (index > FANUC_LOCALS or not self.fanuc):
                self.params[index] = float(value)

    def _fanuc_locals(self) -> list:
        for fr in reversed(self.frames):
            if fr.call_type in ("", "g65"):
                if fr.saved is None:  # pragma: no cover - set on the main frame and by _g65
                    raise AssertionError("a Fanuc macro level without its local variables")
                return fr.saved
        raise AssertionError  # pragma: no cover

    def read_numbered(self, index: int, col: int):
        if self.fanuc:
            if index == 0:
                return NULL
            if 1 <= index <= FANUC_LOCALS:
                return self._fanuc_locals()[index]
            if 100 <= index <= 499:
                return self.params.get(index, NULL)
            if 500 <= index <= 999:
                if index in self.params:
                    return self.params[index]
                raise self.refuse(col, f"#{index} is a retained common variable: its value is kept by the "
                                  "controller and unknown before the program runs",
                                  hint=f"give its value with --var {index}=VALUE, or set #{index} in the program "
                                       "before reading it")
            if index in PROBE_RESULTS:
                raise self.refuse(col, PROBE_MESSAGE.format(index), hint=PROBE_HINT)
            if index >= 1000:
                if index in self.params:
                    return self.params[index]
                raise self.refuse(col, f"#{index} is a system variable (machine state, positions, offsets or "
                                  "signals): its value is unknown before the program runs",
                                  hint=f"give the value it holds on your machine with --var {index}=VALUE")
            raise self.error(col, f"#{index} is not a macro variable number")
        if not 1 <= index <= LINUXCNC_MAX_PARAMETER:
            raise self.error(col, f"parameter number #{index} is out of range (1..{LINUXCNC_MAX_PARAMETER})")
        if index in PROBE_RESULTS and index not in self.params:
            raise self.refuse(col, PROBE_MESSAGE.format(index), hint=PROBE_HINT)
        if index in self.params:
            return self.params[index]
        for lo, hi, what in _LINUXCNC_MACHINE_RANGES:
            if lo <= index <= hi:
                raise self.refuse(col, f"#{index} reads a {what}: its value is unknown before the program runs",
                                  hint=f"give the value it holds on your machine with --var {index}=VALUE")
        return 0.0

    def write_numbered(self, index: int, value, col: int) -> None:
        if self.fanuc:
            if 1 <= index <= FANUC_LOCALS:
                local = self._fanuc_locals()
                if local[index] is not value and local[index] != value:
                    self.version += 1
                local[index] = value
                return
            if 100 <= index <= 999:
                self._set(self.params, index, value)
                return
            if index >= 1000:
                raise self.refuse(col, f"setting system variable #{index} changes controller state "
                                  "(alarm, offsets, signals) that a corrected program cannot follow",
                                  hint="remove the setting or set the value on the controller")
            raise self.error(col, f"#{index} cannot be set")
        if not 1 <= index <= LINUXCNC_MAX_PARAMETER:
            raise self.error(col, f"parameter number #{index} is out of range (1..{LINUXCNC_MAX_PARAMETER})")
        if 5161 <= index <= 5390:
            raise self.refuse(col, f"setting #{index} changes a stored position or coordinate-system offset "
                              "kept by the controller", hint="use G10 L2/L20 or set it on the controller")
        self._set(self.params, index, value)

    def _set(self, scope: dict, key: Any, value: Any) -> None:
        """``scope[key] = value``, counted as a change of state when it is one."""
        old = scope.get(key, _UNSET)
        if old is not value and old != value:  # (NaN is never equal: always a change)
            self.version += 1
        scope[key] = value

    def read_named(self, name: str, col: int):
        scope = self.globals if name.startswith("_") else self.frames[-1].named
        if name in scope:
            return scope[name]
        if name in self.pending_names:
            return 0.0
        if name.startswith("_"):
            bare = name[1:]
            if bare in _LINUXCNC_PREDEFINED or bare.startswith(("hal[", "ini[")):
                raise self.refuse(col, f"#<{name}> reads the controller's live state: its value is unknown "
                                  "before the program runs", hint="replace it with the value it holds")
        raise self.error(col, f"named parameter #<{name}> is not defined",
                         hint=f"set it first: #<{name}> = value")

    def exists_named(self, name: str) -> bool:
        scope = self.globals if name.startswith("_") else self.frames[-1].named
        return name in scope or name in self.pending_names or (
            name.startswith("_") and name[1:] in _LINUXCNC_PREDEFINED)

    def _value(self, node: tuple):
        return evaluate(node, self)

    def _num(self, node: tuple, col: int) -> float:
        v = evaluate(node, self)
        if v is NULL:
            return 0.0
        return v

    # -- units --------------------------------------------------------------
    def load_file(self, file: Path) -> Unit:
        key = str(file)
        unit = self.files.get(key)
        if unit is None:
            with open(file, encoding="utf-8", errors="strict", newline="") as fh:
                lines = list(read_lines(fh, key))  # a line without end is refused, not read whole
            if lines and lines[0].startswith("\ufeff"):
                lines[0] = lines[0][1:]
            unit = Unit(lines, key, self.fanuc, self.nested)
            self.files[key] = unit
        return unit

    def find_sub_file(self, name: str) -> Path | None:
        for d in self.subroutine_path:
            cand = d / f"{name}.ngc"
            if cand.is_file():
                return cand
        return None

    def find_program_file(self, number: int) -> Path | None:
        stems = [f"O{number:04d}", f"O{number}", f"{number:04d}", f"{number}"]
        for d in self.subroutine_path:
            try:
                entries = {p.name.lower(): p for p in d.iterdir() if p.is_file()}
            except OSError:
                continue
            for stem in stems:
                for ext in ("", ".nc", ".ngc", ".txt", ".tap", ".cnc"):
                    hit = entries.get((stem + ext).lower())
                    if hit is not None:
                        return hit
        return None

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
            except _Stop:
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
                f"'o{_oname(name)} sub' has no matching 'o{_oname(name)} endsub'",
                path=unit.path, lineno=idx + 1, col=1,
                hint=f"end the subroutine with 'o{_oname(name)} endsub'")
        skipping = self.skipping_to_sub if self.skipping_to_sub is not None else self.skipping_o
        if skipping is not None:
            unit, idx = self.skip_from or (self.unit, self.idx)
            if self.skipping_to_sub is not None:
                raise GcodeSyntaxError(
                    f"subroutine o{_oname(skipping)} not found: neither in the file nor as {skipping}.ngc on "
                    "the subroutine path", path=unit.path, lineno=idx + 1, col=1,
                    hint=f"define 'o{_oname(skipping)} sub' in the file or put {skipping}.ngc on --subroutine-path")
            ow = unit.block(idx).oword
            kw = ow.kw if ow is not None else ""
            raise GcodeSyntaxError(
                f"'o{_oname(skipping)} {kw}': the file ended before the o{_oname(skipping)} line that closes it",
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
                    f"'o{_oname(name)} {op.kind}' is never closed: the file ends inside it, with no M2/M30 or "
                    "closing '%' before", path=unit.path, lineno=op.idx + 1, col=1,
                    hint=f"close it with its o{_oname(name)} {closers[op.kind][0]} line (is the file complete?)")

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
                    raise _Stop
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
            raise _Stop
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

    def _queue_setting(self, a: Assign, v) -> None:
        t = a.target
        if t[0] == "name":
            self.pending_names.add(t[1])
            self.pending.append((("name", t[1]), v))
        else:
            index = to_index(self, self._value(t[1]), t[2])
            if v is NULL and not self.fanuc:
                v = 0.0
            self.pending.append((("par", index, t[2]), v))

    def _apply_pending(self) -> None:
        for target, v in self.pending:
            if target[0] == "name":
                name = target[1]
                if name.startswith("_"):
                    bare = name[1:]
                    if bare in _LINUXCNC_PREDEFINED or bare in ("value", "value_returned"):
                        raise self.error(1, f"#<{name}> is a read-only parameter")
                    self._set(self.globals, name, v)
                else:
                    self._set(self.frames[-1].named, name, v)
            else:
                self.write_numbered(target[1], v, target[2])
        self.pending = []
        self.pending_names = set()

    # -- subprogram calls (M98 / M99 / G65) ----------------------------------
    def _call_words(self, words: list[tuple[Word, Any]], m_codes: list[float],
                    g_codes: list[float]) -> tuple[Callable[[], None] | None, set[int]]:
        """The call a block makes and the indices of the words it uses (``words``: each
        word with its value, a number or NULL)."""
        letters: dict[str, list[tuple[int, Word, Any]]] = {}
        for k, (w, v) in enumerate(words):
            letters.setdefault(w.letter, []).append((k, w, v))
        if 99.0 in m_codes:
            if len(self.frames) == 1 and "P" not in letters:
                # M99 ending the main program: the end of one pass (a subprogram file
                # corrected on its own, or a program the controller repeats: each pass is
                # corrected alike; the interpreter refuses it in G91, where each pass would
                # start elsewhere). The line stays as it is and expansion stops there.
                return None, set()
            return self._m99_words(letters)
        if 97.0 in m_codes and self.fanuc:
            return self._m97_words(letters)
        if 98.0 in m_codes:
            return self._m98_words(letters)
        return self._g65_words(words, letters)

    def _m99_words(self, letters: dict[str, list[tuple[int, Word, Any]]]) -> tuple[Callable[[], None], set[int]]:
        """M99 [P..]: return from the subprogram (to sequence number P)."""
        drop = {k for k, _w, v in letters.get("M", []) if v == 99.0}
        target: tuple[int, int] | None = None
        for k, w, v in letters.get("P", []):
            drop.add(k)
            if v is not NULL:  # a vacant variable's address is ignored (P#0: none)
                target = (int(round(v)), w.col)
        return (lambda: self._m99(target)), drop

    def _m97_words(self, letters: dict[str, list[tuple[int, Word, Any]]]) -> tuple[Callable[[], None], set[int]]:
        """M97 P.. [L..] (Haas): call the local subprogram at sequence number P, L times."""
        p, drop = self._p_l_words(letters, 97.0, "M97 needs P (the sequence number of the local subprogram)")
        number = int(round(p[2]))
        given = _count(letters)
        count = 1 if given is None else given
        return (lambda: self._m97(number, count, p[1].col)), drop

    def _m98_words(self, letters: dict[str, list[tuple[int, Word, Any]]]) -> tuple[Callable[[], None], set[int]]:
        """M98 P.. [L..]: call subprogram O(P), L times."""
        p, drop = self._p_l_words(letters, 98.0, "M98 needs P (the subprogram number)")
        number = int(round(p[2]))
        repeats = _count(letters)
        return (lambda: self._m98(number, repeats, p[1].col)), drop

    def _p_l_words(self, letters: dict[str, list[tuple[int, Word, Any]]], code: float,
                   missing_p: str) -> tuple[tuple[int, Word, Any], set[int]]:
        """The first P of an M97/M98 call (``code``) and the indices of its M, P and L words;
        ``missing_p`` is the error when there is no P."""
        mw = next(w for k, w, v in letters["M"] if v == code)
        drop = {k for k, _w, v in letters.get("M", []) if v == code}
        drop.update(k for k, _, _ in letters.get("P", []) + letters.get("L", []))
        # a vacant variable's address is ignored (P#0: as if no P)
        p = [x for x in letters.get("P", []) if x[2] is not NULL]
        if not p:
            raise self.error(mw.col, missing_p)
        return p[0], drop

    def _g65_words(self, words: list[tuple[Word, Any]],
                   letters: dict[str, list[tuple[int, Word, Any]]]) -> tuple[Callable[[], None], set[int]]:
        """G65 P.. [L..] arguments: call macro O(P), L times, with the arguments as its locals
        (argument specification I). Every word of the block belongs to the call."""
        gw = next(w for k, w, v in letters["G"] if v == 65.0)
        if not self.fanuc:
            raise self.refuse(gw.col, "G65 macro call is Fanuc/Haas syntax",
                              hint="choose --dialect fanuc or haas for this program")
        args: dict[str, Any] = {}
        macro: int | None = None
        count = 1
        for w, v in words:
            if w.letter == "G":
                if v != 65.0:
                    raise self.refuse(w.col, "G65 must be alone in its block with its arguments")
            elif w.letter == "P":
                if v is not NULL:  # a vacant variable's address is ignored
                    macro = int(round(v))
            elif w.letter == "L":
                if v is not NULL:
                    count = int(round(v))
            elif w.letter != "N":
                self._g65_argument(args, w, v)
        if macro is None:
            raise self.error(gw.col, "G65 needs P (the macro program number)")
        return (lambda: self._g65(macro, count, args, gw.col)), set(range(len(words)))

    def _g65_argument(self, args: dict[str, Any], w: Word, v: Any) -> None:
        """Add word ``w`` (value ``v``) to the arguments ``args`` of a G65 call."""
        if w.letter not in FANUC_ARGUMENTS_I:
            raise self.error(w.col, f"address {w.letter} cannot be a G65 argument")
        if w.node is None and "." not in w.raw and v != 0.0:
            raise self.refuse(w.col, f"G65 argument {w.letter}{w.raw} has no decimal point: the "
                              "control scales it by its least input increment, which is "
                              "machine configuration", hint=f"write {w.letter}{w.raw}. (with a point)")
        if w.letter in args:
            raise self.refuse(w.col, f"argument {w.letter} given twice (argument specification II "
                              "is not supported)")
        args[w.letter] = v

    def _program_target(self, number: int, col: int) -> tuple[Unit, int, int] | None:
        progs = self.main.programs()
        if number in progs:
            return self.main, progs[number], number
        if self.unit_cur is not self.main and number in self.unit_cur.programs():
            return self.unit_cur, self.unit_cur.programs()[number], number
        f = self.find_program_file(number)
        if f is not None:
            u = self.load_file(f)
            start = u.programs().get(number)
            return u, (start if start is not None else -1), number
        return None

    def _m98(self, number: int, count: int | None, col: int) -> None:
        target = self._program_target(number, col)
        repeat = 1 if count is None else count
        if target is None and count is None and number >= 10000 and (
                self.fanuc or self.d.m98_count_in_p):
            # Fanuc: P(count)(4-digit program number)
            target = self._program_target(number % 10000, col)
            repeat = number // 10000
            number = number % 10000
        if target is None:
            raise self.error(col, f"subprogram O{number} not found in the file or on the subroutine path",
                             hint=f"add 'O{number}' ... M99 after the main program's M30, or put O{number}.nc "
                             "on --subroutine-path")
        if repeat <= 0:
            return
        self.will_repeat(repeat, col)
        unit, start, _ = target
        self._enter("m98", f"O{number}", unit, start + 1, repeat - 1)

    def _m97(self, number: int, count: int, col: int) -> None:
        if count <= 0:
            return
        self.will_repeat(count, col)
        start = self._sequence(self.main, number, 0, col)
        self._enter("m98", f"N{number}", self.main, start, count - 1)

    def _g65(self, number: int, count: int, args: dict, col: int) -> None:
        target = self._program_target(number, col)
        if target is None:
            raise self.error(col, f"macro program O{number} not found in the file or on the subroutine path")
        if count <= 0:
            return
        self.will_repeat(count, col)
        unit, start, _ = target
        local = [NULL] * (FANUC_LOCALS + 1)
        for letter, v in args.items():
            local[FANUC_ARGUMENTS_I[letter]] = v
        self._enter("g65", f"O{number}", unit, start + 1, count - 1, saved=local)

    def _enter(self, call_type: str, name: str, unit: Unit, start: int, repeats: int,
               saved: list | None = None) -> None:
        if len(self.frames) > MAX_CALL_DEPTH:
            raise self.refuse(1, f"subprogram calls nested deeper than {MAX_CALL_DEPTH} levels",
                              hint="check for a subprogram that calls itself")
        self.count_iteration(1)
        fr = _Frame(call_type=call_type, ret_unit=self.unit_cur, ret_idx=self.cur_idx + 1,
                    saved=saved, repeats_left=repeats, start_unit=unit, start_idx=start, sub_name=name,
                    call_lineno=self.cur_idx + 1, call_path=self.unit_cur.path)
        self.frames.append(fr)
        self.version += 1
        self.unit, self.idx = unit, start

    def _m99(self, target: tuple[int, int] | None) -> None:
        if len(self.frames) == 1:
            raise self.refuse(1, "M99 P.. in the main program jumps back into it forever",
                              hint="end the main program with M30")
        fr = self.frames[-1]
        if fr.call_type not in ("m98", "g65"):
            raise self.error(1, "M99 inside an o-word subroutine", hint="end it with 'o<name> endsub'")
        if fr.repeats_left > 0:
            self.count_iteration(1)
            fr.repeats_left -= 1
            self.version += 1
            if fr.call_type == "g65":
                pass  # locals persist across G65 L repeats
            if fr.start_unit is None:  # pragma: no cover - _enter sets it
                raise AssertionError(f"{fr.call_type} frame without the start of its repeats")
            self.unit, self.idx = fr.start_unit, fr.start_idx
            return
        self._leave(fr)
        if target is not None:
            number, col = target
            self.idx = self._sequence(self.unit, number, fr.ret_idx, col)
            if self.idx < fr.ret_idx:  # back to or before the call: one more pass of a loop
                self.count_iteration(col)
                self._another_pass(col)

    def _leave(self, fr: _Frame) -> None:
        """Return from ``fr``, the innermost subprogram frame, to the line after its call."""
        self.frames.pop()
        self.version += 1
        if fr.ret_unit is None:  # pragma: no cover - callers never leave the main program's frame
            raise AssertionError("the main program's frame has no caller to return to")
        self.unit, self.idx = fr.ret_unit, fr.ret_idx

    def _sequence(self, unit: Unit, number: int, start: int, col: int) -> int:
        """Fanuc sequence-number search: forward from ``start``, then from the program start."""
        hits = unit.sequence_numbers().get(number, [])
        lo = self._program_start(unit, start)
        for k in hits:
            if k >= start and self._program_start(unit, k) == lo:
                return k
        for k in hits:
            if lo <= k < start:
                return k
        raise self.error(col, f"sequence number N{number} not found in this program",
                         hint="GOTO/M99 P jump to a block that starts with that N number")

    def _program_start(self, unit: Unit, idx: int) -> int:
        starts = sorted(unit.programs().values())
        lo = 0
        for s in starts:
            if s <= idx:
                lo = s
        return lo

    # -- Fanuc macro statements -------------------------------------------------
    def _macro(self, b: Block, m: Macro) -> None:
        """Run the macro statement ``m`` (``b.macro``) of block ``b``."""
        if b.slash:
            raise self.refuse(1, "a macro statement on a block-delete ('/') line")
        if m.kind == "goto" or (m.kind == "if_goto" and self._cond(m)):
            self.idx = self._sequence(self.unit_cur, self._target(m), self.cur_idx + 1, m.col)
            if self.idx <= self.cur_idx:  # a jump back: one more pass of a loop
                self.count_iteration(m.col)
                self._another_pass(m.col)
        elif m.kind == "if_then":
            if self._cond(m):
                a = m.assign
                if a is None:  # pragma: no cover - the parser sets it
                    raise AssertionError("IF .. THEN without its setting")
                v = self._value(a.node)
                self.pending = []
                self._queue_setting(a, v)
                self._apply_pending()
        elif m.kind in ("while", "do"):
            end = self._loop_end_of(m)
            if m.kind == "while" and not self._cond(m):
                self.idx = end + 1
        elif m.kind == "end":
            self.count_iteration(m.col)
            self._another_pass(m.col)
            self.idx = self._find_do(m.loop, m.col)

    def _cond(self, m: Macro) -> bool:
        """Is the condition of IF or WHILE statement ``m`` true?"""
        if m.cond is None:  # pragma: no cover - the parser sets it
            raise AssertionError(f"{m.kind} statement without its condition")
        v = self._value(m.cond)
        return v is not NULL and v != 0.0

    def _target(self, m: Macro) -> int:
        if m.target is None:  # pragma: no cover - the parser sets it
            raise AssertionError(f"{m.kind} statement without its target")
        v = self._value(m.target)
        if v is NULL:
            raise self.error(m.col, "GOTO to a vacant variable")
        return to_index(self, v, m.col)

    def _loop_end_of(self, m: Macro) -> int:
        """The line of the END that closes the WHILE/DO ``m`` on the line running, found
        once: a DO without its END is refused when it first runs, whether or not the loop
        would reach it (Fanuc alarm PS0126: DO and END are not paired), and not only when
        its condition fails."""
        key = (id(self.unit_cur), self.cur_idx)
        end = self._loop_ends.get(key)
        if end is None:
            end = self._loop_ends[key] = self._find_end(m.loop, m.col)
        return end

    def _find_end(self, loop: int, col: int) -> int:
        unit = self.unit_cur
        for k in range(self.cur_idx + 1, len(unit.lines)):
            if "end" in unit.lines[k].lower() or "END" in unit.lines[k]:
                b = unit.block(k)
                if b.macro is not None and b.macro.kind == "end" and b.macro.loop == loop:
                    return k
        raise self.error(col, f"DO {loop} has no END {loop} after it: DO and END must be paired (Fanuc alarm "
                         "PS0126)", hint=f"close the loop with END {loop}")

    def _find_do(self, loop: int, col: int) -> int:
        unit = self.unit_cur
        for k in range(self.cur_idx - 1, -1, -1):
            if "do" in unit.lines[k].lower():
                b = unit.block(k)
                if b.macro is not None and b.macro.kind in ("while", "do") and b.macro.loop == loop:
                    return k
        raise self.error(col, f"END {loop} has no DO {loop} before it")

    # -- LinuxCNC o-words (interp_o_word.cc) ------------------------------------
    def _save_offset(self, ow: OWord) -> None:
        have = self.offsets.get(ow.name)
        if have is not None:
            raise self.error(ow.col, f"o-word o{_oname(ow.name)} is already defined at "
                             f"{have.unit.path or '<input>'}:{have.idx + 1}",
                             hint="give each sub, loop and if its own o-number")
        self.offsets[ow.name] = _Offset(self.unit_cur, self.cur_idx, ow.kw)
        self.version += 1

    def _check_label(self, ow: OWord, allow_do: bool = False) -> _Offset | None:
        op = self.offsets.get(ow.name)
        if op is not None:
            if allow_do and op.kind == "do":
                return op
            if not (op.unit is self.unit_cur and op.idx == self.cur_idx):
                raise self.error(ow.col, f"duplicate o-word label o{_oname(ow.name)}: already used at line "
                                 f"{op.idx + 1}", hint="give each sub, loop and if its own o-number")
        return op

    def _need(self, ow: OWord, kinds: tuple[str, ...], what: str) -> _Offset:
        op = self.offsets.get(ow.name)
        if op is None:
            raise self.error(ow.col, f"'o{_oname(ow.name)} {ow.kw}' without its {what}")
        if op.kind not in kinds:
            raise self.error(ow.col, f"'o{_oname(ow.name)} {ow.kw}' does not match 'o{_oname(ow.name)} "
                             f"{op.kind}' at line {op.idx + 1}")
        return op

    def _back_to(self, name: str, col: int) -> None:
        """Back to the start of loop ``name`` (from the o-word at column ``col``): one more pass."""
        self.count_iteration(col)
        self._another_pass(col)
        op = self.offsets[name]
        self.unit, self.idx = op.unit, op.idx

    def _skip_block(self, name: str) -> None:
        """Skip the lines up to the o-word line ``name`` that ends the block begun here."""
        self.skipping_o = name
        self.skip_from = (self.unit_cur, self.cur_idx)

    def _label(self, ow: OWord, allow_do: bool = False) -> _Offset:
        """The position of the loop or if ``ow`` begins, recorded the first time it runs."""
        op = self._check_label(ow, allow_do)
        if op is None:
            self._save_offset(ow)
            op = self.offsets[ow.name]
        return op

    def _oword(self, b: Block, ow: OWord) -> None:
        """Run the o-word statement ``ow`` (``b.oword``) of block ``b``."""
        if b.slash:
            raise self.refuse(ow.col, "an o-word on a block-delete ('/') line")
        if b.items:
            w = b.items[0]
            if not (isinstance(w, Word) and w.letter == "N" and len(b.items) == 1):
                raise self.error(ow.col, "an o-word line holds nothing but the o-word (and a line number)")
        if self.fanuc:
            raise self.error(ow.col, "o-word control is LinuxCNC syntax",
                             hint="choose --dialect linuxcnc for this program")
        if self.defining_sub is not None and self.skipping_o == self.defining_sub and not (
                ow.name == self.defining_sub and ow.kw == "endsub"):
            return  # inside a definition met in sequence: only its endsub counts
        self._OWORD_HANDLERS[ow.kw](self, ow)

    def _end_skip_at(self, ow: OWord) -> None:
        """A sub or bare o-number line ends the skip to it, and records its position."""
        if self.skipping_o is not None:
            if self.offsets.get(ow.name) is None:
                self.offsets[ow.name] = _Offset(self.unit_cur, self.cur_idx, ow.kw)
                self.version += 1
            self.skipping_o = None
        self.skipping_to_sub = None

    def _o_number(self, ow: OWord) -> None:
        """``o100`` alone (a Fanuc-style O number): execution continues into it."""
        self._end_skip_at(ow)

    def _o_sub(self, ow: OWord) -> None:
        self._end_skip_at(ow)
        fr = self.frames[-1]
        if len(self.frames) > 1 and fr.call_type == "oword" and fr.sub_name == ow.name:
            return  # the called subroutine starts here
        if self.defining_sub is not None:
            raise self.error(ow.col, "a subroutine defined inside another subroutine definition")
        # a definition met in sequence: skipped up to its endsub
        self._save_offset(ow)
        self._skip_block(ow.name)
        self.defining_sub = ow.name

    def _o_return(self, ow: OWord) -> None:
        """``endsub`` or ``return [value]``."""
        name, kw = ow.name, ow.kw
        if self.defining_sub == name:
            if kw == "endsub":  # end of a definition met in sequence
                self.skipping_o = None
                self.defining_sub = None
            return
        if len(self.frames) == 1:
            raise self.error(ow.col, f"'o{_oname(name)} {kw}' outside a subroutine")
        fr = self.frames[-1]
        if fr.call_type != "oword":
            raise self.error(ow.col, f"'o{_oname(name)} {kw}' in a subprogram called with M98",
                             hint="end an M98 subprogram with M99")
        if kw == "endsub" and self.skipping_o is not None:
            self.skipping_o = None
        if ow.args:
            self.globals["_value"] = self._num(ow.args[0], ow.col)
            self.globals["_value_returned"] = 1.0
        for k, v in enumerate(fr.saved or []):
            self.params[k + 1] = v
        self.version += 1
        self._leave(fr)

    def _o_do(self, ow: OWord) -> None:
        self.skipping_o = None
        if ow.name not in self.offsets:
            self._save_offset(ow)

    def _o_repeat(self, ow: OWord) -> None:
        op = self._label(ow)
        self.skipping_o = None
        self.version += 1
        if op.repeat_count == -1:
            op.repeat_count = _round_to_int(self._num(ow.args[0], ow.col))
            self.will_repeat(op.repeat_count, ow.col)
        if op.repeat_count > 0:
            op.repeat_count -= 1
        else:
            self._skip_block(ow.name)
            op.repeat_count = -1

    def _o_while(self, ow: OWord) -> None:
        """``while [test]``: the start of a while loop, or the end of a do loop."""
        op = self._label(ow, allow_do=True)
        self.skipping_o = None
        test = self._num(ow.args[0], ow.col)
        if op.kind == "while":
            if test == 0.0:
                self._skip_block(ow.name)
        elif test != 0.0 and not self.doing_break:  # end of a do loop
            self._back_to(ow.name, ow.col)
        else:
            self.doing_break = False

    def _o_if(self, ow: OWord) -> None:
        self._label(ow)
        if self._num(ow.args[0], ow.col) != 0.0:
            self.skipping_o = None
            self.executed_if = True
        else:
            self._skip_block(ow.name)
            self.executed_if = False

    def _o_elseif(self, ow: OWord) -> None:
        self._need(ow, ("if",), "'if'")
        test = self._num(ow.args[0], ow.col)  # rs274ngc reads (evaluates) it in any case
        if self.executed_if:
            self._skip_block(ow.name)
        elif test != 0.0:
            self.skipping_o = None
            self.executed_if = True

    def _o_else(self, ow: OWord) -> None:
        self._need(ow, ("if",), "'if'")
        if self.executed_if:
            self._skip_block(ow.name)
        elif self.skipping_o == ow.name:
            self.executed_if = True
            self.skipping_o = None

    def _o_endif(self, ow: OWord) -> None:
        self._need(ow, ("if",), "'if'")
        self.skipping_o = None
        self.executed_if = True

    def _o_break(self, ow: OWord) -> None:
        self._need(ow, ("while", "do"), "loop")
        self._skip_block(ow.name)
        self.doing_break = True

    def _o_continue(self, ow: OWord) -> None:
        self._need(ow, ("while", "do"), "loop")
        if self.skipping_o == ow.name:
            return
        self._skip_block(ow.name)
        self.doing_continue = True

    def _o_endwhile(self, ow: OWord) -> None:
        self._need(ow, ("while",), "loop start")
        self._loop_end(ow.name, ow.col)

    def _o_endrepeat(self, ow: OWord) -> None:
        self._need(ow, ("repeat",), "loop start")
        self._loop_end(ow.name, ow.col)

    def _loop_end(self, name: str, col: int) -> None:
        """``endwhile``/``endrepeat``: back to the loop's start, unless the loop is being
        left (its skip ends here) or a continue skipped to here."""
        if self.skipping_o == name:
            self.skipping_o = None
            if self.doing_continue:
                self.doing_continue = False
                self._back_to(name, col)
            return
        self._back_to(name, col)

    def _ocall(self, ow: OWord) -> None:
        args = [self._num(a, ow.col) for a in ow.args]
        if len(args) > LINUXCNC_SUB_PARAMS:
            raise self.error(ow.col, f"more than {LINUXCNC_SUB_PARAMS} call arguments")
        if len(self.frames) > MAX_CALL_DEPTH:
            raise self.refuse(ow.col, f"o-word calls nested deeper than {MAX_CALL_DEPTH} levels",
                              hint="check for a subroutine that calls itself without end")
        saved = [self.params.get(k, 0.0) for k in range(1, LINUXCNC_SUB_PARAMS + 1)]
        for k in range(1, LINUXCNC_SUB_PARAMS + 1):
            self.params[k] = args[k - 1] if k <= len(args) else 0.0
        self.globals["_value"] = 0.0
        self.globals["_value_returned"] = 0.0
        self.version += 1
        self.count_iteration(ow.col)
        fr = _Frame(call_type="oword", ret_unit=self.unit_cur, ret_idx=self.cur_idx + 1, saved=saved,
                    sub_name=ow.name, call_lineno=self.cur_idx + 1, call_path=self.unit_cur.path)
        self.frames.append(fr)
        op = self.offsets.get(ow.name)
        if op is not None:
            if op.kind != "sub":
                raise self.error(ow.col, f"o{_oname(ow.name)} is a '{op.kind}', not a subroutine")
            self.unit, self.idx = op.unit, op.idx + 1
            return
        if _leaves_folder(ow.name):
            raise self.refuse(ow.col, f"subroutine name <{ow.name}> names a path: subroutines are looked up by "
                              "name in the --subroutine-path folders only",
                              hint="call it by its file name without folders, and put the folder on "
                              "--subroutine-path")
        f = self.find_sub_file(ow.name)
        if f is not None:
            self.unit, self.idx = self.load_file(f), 0
        self.skipping_to_sub = ow.name
        self.skipping_o = ow.name
        self.skip_from = (self.unit_cur, self.cur_idx)

    # o-word keyword -> the method that runs it ("" is a bare o-number)
    _OWORD_HANDLERS: dict[str, Callable[[_Expander, OWord], None]] = {
        "": _o_number, "sub": _o_sub, "endsub": _o_return, "return": _o_return, "call": _ocall,
        "do": _o_do, "while": _o_while, "endwhile": _o_endwhile, "repeat": _o_repeat,
        "endrepeat": _o_endrepeat, "break": _o_break, "continue": _o_continue,
        "if": _o_if, "elseif": _o_elseif, "else": _o_else, "endif": _o_endif,
    }


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


def _leaves_folder(name: str) -> bool:
    """A subroutine name that, made a file name, would name another folder (``a/b``,
    ``..``, an absolute path): refused, so that lookups stay inside the subroutine path."""
    return "/" in name or "\\" in name or ".." in name or Path(name).is_absolute()


def _round_to_int(v: float) -> int:
    return int(math.floor(v + 0.5))


def _oname(name: str) -> str:
    return name if name.isdigit() else f"<{name}>"


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
    through without yielding anything, counting its lines, and refused
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
        for n, sl in enumerate(dry.run(), start=1):
            if n > max_lines_out:
                raise flat_program_too_long(max_lines_out, sl.path, sl.lineno)
    ex = _Expander(lines, path, dialect, subroutine_path, max_lines, max_iterations)
    ex.seed(variables or {})
    return ex.run()


def _count(letters: dict[str, list[tuple[int, Word, Any]]]) -> int | None:
    """The repeat count of a call's first L word, or None without one (an L of a vacant
    variable is ignored, as the control ignores any such address)."""
    ls = [v for _k, _w, v in letters.get("L", []) if v is not NULL]
    return int(round(ls[0])) if ls else None
