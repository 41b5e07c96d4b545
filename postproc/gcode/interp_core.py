"""The interpreter's state and the helpers every part of it uses: the setup it reads, the
errors it raises at their place, the offsets that map program to machine coordinates.

:class:`postproc.gcode.interp.Interpreter` is this core with the readers of
:mod:`~postproc.gcode.interp_words`, :mod:`~postproc.gcode.interp_offsets`,
:mod:`~postproc.gcode.interp_cycles` and :mod:`~postproc.gcode.interp_motion` mixed in.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Protocol, TypeVar

from postproc.errors import (
    MissingSetupError,
    PostprocError,
    UnsupportedGcodeError,
)
from postproc.gcode import lexer
from postproc.gcode.recognise import (
    LATHE_HINT,
    LatheMarks,
    LatheProgramError,
    foreign_dialect,
    lathe_message,
)
from postproc.gcode.state import NAN, ModalState
from postproc.limits import DEFAULT_MAX_ARC_TURNS

if TYPE_CHECKING:
    from postproc.gcode.dialect import Dialect
    from postproc.gcode.moves import Move
    from postproc.gcode.sinumerik import CycleCall

#: a block's words by letter, G and M aside: (value, word index)
Vals = dict[str, tuple[float, int]]
# Largest value of a word (1000 km, a billion turns): a 400-digit coordinate reads as inf,
# and one of 300 digits makes the correction's arithmetic overflow.
MAX_WORD_VALUE = 1e9
_E = TypeVar("_E", bound=PostprocError)


class _Setup(Protocol):
    """What the interpreter reads of a :class:`postproc.gcode.path.Setup` (which imports
    this module), besides its optional ``start`` and ``home``."""

    offsets: dict
    tool_lengths: dict
    tool_vector: tuple | None


class NeedsExpansion(UnsupportedGcodeError):
    """A construct the expansion stage flattens (parameters, expressions, O-words,
    subprograms, macros): the corrector starts over on the expanded program."""


# constructs the expansion stage (postproc.gcode.expand) flattens
EXPANDABLE_M = {97, 98, 99}
EXPANDABLE_G = {650, 660, 661}

AXES = "XYZ"
ROTARY = "ABC"
# A degenerate arc (start, end and centre within this) is not an arc.
MIN_ARC_RADIUS_MM = 1e-6


# word letter -> role on the fast path (axes 0-2, feed 3, motion 4, line number 5)
_GKEYS = {"0": 0, "00": 0, "1": 10, "01": 10, "2": 20, "02": 20, "3": 30, "03": 30}


def gkey(text: str) -> int:
    key = _GKEYS.get(text)
    return key if key is not None else int(round(float(text) * 10))


class InterpreterCore:
    """The state of :class:`postproc.gcode.interp.Interpreter` and the helpers its parts share."""

    def __init__(self, setup: _Setup, path: str | None = None, *, lenient_setup: bool = False,
                 dialect: str = "generic") -> None:
        self.max_arc_turns = DEFAULT_MAX_ARC_TURNS  # turns of one helix (G2/G3 P), --max-arc-turns
        self.setup = setup
        # lenient: every work offset and tool length is taken as zero (for comparing
        # two versions of one program, where they cancel out)
        self.lenient_setup = lenient_setup
        self.path = path
        self.state = ModalState()
        # axes the program has not positioned yet start where the machine is (Setup.start)
        self.state.pos = start_position(getattr(setup, "start", None))
        # set by the corrector when a start is given: words it adds on an axis known only
        # from the start are written in the work frame, so G54 must not be taken as zero
        self.require_g54 = False
        self.offsets = {k: _offset_tuple(v) for k, v in (setup.offsets or {}).items()}
        self.tool_lengths = dict(setup.tool_lengths or {})  # G10 L1/L10/L11 write here
        self.rotary_g92: dict[str, float] = {}
        self.program_offsets: dict[str, list[float]] = {}  # set by G10 L2/L20
        self.implicit_g54 = False  # a move ran in G54 that the user did not give
        self.used_rotary: set[str] = set()
        self.tool_vector = tuple(setup.tool_vector) if setup.tool_vector is not None else None
        self.motion_word = False  # did the last line hold a G0/G1/G2/G3 word?
        # the last line set an offset from where the machine is (G92, G10 L20, G10 L10/L11):
        # (words, [(word index, axis), ...], nominal position then), else None
        self.rebase: tuple | None = None
        # the last line stored the position for G28 or G30 (G28.1/G30.1): its name, else None
        self.stored_here: str | None = None
        self.program_stored: set[str] = set()  # stored positions the program set itself
        self.ended = False  # an M2/M30 was read: later lines are not executed
        self.dialect = dialect
        from postproc.gcode.dialect import get as _dialect

        self.d: Dialect = _dialect(dialect)  # the facts of the controller the program is for
        if self.d.machine != "mill":
            raise LatheProgramError(lathe_message([f"--dialect {self.d.name} ({self.d.title})"]), path=path,
                                    hint=LATHE_HINT)
        self.lathe = LatheMarks()
        self._iso_blocks = self.d.block_syntax == "iso"  # else every line is read by the dialect's reader
        self.variables: dict[str, float] = {}  # Sinumerik R parameters and DEF variables set so far
        self._arc_absolute_once = False  # the next block's centre words are absolute (Sinumerik I=AC())
        self.modal_call: CycleCall | None = None  # Sinumerik MCALL CYCLE8x(): drills after each moving block
        self._cycle_due: CycleCall | None = None  # the cycle this block calls (run after its move)
        self.cycle_move: Move | None = None  # the drilling cycle this line made (Sinumerik): its moves
        self.call_line = ""  # the Sinumerik cycle call this line is ("MCALL CYCLE81"): a comment when expanded
        self.call_col = 0  # the column where that call starts (its MCALL or cycle name; 0: no call)
        self._g_alias = dict(self.d.g_aliases)
        # G codes whose meaning is the dialect's own: further work offsets, refusals in its words
        self._dialect_g: dict = {k: _work_code(name) for k, name in self.d.work_codes}
        self._dialect_g.update({k: _refused_g(what, instead) for k, what, instead in self.d.refused_g})
        if self.d.fixture_offset_word:  # E0: fixture offsets cancelled (machine coordinates)
            self.offsets.setdefault(f"{self.d.fixture_offset_word}0", (0.0, 0.0, 0.0))
        self.may_expand = False  # set by the corrector when it can start over on the expanded program
        self.repeats = False  # the program ended with M99 (repeated by the controller)
        # stored positions (machine mm, NaN = unknown) of G28 and G30 (--home, G28.1/G30.1)
        self.home = {name: list(_offset_tuple(v, partial=True)) for name, v in
                     ((getattr(setup, "home", None) or {}).items())}
        # axes sent to a stored position that was not given: unknown until positioned again
        self.unknown_after: dict[int, str] = {}
        self._last_pq: tuple[float, float] | None = None  # the previous G5's P/Q (mm)
        # for lines read in bulk (postproc.gcode.bulk): the offsets of absolute words (mm)
        # and the tool vector in the current state, found once (bulk.prime_shift) and
        # forgotten (None) wherever a line read here may change them
        self.run_shift: tuple[float, float, float] | None = None
        self.run_r: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self.comp_moves: list = []  # moves the controller offsets (cutter.CompMove), taken by the corrector

    # -- helpers -----------------------------------------------------------------------
    def arc_dialect(self) -> Dialect:
        """The controller whose input-arc rule applies: the dialect's own (generic reads
        arcs as LinuxCNC, the reference interpreter, does)."""
        from postproc.gcode import dialect

        return dialect.get(self.d.reads_arcs_as or self.d)

    def _foreign(self, line: str, lineno: int) -> None:
        """Refuse a line of another dialect naming the dialect to choose, and a construct
        the chosen dialect's controller reads but postproc does not, in that dialect's words."""
        for pattern, construct, instead in self.d.refused:
            m = re.search(pattern, line)
            if m:
                what = construct.format(*m.groups())
                cls = self._construct_error(what) if construct in self.d.expanded_constructs else UnsupportedGcodeError
                raise self.error(cls, f"{self.d.title.split(' ')[0]} {what}", lineno, m.start() + 1, hint=instead)
        other = foreign_dialect(line, self.d.name)
        if other is not None:
            name, title, construct = other
            raise self.error(UnsupportedGcodeError, f"{construct}: a program for {title}", lineno, 1,
                            hint=f"choose --dialect {name} for this program")

    def _construct_error(self, what: str) -> type[UnsupportedGcodeError]:
        """The error class for a refused construct: NeedsExpansion when expanding is allowed
        and the construct is one the expansion stage flattens."""
        if self.may_expand and not what.startswith("polar"):
            return NeedsExpansion
        return UnsupportedGcodeError

    def error(self, cls: type[_E], msg: str, lineno: int, col: int, hint: str | None = None) -> _E:
        return cls(msg, path=self.path, lineno=lineno, col=col, hint=hint)

    def _work_offset(self, lineno: int, col: int) -> list[float]:
        st = self.state
        name = st.work
        if name in self.program_offsets:
            return self.program_offsets[name]
        if name in self.offsets:
            return list(self.offsets[name])
        if self.lenient_setup:
            return [0.0, 0.0, 0.0]
        if name == "G54" and not st.work_explicit:
            if self.require_g54:
                raise self.error(
                    MissingSetupError, "--start gives machine positions, so the value of the work offset G54 "
                    "the program runs in must be given too", lineno, col,
                    hint="give --offset G54=X..,Y..,Z.. (G54=X0,Y0,Z0 if the program's coordinates are "
                         "machine coordinates)")
            # Documented default: a program that never names a work offset runs in
            # G54 taken as zero (program coordinates = machine coordinates); flagged.
            self.implicit_g54 = True
            return [0.0, 0.0, 0.0]
        raise self.error(
            MissingSetupError, f"work offset {name} is used but its value was not given",
            lineno, col, hint=f"give it with --offset {name}=X..,Y..,Z.. (machine-frame mm)")

    def shift(self, g53: bool, lineno: int, col: int) -> tuple[float, float, float]:
        if g53:
            return (0.0, 0.0, 0.0)
        st = self.state
        w = self._work_offset(lineno, col)
        return (w[0] + st.g92[0], w[1] + st.g92[1], w[2] + st.g92[2] + st.tlo)

    def load_tool(self, tool: int) -> None:
        """What a line of a tool change alone (``T<tool> M6``, lexer.TOOL_LINE_RE) does to
        the state, for the readers that take such lines as columns: T selects the tool,
        then M6 loads it (as :meth:`_block` reads them)."""
        st = self.state
        st.tool = tool
        st.spindle_tool = st.tool

    def tool_r(self) -> tuple[float, float, float]:
        if self.tool_vector is not None:
            return self.tool_vector
        st = self.state
        return (0.0, 0.0, -st.tlo) if st.tlo_active else (0.0, 0.0, 0.0)

    def _check_known(self, q1: Sequence[float], lineno: int, col: int) -> None:
        """Refuse a move that needs an axis left at a stored position that was not given."""
        for k, name in self.unknown_after.items():
            if math.isnan(q1[k]):
                raise self.error(
                    MissingSetupError, f"axis {AXES[k]} is at the {name} stored position, which was not given, "
                    "and this move needs it", lineno, col,
                    hint=f"give it with --home {name}=X..,Y..,Z.. (machine mm), or position {AXES[k]} with an "
                         "absolute move first")


@dataclass(slots=True)
class Block:
    """One block as :meth:`Interpreter._block` reads it: its words, what its M and G codes
    set, and what the handler of its motion family reads."""

    lineno: int
    words: list
    vals: dict  # the words by letter, G and M aside (:data:`Vals`)
    gcodes: list = field(default_factory=list)  # (key, word index) of each G code
    mcodes: list = field(default_factory=list)  # (key, word index) of each M code
    block_delete: bool = False  # the block starts with '/'
    tool_change: bool = False  # M6
    event_idx: list = field(default_factory=list)  # words acting before the motion (S, T, M codes), in order
    rotary_changed: bool = False  # an A, B or C word moved a rotary axis
    has_axes: bool = False  # an X, Y or Z word
    motion_key: int | None = None
    motion_idx: int = -1
    g53: bool = False
    g92: int | None = None
    g10: bool = False
    home_code: tuple[int, int] | None = None
    cancel_cycle: bool = False
    g52: bool = False
    lookahead: int | None = None
    work_name: str | None = None
    prefix: list = field(default_factory=list)
    comp: tuple[int, int] | None = None  # G40/G41/G42/G41.1/G42.1: (key, word index)

    def col(self, i: int) -> int:
        return self.words[i].letter_pos + 1

    def gtext(self, i: int) -> str:
        return f"G{self.words[i].number}"

    def prefix_words(self) -> list[str]:
        """The words written before the motion when the block is split: its modal G codes,
        then the words acting before the motion."""
        return self.prefix + [self.words[j].letter + self.words[j].number for j in self.event_idx]


def _work_code(name: str):
    def handler(it: InterpreterCore, b: Block, key: int, i: int) -> None:
        b.work_name = name
        b.prefix.append(b.gtext(i))
    return handler


def _refused_g(what: str, instead: str):
    def handler(it: InterpreterCore, b: Block, key: int, i: int) -> None:
        raise it.error(UnsupportedGcodeError, f"{it.d.title.split(' ')[0]} {what}", b.lineno, b.col(i), hint=instead)
    return handler


def col_of_word(words: list[lexer.Word], i: int) -> int:
    return words[i].letter_pos + 1


def _offset_tuple(v: dict | Iterable[float], partial: bool = False) -> tuple[float, float, float]:
    if isinstance(v, dict):
        d = NAN if partial else 0.0
        up = {str(k).upper(): x for k, x in v.items()}
        return (float(up.get("X", d)), float(up.get("Y", d)), float(up.get("Z", d)))
    t = tuple(float(x) for x in v)
    if len(t) != 3:
        raise ValueError(f"work offset needs 3 values, got {v!r}")
    return t


def start_position(start: dict | Iterable[float] | None) -> list[float]:
    """Machine gauge position at program start: ``{"X":.., "Z":..}`` (any subset) or
    (x, y, z); NaN for an axis not given."""
    if not start:
        return [NAN, NAN, NAN]
    if isinstance(start, dict):
        bad = [k for k in start if str(k).upper() not in AXES]
        if bad:
            raise ValueError(f"start position names unknown axes {bad!r} (X, Y, Z only)")
        up = {str(k).upper(): float(v) for k, v in start.items()}
        return [up.get(a, NAN) for a in AXES]
    t = [float(x) for x in start]
    if len(t) != 3:
        raise ValueError(f"start position needs 3 values, got {start!r}")
    return t
