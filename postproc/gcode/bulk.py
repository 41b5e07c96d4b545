"""The bulk lane: runs of plain absolute moves read and rewritten per chunk.

Most lines of CAM output are ``[N..] [G0|G1|G2|G3] [X..] [Y..] [Z..] [A..] [B..] [C..]
[I..] [J..] [R..] [F..]`` in that order. A chunk of lines is read by the scanner (:mod:`postproc.gcode.scanner`,
the lexer's grammar, compiled), which gives for every such line where its head ends and
where each axis and centre word's number stands, and what its words say
(:func:`postproc.gcode.plainscan.pieces`); the numbers of the whole chunk are then
columns (:class:`Block`). Consecutive plain lines read while the modal
state is simple (:func:`state_allows`) form a :class:`Run`: reading one only advances
the modal state to its last line; the nominal targets of all the chunk's runs are then
made at once (positions carried forward where a line does not name an axis).

A run holds three kinds of lines:

- straight moves (G0/G1, or no motion word under G0/G1);
- arcs in the XY plane with centre words (G2/G3 with I and/or J) or a radius (R): their
  centre is found from the run's columns, and the controller's checks the interpreter
  makes (zero radius, end radius; for R, ends that coincide or a radius short of half
  the chord) end the run before an arc that fails them, so the interpreter reads and
  reports it. An R-form arc is always written by the general emitter, from its plan. A
  line with no motion word is an arc or a straight move by the modal motion, and a run
  ends before one whose words do not fit it (:meth:`Block.motion_end`);
- lines that move nothing (blank, comments, S words, M0 M1 M3-M5 M7-M9: :data:`_NEUTRAL`;
  a tool change alone: :data:`_TOOL`; a feed alone, which sets the modal feed):
  written whole, no move, no word added; a run never starts with one.

Rotary words (A, B, C after Z) pass through as written; each
run line carries the rotary positions a line read by the interpreter has
(:attr:`Run.rot`), for the engine's context.

A straight move that sets the tool length first (``G0 G43 H2 Z25``, :attr:`Block.tlo`)
starts a run of its own: the length is set (``Interpreter.set_tool_length``), then the
run read (split, it is written with the G43 H.. words on its first line, as the
interpreter's move is).

After the chunk's targets are corrected, the comparisons of old and new values of every
run line are vectorised and the new numbers formatted in one operation; each run is then
written in program order, each line its own text with the new numbers put in at their
places (:func:`postproc.gcode.runwords.join_rows`). The words an axis does not name
but whose corrected position moves (squareness) need a sequential pass, because whether
one is written depends on the position the words before it reached; so do an arc's
centre words, which the planner's :class:`postproc.gcode.vplan.ArcHint` gives for the
end points as written. A line the planner splits, and an arc whose hint does not hold
there, are written by the general emitter between the run's other lines. The result is byte
for byte that of the general path (tests run both on the same programs); every line
that is not plain takes it. Lines end as they do in the program (LF, CRLF or a lone CR):
a run's line is written with its own ending.

A run's lines are numbered from its first (:attr:`Run.lineno`) on, but in a block of an
expanded program (:meth:`Block.set_source`), where a loop's body is read once per pass
and a subprogram's lines come from its own file: each line then has its source line
(:meth:`Run.line`, :meth:`Run.linenos`), which the table and every error name.
"""

from __future__ import annotations

import math
import re
from bisect import bisect_left, bisect_right
from collections.abc import Callable, Iterator, Mapping
from typing import Protocol, TypeAlias, final

import numpy as np

from postproc.errors import PostprocError
from postproc.gcode import emit, lexer, numfmt, plainscan, runwords, scanner
from postproc.gcode.emitter import FIT_BUDGET
from postproc.gcode.geometry import R_TOLERANCE
from postproc.gcode.interp import MIN_ARC_RADIUS_MM, Arc, Interpreter, Move
from postproc.gcode.moves import Kind, Role
from postproc.gcode.state import ARC_CCW, ARC_CW, LINE, RAPID
from postproc.gcode.vplan import ArcHint, BoolArray, FloatArray, IntArray, KindArray, Plan

# Digits before the point of a word's number from which the chunk is the interpreter's
# (ten: 1e9, interp_core.MAX_WORD_VALUE, and beyond; a 400-digit one reads as inf)
_LONG_DIGITS = 10
_CODE = (RAPID, LINE, ARC_CW, ARC_CCW)  # by the G number (plainscan.Pieces.motion)
# A line that moves nothing (lexer.QUIET_LINE_RE): inside a run it is written as it is,
# as the interpreter would.
_NEUTRAL = re.compile(lexer.QUIET_LINE_RE + r"\r?\n?")
# A tool change and nothing else (``T2 M6``, ``N40 M06 T02 (FLAT D6)``): it moves nothing
# and changes nothing of a run's geometry (the tool length offset stays what G43 set),
# only the tool the interpreter holds (group 1 or 2: the T number), which the run sets
# when it is read (:func:`read_run`).
_TOOL = re.compile(lexer.TOOL_LINE_RE + r"\r?\n?")
# The G43 H.. of a line's head (a straight move that sets the tool length first).
_TLO = re.compile(lexer.TOOL_LENGTH_RE + r"(\d++)")
_XY = (0, 1, 2)  # the plane of a run's arcs (G17) and its normal
# Most lines the run writer takes in one stretch (see _emit_rows): an arc whose hint
# fails unexpectedly makes the writer read again at most this many lines.
MAX_STRETCH = 2048

#: where text is written (what it returns is ignored)
Write: TypeAlias = Callable[[str], object]


class Mark(Protocol):
    """Told, while a run is written, where the text written next comes from (emit_run),
    and when the writer's state may be saved."""

    def __call__(self, j: int, whole: bool) -> None: ...

    def save(self, y: int) -> None:
        """Save the writer's state: the run is written on from its block line ``y``
        (``emit_run``'s ``resume``) if the writer must go back."""
        ...


Point: TypeAlias = tuple[float, float, float]
#: an arc of a run: its centre (machine mm) and whether it turns clockwise
RunArc: TypeAlias = plainscan.RunArc
# the r_idx of a run's R-form arc (RunMove.arc) until its Move is made (RunMove.to_move):
# not a word index, only >= 0 (the bulk planner leaves an R-form arc to the general one)
R_FORM = 1 << 30


class _Report(Protocol):
    """The counts the bulk writer adds to (:class:`postproc.gcode.pipeline.CorrectReport`)."""

    lines_out: int
    moves: int
    words_changed: int
    lines_changed: int
    arcs_kept: int


class _Options(Protocol):
    """The option the bulk writer reads (:class:`postproc.gcode.pipeline.CorrectOptions`)."""

    @property
    def tolerance_mm(self) -> float: ...


class Corrector(Protocol):
    """What the bulk writer uses of :class:`postproc.gcode.pipeline.Corrector`: the
    emitted position and motion, the report, the options and the general emitter."""

    emitted_motion: int | None

    @property
    def qe(self) -> list[float]: ...
    @property
    def report(self) -> _Report: ...
    @property
    def opt(self) -> _Options: ...

    def emit_move(self, line: str, mv: Move, target: list[float], plan: Plan | None, write: Write) -> None: ...

    def emit_hinted_arc(self, line: str, mv: Move, target: list[float], hint: ArcHint, write: Write) -> None: ...


def last_index(present: BoolArray) -> IntArray:
    """For each row, the index of the last present row at or before it (-1: none)."""
    idx = np.where(present, np.arange(len(present)), -1)
    np.maximum.accumulate(idx, out=idx)
    return idx


class RunMove:
    """A line of a run as a move, for the general emitter (a line the planner splits, or
    one whose motion word the controller needs written)."""

    __slots__ = ("lineno", "kind", "q0", "q1", "r", "shift", "unit", "rotary", "arc", "arc_absolute", "feed", "path")
    role = Role.MOVE  # a motion block written from its words

    def __init__(self, run: Run, lineno: int, kind: int, q0: Point, q1: Point, feed: float) -> None:
        self.lineno = lineno
        self.kind = kind
        self.q0 = q0
        self.q1 = q1
        self.r = run.r  # the run's tool vector, offsets, unit and arc-centre mode
        self.shift = run.shift
        self.unit = run.unit
        self.rotary: dict[str, float] = {}
        self.arc: Arc | None = None
        self.arc_absolute = run.arc_absolute
        self.feed = feed
        self.path: str | None = None  # the file of its line (None: the program's own)

    def to_move(self, line: str) -> Move:
        """The general Move of the same line (a line written one by one: an arc, a line the
        planner splits, or one whose motion word the controller needs)."""
        words = lexer.scan_words(line)
        if words is None:  # a plain line: words and blanks only
            raise AssertionError(f"line {self.lineno} of a run is not plain: {line!r}")
        idx = [-1, -1, -1]
        centre_idx = [-1, -1]
        feed_idx = motion_idx = r_idx = -1
        prefix: list[str] = []
        for i, w in enumerate(words):
            letter = w.letter
            if letter in "XYZ":
                idx["XYZ".index(letter)] = i
            elif letter == "F":
                feed_idx = i
            elif letter == "G":
                if w.number.lstrip("0") == "43":  # G43 H..: the words the interpreter keeps for a split
                    h = next(x for x in words if x.letter == "H")
                    prefix.append(f"G{w.number} H{h.number}")
                else:
                    motion_idx = i
            elif letter in "IJ":
                centre_idx["IJ".index(letter)] = i
            elif letter == "R":
                r_idx = i
        arc = self.arc
        aux: tuple[int, ...] = ()
        if arc is not None:
            if arc.r_idx < 0:
                arc = Arc(arc.center, arc.plane, arc.clockwise, 1, (centre_idx[0], centre_idx[1]), -1)
                aux = tuple(i for i in centre_idx if i >= 0)
            else:
                arc = Arc(arc.center, arc.plane, arc.clockwise, 1, (-1, -1), r_idx)
                aux = (r_idx,)
        return Move(self.lineno, self.kind, self.q0, self.q1, self.r, self.shift, self.unit, False,
                    self.arc_absolute, words, (idx[0], idx[1], idx[2]), feed_idx, False, self.feed, self.rotary, arc,
                    prefix,
                    Role.MOVE, motion_idx, aux, path=self.path)


def tlo_col(line: str) -> int:
    """The column of a line's G43 word (of :attr:`Block.tlo`), for its errors."""
    m = _TLO.search(line)
    return m.start() + 1 if m is not None else 1


def prime_shift(interp: Interpreter) -> bool:
    """Compute the offsets of absolute words in the current state ; False if they cannot be (the general path then reports why)."""
    if interp.run_shift is None:
        try:
            shift = interp.shift(False, 0, 0)  # no line: its error is dropped here
        except PostprocError:
            return False
        interp.run_shift = shift
        interp.run_r = interp.tool_r()
    return True


def state_allows(interp: Interpreter, motion_word: bool = False) -> bool:
    """Whether the modal state lets a run of plain lines start at the next line (``motion_word``:
    that line names its own motion, so the modal motion does not matter; the run then
    takes only the lines that fit the modal motion: :meth:`Block.motion_end`)."""
    st = interp.state
    return (not interp.ended and interp.modal_call is None and st.frame is None
            and not st.incremental and not st.inverse_time and interp.run_shift is not None
            and st.comp == 400 and not st.comp_edge  # moves under cutter compensation: postproc.gcode.cutter
            and (motion_word or st.motion in (RAPID, LINE, ARC_CW, ARC_CCW))
            and not (math.isnan(st.pos[0]) or math.isnan(st.pos[1]) or math.isnan(st.pos[2])))


class Block:
    """One chunk of lines, with the plain lines' words in columns."""

    def __init__(self, lines: list[str], pieces: plainscan.Pieces) -> None:
        n = len(lines)
        self.lines = lines
        # where the head ends and each X, Y, Z, I, J number stands on each line (offsets
        # from its start: plainscan.Pieces.at)
        self.at = pieces.at
        self.has: list[BoolArray] = []  # X, Y, Z, I, J named on each line
        self.ov: list[FloatArray] = []  # their values (0 where not named)
        self.ovl: list[list[float]] = pieces.value
        self.frac: list[IntArray] = []  # digits after the point of X, Y, Z
        self.last: list[IntArray] = []  # the last line at or before each that names X, Y, Z
        for k in range(5):  # X, Y, Z, I, J
            has = np.frombuffer(bytes(pieces.has[k]), dtype=bool)  # a byte per bool (read only)
            self.has.append(has)
            self.ov.append(np.fromiter(pieces.value[k], dtype=float, count=n))
            if k < 3:
                self.frac.append(np.fromiter(pieces.frac[k], dtype=int, count=n))
                self.last.append(last_index(has))
        # lines naming X or Y after Z (plainscan.Pieces.late): cut from their runs, written
        # by the general emitter
        self.late: list[int] = [i for i, v in enumerate(pieces.late) if v] if any(pieces.late) else []
        # R-form arcs (their R word is in the rest): its value on each line (0 where none)
        self.has_r = np.frombuffer(bytes(pieces.has[5]), dtype=bool)
        self.r_value: list[float] = pieces.value[5]
        # rotary words (A, B, C: passed through, in the piece after Z): which lines name
        # each, its value; None where no line names one
        self.rotary: list[tuple[str, list[bool], list[float]]] | None = [
            (letter, pieces.has[6 + r], pieces.value[6 + r]) for r, letter in enumerate("ABC")
            if any(pieces.has[6 + r])] or None
        self.motion_l: list[int] = pieces.motion  # the G word's number, 0 to 3 (-1: none)
        motion = np.fromiter(pieces.motion, dtype=np.int8, count=n)
        no_g = motion < 0
        last_g = last_index(~no_g)
        # G2/G3 lines with centre words (I, J) or a radius (R) are arcs, G0/G1 lines with
        # neither straight moves; a line without a motion word is shaped as one or the
        # other by its words, and a run takes it only under the motion it needs
        # (read_run: :meth:`motion_end`); a line with both is the interpreter's
        self.arc = (motion == 2) | (motion == 3)
        self.has_l: list[list[bool]] = pieces.has
        centre = self.has[3] | self.has[4]
        arc_shape = centre ^ self.has_r
        moving = (self.has[0] | self.has[1] | self.has[2]) & ~(centre & self.has_r) & (no_g | (self.arc == arc_shape))
        self._modal_shapes(moving, no_g, arc_shape, last_g)
        # the feed word of each line: whether it names one and its value
        self.f_has: list[bool] = pieces.has[plainscan.F]
        self.f_value: list[float] = pieces.value[plainscan.F]
        neutral = self._inert(np.flatnonzero(~moving & ~self.arc & ~centre & ~self.has_r & no_g).tolist(), pieces.tlo)
        self._tool_lengths(moving, arc_shape, pieces.tlo)
        self.neutral = neutral
        self.neutral_rows: list[int] = np.flatnonzero(neutral).tolist()
        self.last_moving: list[int] = last_index(~neutral).tolist()
        self.plain = moving | neutral
        if self.tlo:
            self.plain[self.tlo_rows] = True
        self.last_g: list[int] = last_g.tolist()
        self.last_g_arr = last_g
        self.motion = motion
        self.last_f: list[int] = last_index(np.frombuffer(bytes(self.f_has), dtype=bool)).tolist()
        self.last_l: list[list[int]] = [a.tolist() for a in self.last]
        self.runs: list[Run] = []
        # the source line of each line, when they are not consecutive (an expanded
        # program's: :meth:`set_source`); None: a run's lines follow its first
        self.src: list[int] | None = None
        self.src_arr: IntArray | None = None
        self.src_files: list[str | None] | None = None  # ... and its file (set_source)

    def _modal_shapes(self, moving: BoolArray, no_g: BoolArray, arc_shape: BoolArray, last_g: IntArray) -> None:
        """The lines a run may take only under some modal motion (see
        :meth:`motion_end`): :attr:`arc_rows` (G2/G3 lines, and the moving lines without
        a motion word shaped as arcs), the moving lines without a motion word by shape,
        the lines naming a motion word, and those without one whose shape is not the
        motion of the last line before them naming one."""
        modal = moving & no_g
        modal_arc = modal & arc_shape
        self.arc_rows: list[int] = np.flatnonzero(self.arc | modal_arc).tolist()
        self._modal_arcs: list[int] = np.flatnonzero(modal_arc).tolist()
        self._modal_lines: list[int] = np.flatnonzero(modal & ~arc_shape).tolist()
        self._g_rows: list[int] = np.flatnonzero(~no_g).tolist()
        named = last_g >= 0
        self._wrong_shape: list[int] = np.flatnonzero(
            modal & named & (self.arc[np.maximum(last_g, 0)] != arc_shape)).tolist()

    def motion_end(self, a: int, b: int, motion0: int | None) -> int:
        """The first of lines ``a:b`` (a stretch of plain lines) that a run starting
        under the modal ``motion0`` cannot take, or ``b``: a line without a motion word
        shaped as an arc (centre words or R) where the modal motion is straight, or as
        a straight move where it is an arc; the interpreter reads (or refuses) it."""
        g = self._g_rows
        k = bisect_left(g, a)
        first_g = g[k] if k < len(g) and g[k] < b else b  # before it, the modal motion is motion0
        end = b
        if first_g > a:
            if motion0 in (RAPID, LINE):
                wrong = [self._modal_arcs]
            elif motion0 in (ARC_CW, ARC_CCW):
                wrong = [self._modal_lines]
            else:  # no motion the line could move in
                wrong = [self._modal_arcs, self._modal_lines]
            for rows in wrong:
                k = bisect_left(rows, a)
                if k < len(rows) and rows[k] < min(end, first_g):
                    end = rows[k]
        rows = self._wrong_shape
        k = bisect_left(rows, first_g)
        if k < len(rows) and rows[k] < end:
            end = rows[k]
        return end

    def _inert(self, candidates: list[int], tlo: list[int]) -> BoolArray:
        """The lines among ``candidates`` (no word of a move) that move nothing (blank,
        comments, S and some M words, a tool change alone: :attr:`tools`; ``tlo``: the
        H number of each line's G43 H, -1 where none), written as they are."""
        lines, feed = self.lines, self.f_has
        neutral = np.zeros(len(lines), dtype=bool)
        match, tool = _NEUTRAL.fullmatch, _TOOL.fullmatch
        self.tools: dict[int, int] = {}  # line -> the tool a tool-change line loads
        rotary = self.rotary or ()
        for i in candidates:
            line = lines[i]
            if not match(line):
                m = tool(line)
                if m is not None:
                    self.tools[i] = int(m.group(1) or m.group(2))
                # a feed alone (``F300``, ``N20 F300``; a plain line without a motion word
                # here): the modal feed (Block.last_f), no move
                elif not (feed[i] and tlo[i] < 0 and not any(has[i] for _r, has, _v in rotary)):
                    continue
            neutral[i] = True
        return neutral

    def _tool_lengths(self, moving: BoolArray, arc_shape: BoolArray, tlo: list[int]) -> None:
        """The straight moves that set the tool length first (G43 H..: :attr:`tlo`, line ->
        H; ``tlo``: the H number of each line's, -1 where none): a run starts at one
        (set_tool_length before it is read); an arc that does is the interpreter's
        (``moving`` loses both; ``arc_shape``: the lines whose words are an arc's, which a
        moving line's motion word, where it has one, agrees with)."""
        self.tlo: dict[int, int] = {}
        if max(tlo, default=-1) >= 0:  # (most blocks have none)
            for i in np.flatnonzero(np.fromiter(tlo, dtype=np.int64, count=len(tlo)) >= 0).tolist():
                if moving[i]:
                    moving[i] = False
                    if not arc_shape[i]:
                        self.tlo[i] = tlo[i]
        self.tlo_rows: list[int] = sorted(self.tlo)

    def set_source(self, src: list[int], files: list[str | None] | None = None) -> None:
        """Give each of the block's lines its source line (``src``, one per line: an
        expanded program's, where a loop's body is read once per pass and a subprogram's
        lines come from another file) and its file (``files``); the runs read from it
        then number their lines so, and name their files."""
        self.src = src
        self.src_arr = np.array(src, dtype=int)
        self.src_files = files

    def code(self, i: int) -> int:
        """Motion of line i's G word (G0 to G3, G00 to G03)."""
        return _CODE[self.motion_l[i]]


def scan(lines: list[str]) -> Block | None:
    """The chunk ``lines`` as a :class:`Block`, or None when it cannot be scanned as a
    whole (lines not split as the scanner splits them, a number too long)."""
    text = "".join(lines)
    cols = scanner.scan(text)
    if len(cols) != len(lines):  # lines not split as the scanner splits them
        return None
    if cols.longest >= _LONG_DIGITS:
        return None  # the interpreter refuses a value beyond interp.MAX_WORD_VALUE, at its place
    return Block(lines, plainscan.pieces(text, cols))


@final
class Run:
    """Plain lines ``a:b`` of a block read in one go; see the module docstring."""

    __slots__ = ("block", "a", "b", "lineno", "unit", "shift", "r", "arc_absolute", "decimals", "q0", "motion0",
                 "feed0", "q1", "trow", "cut", "arcs", "inert", "_arc_rows", "rot")
    block: Block
    a: int
    b: int
    lineno: int  # of line a (the others: line())
    unit: float  # mm per program unit
    shift: Point  # machine = program x unit + shift
    r: Point  # tool vector
    arc_absolute: bool
    decimals: int  # of the words written
    q0: Point  # the nominal position before the run
    motion0: int | None  # modal motion and feed before the run
    feed0: float
    q1: FloatArray  # (b - a, 3) nominal targets (finish_block)
    trow: int  # row of line a among the chunk's targets

    def __init__(self) -> None:
        self.cut: list[int] = []  # lines (within the run) written one by one: arcs, lines the planner splits
        self.arcs: dict[int, RunArc] = {}  # line (within the run) -> its arc
        self.inert: list[int] = []  # lines (within the run) that move nothing (blank, comment, S/M words)
        self._arc_rows: list[int] | None = None
        # the rotary axes' positions at each line, as a line read by the interpreter has them
        # (Move.rotary: {} before the program names one); None: none is named
        self.rot: list[dict[str, float]] | None = None

    def line(self, j: int) -> int:
        """The source line of the run's line ``j`` (an index within it)."""
        src = self.block.src
        return self.lineno + j if src is None else src[self.a + j]

    def path(self, j: int) -> str | None:
        """The file of the run's line ``j`` (None: the program's own)."""
        files = self.block.src_files
        return None if files is None else files[self.a + min(j, len(self) - 1)]

    def paths(self) -> list[str | None] | None:
        """The file of each of the run's lines, or None when they are the program's own."""
        files = self.block.src_files
        return None if files is None else files[self.a:self.b]

    def text_line(self, n: int) -> int:
        """The source line of the run's line ``n`` (lines past its end numbered on from
        its last)."""
        last = len(self) - 1
        return self.line(n) if n <= last else self.line(last) + n - last

    def inert_at(self, j: int) -> bool:
        """Whether the run's line ``j`` moves nothing (it is written as it is)."""
        return j < len(self) and bool(self.block.neutral[self.a + j])

    def linenos(self) -> IntArray:
        """The source line of each of the run's lines."""
        arr = self.block.src_arr
        return np.arange(self.lineno, self.lineno + self.b - self.a) if arr is None else arr[self.a:self.b]

    def kinds(self) -> KindArray:
        """The table kind of each of the run's lines (:class:`postproc.gcode.moves.Kind`:
        STILL where it moves nothing, else the motion it moves in, G0 to G3)."""
        blk, a, b = self.block, self.a, self.b
        g = blk.last_g_arr[a:b]
        before = -1 if self.motion0 is None else self.motion0 // 10  # a moving line then names its motion
        # Kind.RAPID .. Kind.ARC_CCW are the G number plus one
        kinds = (np.where(g >= a, blk.motion[np.maximum(g, 0)], before) + 1).astype(np.int8)
        kinds[blk.neutral[a:b]] = Kind.STILL
        return kinds

    def arc_rows(self) -> list[int]:
        """The block lines of the run's arcs, in order (made once)."""
        if self._arc_rows is None:
            self._arc_rows = sorted(self.a + j for j in self.arcs)
        return self._arc_rows

    def __len__(self) -> int:
        return self.b - self.a


def _arc_rows(interp: Interpreter, block: Block, a: int, b: int, unit: float, shift: Point,
              q0: Point) -> tuple[int, dict[int, RunArc]]:
    """The arcs among lines ``a:b``: ``(end, {line within the run: (centre, clockwise, turn)})``,
    ``end`` the first line the run cannot take (b when it takes every line): an arc out
    of the XY plane, of zero radius, whose end radius its controller refuses, or an R
    arc whose ends coincide or whose radius is short of half its chord (the interpreter
    reports those)."""
    arc_rows = block.arc_rows
    lo = bisect_left(arc_rows, a)
    if lo == len(arc_rows) or arc_rows[lo] >= b:
        return b, {}
    if interp.state.plane != 170:
        return arc_rows[lo], {}
    rule = interp.arc_dialect()
    # an end radius within the rule's tolerance at radius 0 (the least it has: every
    # tolerance grows with the radius) passes without asking the rule
    sure = rule.arc_end_radius_tolerance(0.0, unit)
    lx, ly, lz = block.last_l[:3]
    vx, vy, vz, vi, vj = block.ovl[:5]
    stop, arcs = plainscan.run_arcs(
        arc_rows[lo:bisect_left(arc_rows, b, lo)], (lx, ly, lz, vx, vy, vz),
        (vi, vj, block.has_l[3], block.has_l[4], block.has_l[5], block.r_value),
        (block.motion_l, block.last_g, interp.state.motion == ARC_CW),
        (a, unit, shift, q0, interp.state.arc_absolute), (MIN_ARC_RADIUS_MM, sure, *R_TOLERANCE), rule.arc_end_radius_ok)
    return (b if stop < 0 else stop), arcs


def read_run(interp: Interpreter, block: Block, a: int, b: int, lineno: int, decimals: int) -> Run | None:
    """Interpret the plain lines ``a:b`` of ``block``, or as many of them as a run
    takes (``run.b``; None: not even the first, an arc the interpreter must read):
    advance the modal state to the end of the run. The caller checks
    :func:`state_allows`."""
    st = interp.state
    unit = 25.4 if st.inch else 1.0
    shift = interp.run_shift
    if shift is None:
        raise AssertionError("a run read before the offsets of its words are known (prime_shift)")
    pos = st.pos
    q0 = (pos[0], pos[1], pos[2])
    tr = block.tlo_rows
    if tr:  # a run ends before a line that sets the tool length
        k = bisect_right(tr, a)
        if k < len(tr) and tr[k] < b:
            b = tr[k]
    b = block.motion_end(a, b, st.motion)
    b, arcs = _arc_rows(interp, block, a, b, unit, shift, q0)
    if b == a:
        return None
    run = Run()
    run.block, run.a, run.b, run.lineno = block, a, b, lineno
    run.unit = unit
    run.shift = shift
    run.r = interp.run_r
    run.arc_absolute = st.arc_absolute
    run.decimals = decimals
    run.q0 = q0
    run.motion0 = st.motion
    run.feed0 = st.feed
    run.arcs = arcs
    if block.late:
        late = block.late
        run.cut = [y - a for y in late[bisect_left(late, a):bisect_left(late, b)]]
    nr = block.neutral_rows
    if nr:
        run.inert = [y - a for y in nr[bisect_left(nr, a):bisect_left(nr, b)]]
        tools = block.tools
        changes = [tools[a + j] for j in run.inert if a + j in tools] if tools else None
        if changes:
            interp.load_tool(changes[-1])  # the run's last tool change
    if block.rotary is not None or interp.used_rotary:
        run.rot = _rotary_rows(interp, block, a, b)
    pos = list(st.pos)
    e = b - 1
    for k in range(3):
        i = block.last_l[k][e]
        if i >= a:
            pos[k] = block.ovl[k][i] * unit + shift[k]
    st.pos = pos
    st.motion, st.feed = _modal_at(run, b)
    interp.motion_word = block.motion_l[e] >= 0
    block.runs.append(run)
    return run


def _rotary_rows(interp: Interpreter, block: Block, a: int, b: int) -> list[dict[str, float]]:
    """The rotary positions of lines ``a:b`` (the interpreter's ``Move.rotary``: its
    positions once the program has named a rotary axis, {} before), the interpreter's
    state advanced to their end."""
    st, used, g92 = interp.state, interp.used_rotary, interp.rotary_g92
    cur = dict(st.rotary)
    named = [(letter, has, val) for letter, has, val in block.rotary or () if any(has[a:b])]
    if not named:
        return [dict(cur) if used else {}] * (b - a)  # (one dict for every line: none changes it)
    rows: list[dict[str, float]] = []
    for y in range(a, b):
        for letter, has, val in named:
            if has[y]:
                cur[letter] = val[y] + g92.get(letter, 0.0)
                used.add(letter)
        rows.append(dict(cur) if used else {})
    st.rotary = cur
    return rows


def arc_moves(run: Run) -> list[tuple[int, RunMove]]:
    """The arcs of a run (after :func:`finish_block`) as (line within the run, RunMove)."""
    if not run.arcs:
        return []
    q1 = run.q1.tolist()  # the targets as tuples of floats, converted at once
    return [(j, _row_move(run, j, tuple(q1[j - 1]) if j else run.q0, tuple(q1[j]))) for j in run.arcs]


def finish_block(block: Block) -> None:
    """Nominal targets ``q1`` of every run of the block (after all were read)."""
    runs = block.runs
    if not runs:
        return
    lengths = [r.b - r.a for r in runs]
    idx = np.concatenate([np.arange(r.a, r.b) for r in runs])
    starts = np.concatenate([[0], np.cumsum(lengths)[:-1]])
    unit = np.repeat([r.unit for r in runs], lengths)
    shift = np.repeat(np.array([r.shift for r in runs], dtype=float), lengths, axis=0)
    q0 = np.array([r.q0 for r in runs], dtype=float)
    q = np.empty((len(idx), 3))
    for k in range(3):
        has = block.has[k][idx]
        val = block.ov[k][idx] * unit + shift[:, k]
        # a run's first line that does not name the axis starts from the run's start
        first_missing = ~has[starts]
        val[starts[first_missing]] = q0[first_missing, k]
        has[starts] = True
        q[:, k] = val[last_index(has)]
    for r, s, n in zip(runs, starts.tolist(), lengths, strict=True):
        r.q1 = q[s:s + n]


class Emission:
    """What the emitter needs of a block's run lines once their targets are known (per
    axis X, Y, Z: the lists of that axis)."""

    __slots__ = ("nums", "unnamed", "edits_cum", "changed_cum", "named_edits")
    nums: list[list[str]]  # by line: the new number text of the named word ("": its own stays)
    unnamed: list[runwords.Unnamed]  # the lines that do not name the axis and the words they may add
    named_edits: list[int]  # by line: named words that change
    edits_cum: list[int]  # cumulative sums of named_edits, from 0
    changed_cum: list[int]  # cumulative count of lines with a named word that changes, from 0


def prepare_emission(block: Block, T: FloatArray) -> Emission:
    """Vectorised part of writing the block's runs (``run.trow``: first row in T).

    Named words: the new number where it changes. Axes a line does not name: the
    word that would be added (its text and the position it reaches), for the
    sequential decision in :func:`emit_run`.
    """
    runs = block.runs
    lengths = [r.b - r.a for r in runs]
    idx = np.concatenate([np.arange(r.a, r.b) for r in runs])
    trow = np.concatenate([np.arange(r.trow, r.trow + n) for r, n in zip(runs, lengths, strict=True)])
    unit = np.repeat([r.unit for r in runs], lengths)
    shift = np.repeat(np.array([r.shift for r in runs], dtype=float), lengths, axis=0)
    dec = np.repeat([r.decimals for r in runs], lengths)
    n = len(block.lines)
    em = Emission()
    em.nums, em.unnamed = [], []
    named = np.zeros(n, dtype=int)
    for k in range(3):
        has = block.has[k][idx]
        tk = T[trow, k]
        v = (tk - shift[:, k]) / unit
        # the new number texts (a word within half an output step of its value keeps its
        # text); "" where the line's own stays
        on = np.flatnonzero(has)
        rows_on = idx[on]
        nums = [""] * n
        changed, _texts = numfmt.word_texts(v[on].tolist(), block.ov[k][rows_on].tolist(),
                                            block.frac[k][rows_on].tolist(), dec[on].tolist(),
                                            (nums, rows_on.tolist()))
        if changed:
            named[rows_on[changed]] += 1
        em.nums.append(nums)
        miss = np.flatnonzero(~has & ~block.neutral[idx])  # an inert line gets no word
        vm = v[miss]
        rows = idx[miss]
        em.unnamed.append(runwords.Unnamed(
            "XYZ"[k], rows.tolist(), tk[miss].tolist(), vm.tolist(), dec[miss].tolist(),
            block.last[k][rows].tolist(), (nums, block.ovl[k], block.has_l[k], block.lines)))
    em.named_edits = named.tolist()
    em.edits_cum = np.concatenate([[0], np.cumsum(named)]).tolist()
    em.changed_cum = np.concatenate([[0], np.cumsum(named > 0)]).tolist()
    return em


def _row_move(run: Run, j: int, q0: Point | None = None, q1: Point | None = None) -> RunMove:
    """Line ``j`` of a run (an index within it) as a RunMove, for the general emitter
    (``q0``, ``q1``: its start and target, when the caller has them)."""
    blk = run.block
    a = run.a
    y = a + j
    # the motion and feed in force at the line: its own words, or the last ones before it
    # in the run, or those the run started with
    g, f = blk.last_g[y], blk.last_f[y]
    motion = blk.code(g) if g >= a else run.motion0
    if motion is None:  # a run's first line names its motion when none is modal
        raise AssertionError(f"line {run.line(j)} of a run without a motion")
    if q0 is None:
        q0 = run.q0 if j == 0 else tuple(run.q1[j - 1].tolist())
    if q1 is None:
        q1 = tuple(run.q1[j].tolist())
    src, files = blk.src, blk.src_files  # (Run.line and Run.path of line j)
    mv = RunMove(run, run.lineno + j if src is None else src[y], motion, q0, q1,
                 blk.f_value[f] if f >= a else run.feed0)
    if files is not None:
        mv.path = files[y]
    if run.rot is not None:
        mv.rotary = run.rot[j]
    arc = run.arcs.get(j)
    if arc is not None:
        mv.arc = Arc(arc[0], 170, arc[1], 1, (-1, -1), R_FORM if blk.has_r[y] else -1)
    return mv


def emit_run(corrector: Corrector, run: Run, em: Emission, T: FloatArray, write: Write,
             hints: Mapping[int, ArcHint], mark: Mark | None = None, resume: int = -1) -> None:
    """Write the corrected lines of ``run`` (targets prepared in ``em``; ``hints``: the
    planner's :class:`postproc.gcode.vplan.ArcHint` of each of the run's arcs, by row
    of T). ``mark(j, whole)`` is told where the text written next comes from: line ``j``
    of the run alone (``whole``: the general emitter's, one or more lines), or its lines
    one by one from ``j`` on; ``mark.save(y)`` before an arc whose hint does not hold is
    handed to the general emitter (which may need its plan made first). ``resume``: that
    arc's block line, where ``mark.save`` was told it: the writer's state is as it was
    then, and the run is written on from that arc."""
    s = run.a
    if resume >= 0:  # saved before its line went to the general emitter: it goes there again
        s = _general_row(corrector, run, T, write, hints, resume, mark)
    while s < run.b:
        s = _motion_row(corrector, run, T, write, hints, s, mark)
        if s < run.b:
            s = _emit_rows(corrector, run, em, T, write, hints, s, mark)


def _motion_row(corrector: Corrector, run: Run, T: FloatArray, write: Write, hints: Mapping[int, ArcHint],
                s: int, mark: Mark | None) -> int:
    """Where the controller's modal motion differs from the program's at the first line
    from block line ``s`` that moves (after an arc written as lines or split), and that
    line names no motion word: write the lines before it as they are and it by the
    general emitter, which adds the motion word; returns the line to write on from."""
    blk = run.block
    a, b = run.a, run.b
    f = s
    while f < b and blk.neutral[f]:
        f += 1
    if f == b or blk.motion_l[f] >= 0 or corrector.emitted_motion == _modal_at(run, f)[0]:
        return s
    if f > s:
        write("".join(blk.lines[s:f]))
        corrector.report.lines_out += f - s
    if f - a in run.arcs:
        return _general_row(corrector, run, T, write, hints, f, mark)
    line = blk.lines[f]
    if mark is not None:
        mark(f - a, True)
    corrector.emit_move(line, _row_move(run, f - a).to_move(line), T[run.trow + f - a].tolist(), None, write)
    if mark is not None:
        mark(f + 1 - a, False)
    return f + 1


def _emit_rows(corrector: Corrector, run: Run, em: Emission, T: FloatArray, write: Write,
               hints: Mapping[int, ArcHint], s: int, mark: Mark | None) -> int:
    """Write lines ``s:`` of ``run``, up to the first arc whose hint does not hold for
    the end points as written, which the general emitter then writes; returns the
    line after the last one written. One call takes a stretch of the run: up to the
    first arc whose hint the planner expects to fail there (:attr:`ArcHint.edge`), and
    at most :data:`MAX_STRETCH` lines, so that the pass over the words to add, made
    again from the line after such an arc, reads each line of a long run about once."""
    arcs = run.arc_rows()
    first = bisect_left(arcs, s)
    b = _stretch_end(run, arcs, first, s, hints)
    st = _Stretch(run, em, s, b, arcs[first:bisect_left(arcs, b, first)], list(corrector.qe))
    final = [_added_words(st, k, corrector.qe[k]) for k in range(3)]
    stop, arc_edit = _arc_stop(corrector, st, hints)
    if stop > s:
        _write_stretch(corrector, st, stop, arc_edit, write)
        moved = run.block.last_moving
        p = moved[stop - 1]
        corrector.qe[:] = final if stop == b else (st.want[p] if p >= s else st.qe0)
    if stop == b:
        return b
    return _general_row(corrector, run, T, write, hints, stop, mark)


def _general_row(corrector: Corrector, run: Run, T: FloatArray, write: Write, hints: Mapping[int, ArcHint],
                 y: int, mark: Mark | None) -> int:
    """Write block line ``y`` of ``run``, an arc the hint does not settle there (or whose
    centre word must be added), by the general emitter; returns the line after it."""
    j = y - run.a
    line = run.block.lines[y]
    if mark is not None:
        mark.save(y)
        mark(j, True)
    corrector.emit_hinted_arc(line, _row_move(run, j).to_move(line), T[run.trow + j].tolist(),
                               hints[run.trow + j], write)
    if mark is not None:
        mark(j + 1, False)
    return y + 1


def _stretch_end(run: Run, arcs: list[int], first: int, s: int, hints: Mapping[int, ArcHint]) -> int:
    """Where the stretch from line ``s`` ends: at most :data:`MAX_STRETCH` lines, and
    after the first arc whose hint the planner expects to fail (``arcs[first]`` is the
    first arc at or after ``s``)."""
    end = min(run.b, s + MAX_STRETCH)
    trow = run.trow - run.a
    for x in range(first, len(arcs)):
        y = arcs[x]
        if y >= end:
            break
        if hints[trow + y].edge:
            return y + 1
    return end


@final
class _Stretch:
    """A stretch ``s:b`` of a run being written: its arcs, the words added to each line
    (``add_col``), the written position wanted at each arc's line and at the last line
    before it that moves (``want``), and the controller's position before it (``qe0``)."""

    __slots__ = ("run", "em", "s", "b", "arc_rows", "qe0", "add_col", "want")

    def __init__(self, run: Run, em: Emission, s: int, b: int, arc_rows: list[int], qe0: list[float]) -> None:
        self.run, self.em, self.s, self.b, self.arc_rows, self.qe0 = run, em, s, b, arc_rows, qe0
        self.add_col = [""] * (b - s)
        moved = run.block.last_moving
        self.want: dict[int, list[float]] = {}
        for y in arc_rows:
            self.want[y] = [math.nan] * 3
            p = moved[y - 1] if y > s else -1
            if p >= s:
                self.want[p] = [math.nan] * 3


def _added_words(st: _Stretch, k: int, qk: float) -> float:
    """The words added on axis ``k`` to the stretch's lines that do not name it (where
    the corrected position differs from the written one by half a step or more), the
    written positions ``want`` asks for, and the position on ``k`` after the stretch
    (``qk``: before it); see :mod:`postproc.gcode.runwords`."""
    run, s, b = st.run, st.s, st.b
    unit, sk = run.unit, run.shift[k]
    unnamed = st.em.unnamed[k]
    qk = unnamed.add((s, b, k), (unit, sk), qk, st.add_col, st.want)
    e = run.block.last_moving[b - 1]  # the last line that moves
    if e >= s and unnamed.has[e]:
        qk = unnamed.written(e) * unit + sk
    return qk


def _arc_stop(corrector: Corrector, st: _Stretch, hints: Mapping[int, ArcHint]
              ) -> tuple[int, dict[int, tuple[str, str, int]]]:
    """The centre words of the stretch's arcs, up to the first whose hint does not hold
    for its end points as written: (that arc's line, or the stretch's end; the words of
    the arcs before it by line)."""
    s, moved = st.s, st.run.block.last_moving
    arc_edit: dict[int, tuple[str, str, int]] = {}  # row -> (I text, J text, edits)
    for y in st.arc_rows:
        p = moved[y - 1] if y > s else -1
        ok = _arc_words(corrector, st.run, hints, y, st.want[p] if p >= s else st.qe0, st.want[y],
                        st.em.named_edits[y])
        if ok is None:
            return y, arc_edit
        arc_edit[y] = ok
    return st.b, arc_edit


def _write_stretch(corrector: Corrector, st: _Stretch, stop: int, arc_edit: dict[int, tuple[str, str, int]],
                   write: Write) -> None:
    """Write lines ``s:stop`` of the stretch, its words as prepared, and count them."""
    run, em, s, add_col = st.run, st.em, st.s, st.add_col
    blk, a = run.block, run.a
    rep = corrector.report
    c = stop - s
    named = em.named_edits
    rows_added, newly_changed = runwords.added_counts(add_col, c, named, s)
    arc_words = 0
    centre_i = centre_j = [""] * c  # the new I and J number texts ("": the line's own stays)
    if arc_edit:
        centre_i, centre_j = [""] * c, [""] * c
        for y, (ti, tj, count) in arc_edit.items():
            centre_i[y - s], centre_j[y - s] = ti, tj
            arc_words += count
            newly_changed += count > 0 and named[y] == 0 and not add_col[y - s]
        rep.arcs_kept += len(arc_edit)
    rep.words_changed += em.edits_cum[stop] - em.edits_cum[s] + rows_added + arc_words
    rep.lines_changed += em.changed_cum[stop] - em.changed_cum[s] + newly_changed
    rep.lines_out += c
    rep.moves += c
    if run.inert:
        rep.moves -= bisect_left(run.inert, stop - a) - bisect_left(run.inert, s - a)
    i = blk.last_g[stop - 1]
    corrector.emitted_motion = blk.code(i) if i >= a else run.motion0
    write(runwords.join_rows(blk.lines, (s, stop), blk.at, em.nums, add_col, (centre_i, centre_j)))


def _arc_words(corrector: Corrector, run: Run, hints: Mapping[int, ArcHint], y: int, S: list[float],
               E: list[float], named_edits: int) -> tuple[str, str, int] | None:
    """The centre words of the run's arc on block line ``y`` from S to E (as written):
    ``(new I number, new J number, words changed)`` ("": the line's own stays), or None
    when its hint does not hold there."""
    blk = run.block
    j = y - run.a
    hint = hints[run.trow + j]
    centre, cw, _turn = run.arcs[j]
    budget = corrector.opt.tolerance_mm * FIT_BUDGET
    unit = run.unit
    base = (run.shift[0], run.shift[1]) if run.arc_absolute else (S[0], S[1])
    if not named_edits:  # unchanged end words: the input's own arc words stay if they still pass
        view = _ArcView(Arc(centre, 170, cw, 1, (-1, -1), -1), unit, run.arc_absolute, run.shift)
        c = (base[0] + blk.ov[3][y] * unit, base[1] + blk.ov[4][y] * unit)
        if hint.keep(view, S, E, c, budget) is None:
            return None
        return "", "", 0
    w = hint.words(S, E, _XY, cw, run.decimals, unit, base, budget)
    if w is None:
        return None
    w1, w2 = w[0], w[1]
    count = 0
    ti = tj = ""
    if blk.has_l[3][y]:
        if blk.ovl[3][y] != w1:
            ti, count = emit.fmt(w1, run.decimals), count + 1
    elif w1 != 0.0 or run.arc_absolute:
        return None  # a centre word to add: the general emitter places it
    if blk.has_l[4][y]:
        if blk.ovl[4][y] != w2:
            tj, count = emit.fmt(w2, run.decimals), count + 1
    elif w2 != 0.0 or run.arc_absolute:
        return None
    return ti, tj, count


class _ArcView:
    """What an :class:`postproc.gcode.vplan.ArcHint` reads of a move."""

    __slots__ = ("arc", "unit", "arc_absolute", "shift")

    def __init__(self, arc: Arc, unit: float, arc_absolute: bool, shift: Point) -> None:
        self.arc, self.unit, self.arc_absolute, self.shift = arc, unit, arc_absolute, shift


def _modal_at(run: Run, x: int) -> tuple[int | None, float]:
    """Modal motion and feed after block line ``x - 1`` of ``run`` (its start state for x == a)."""
    blk = run.block
    if x <= run.a:
        return run.motion0, run.feed0
    g, f = blk.last_g[x - 1], blk.last_f[x - 1]
    return (blk.code(g) if g >= run.a else run.motion0,
            blk.f_value[f] if f >= run.a else run.feed0)


def split_run(run: Run, rows: list[int]) -> Iterator[Run | tuple[int, RunMove]]:
    """The run cut at its lines ``rows`` (indices within the run, increasing): yields
    sub-runs (:class:`Run`) and, for each cut line, ``(index within the run, RunMove)``."""
    x = run.a
    arc_keys = sorted(run.arcs)  # the run's arcs and inert lines, by index: each sub-run takes a slice
    inert = run.inert
    for j in [*rows, len(run)]:
        y = run.a + j
        if y > x:
            sub = Run()
            sub.block, sub.a, sub.b = run.block, x, y
            sub.lineno = run.line(x - run.a)
            sub.unit, sub.shift, sub.r, sub.arc_absolute, sub.decimals = (run.unit, run.shift, run.r,
                                                                          run.arc_absolute, run.decimals)
            sub.q0 = run.q0 if x == run.a else tuple(run.q1[x - run.a - 1].tolist())
            sub.motion0, sub.feed0 = _modal_at(run, x)
            sub.q1 = run.q1[x - run.a:j]
            sub.trow = run.trow + (x - run.a)
            base = x - run.a
            sub.arcs = {jj - base: run.arcs[jj] for jj in arc_keys[bisect_left(arc_keys, base):bisect_left(arc_keys, j)]}
            sub.inert = [jj - base for jj in inert[bisect_left(inert, base):bisect_left(inert, j)]]
            sub.rot = None if run.rot is None else run.rot[base:j]
            yield sub
        if j == len(run):
            break
        yield j, _row_move(run, j)
        x = y + 1
