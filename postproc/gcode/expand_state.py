"""The expander's state (:mod:`postproc.gcode.expand`): where it is, its counts and
bounds, the numbered and named parameters and their scopes, the call frames and the
o-word table, and the files subprograms come from. The statements that change it are
the layers above: calls and returns (:mod:`postproc.gcode.expand_calls`), then loops,
branches and o-words (:mod:`postproc.gcode.expand_flow`), then the line driver
(:class:`postproc.gcode.expand._Expander`)."""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from postproc.errors import GcodeSyntaxError, UnsupportedGcodeError
from postproc.fileio import read_lines
from postproc.gcode.dialect import DIALECTS
from postproc.gcode.dialect import get as get_dialect
from postproc.gcode.expand_syntax import (
    Assign,
    Unit,
    is_fanuc,
)
from postproc.gcode.expr import (
    NULL,
    Env,
    evaluate,
    to_index,
)
from postproc.gcode.variables import PROBE_HINT, PROBE_MESSAGE, PROBE_RESULTS
from postproc.limits import (
    ResourceLimitError,
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
LINUXCNC_PREDEFINED = frozenset(
    """vmajor vminor line motion_mode plane ccomp metric imperial absolute incremental
    inverse_time units_per_minute units_per_rev coord_system tool_offset retract_r_plane
    retract_old_z spindle_rpm_mode spindle_css_mode ijk_absolute_mode lathe_diameter_mode
    lathe_radius_mode spindle_on spindle_cw mist flood speed_override feed_override
    adaptive_feed feed_hold feed rpm x y z a b c u v w abs_x abs_y abs_z abs_a abs_b abs_c
    abs_u abs_v abs_w current_tool current_pocket selected_tool selected_pocket task
    call_level remap_level task""".split()
)

# LinuxCNC numbered parameters whose value lives in the controller.
LINUXCNC_MACHINE_RANGES = (
    (5061, 5070, "probe result (G38)"),
    (5161, 5390, "stored position or coordinate-system offset kept by the controller"),
    (5399, 5399, "M66 input result"),
    (5400, 5413, "current tool and its offsets"),
    (5420, 5428, "current position"),
    (5599, 5601, "controller flag"),
)


class ExpansionError(UnsupportedGcodeError):
    """A program whose expansion is refused (machine state, runaway loop, ...)."""


@dataclass
class OwordPlace:
    unit: Unit
    idx: int  # line index of the o-word
    kind: str
    repeat_count: int = -1


@dataclass
class CallFrame:
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


class Stop(Exception):
    pass


UNSET = object()  # no value yet (Fanuc's vacant NULL is a value)


def oname(name: str) -> str:
    return name if name.isdigit() else f"<{name}>"


class ExpanderState(Env):
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
        self.frames = [CallFrame()]
        if self.fanuc:
            self.frames[0].saved = [NULL] * (FANUC_LOCALS + 1)
        # LinuxCNC o-word state (interp_o_word.cc)
        self.offsets: dict[str, OwordPlace] = {}
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
        for lo, hi, what in LINUXCNC_MACHINE_RANGES:
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
        old = scope.get(key, UNSET)
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
            if bare in LINUXCNC_PREDEFINED or bare.startswith(("hal[", "ini[")):
                raise self.refuse(col, f"#<{name}> reads the controller's live state: its value is unknown "
                                  "before the program runs", hint="replace it with the value it holds")
        raise self.error(col, f"named parameter #<{name}> is not defined",
                         hint=f"set it first: #<{name}> = value")

    def exists_named(self, name: str) -> bool:
        scope = self.globals if name.startswith("_") else self.frames[-1].named
        return name in scope or name in self.pending_names or (
            name.startswith("_") and name[1:] in LINUXCNC_PREDEFINED)

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
                    if bare in LINUXCNC_PREDEFINED or bare in ("value", "value_returned"):
                        raise self.error(1, f"#<{name}> is a read-only parameter")
                    self._set(self.globals, name, v)
                else:
                    self._set(self.frames[-1].named, name, v)
            else:
                self.write_numbered(target[1], v, target[2])
        self.pending = []
        self.pending_names = set()
