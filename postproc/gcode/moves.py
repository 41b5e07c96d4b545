"""The records the interpreter makes of a program's motion: a :class:`Move` per motion
block, with its :class:`Arc` or canned :class:`Cycle`, and its :class:`Role`: what the
row is (a motion block, one never split, a cycle, a spline, a chord, a position reached
uncorrected, a point corrected but not written). They are read by the planner and
the writer, and by modules the interpreter itself calls (cutter compensation, arc
geometry), so they live apart from the interpreter."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum

from postproc.gcode import lexer


@dataclass(slots=True)
class Arc:
    """An arc in machine gauge coordinates: centre (3,), plane triple, direction, turns."""

    center: tuple[float, float, float]
    plane: int
    clockwise: bool
    turns: int
    offset_idx: tuple[int, int]  # word indices of the two centre offsets, or -1
    r_idx: int  # word index of R, or -1


@dataclass(slots=True)
class Cycle:
    """A canned-cycle block: its holes and the controller's moves (machine mm)."""

    code: int  # 730, 810, ..., 890
    holes: list  # [((x, y, z_bottom), (x, y, z_r)), ...] one per repeat
    clear_z: float  # level after the block (R for G99, max(start, R) for G98)
    steps: list  # [(RAPID | LINE | DWELL, (x, y, z) or (seconds, 0, 0)), ...]
    r_idx: int  # word index of R on the line, or -1
    r_mm: float  # machine Z of the R plane
    z_mm: float  # machine Z of the hole bottom
    repeats: int
    retract_r: bool  # G99
    dwell: float | None


class Role(IntEnum):
    """What a row of a chunk's moves is, and so how it is planned and written."""

    MOVE = 0  # a motion block, written from its words and split as its plan needs
    WHOLE = 1  # a motion block never split: a tool change or G53 on its line, the entry or exit
    # move of cutter radius compensation, the intermediate point of G28/G30
    CYCLE = 2  # a canned-cycle block (its holes and steps: Move.cycle)
    SPLINE = 3  # a G5/G5.1 spline (its control points: Move.spline)
    CHORD = 4  # a chord a spline is written as, already cut within tolerance: not split again
    AT = 5  # the machine goes there uncorrected and no words are written for it: a stored
    # position reached by G28/G30 (NaN axes unknown), the end of a block kept as it is
    R_POINT = 6  # corrected, not written: the R point of the cycle block before it
    HOLE = 7  # corrected, not written: a hole of a cycle block kept as it is, whose correction
    # must round to nothing


class Kind(IntEnum):
    """What a row of a chunk's table is (:attr:`postproc.gcode.table.Table.kind`): the
    motion of a motion block (:attr:`Role.MOVE` or :attr:`Role.WHOLE`), or its role."""

    STILL = 0  # a line of a run of plain lines that moves nothing (blank, comment, S, M, T words)
    RAPID = 1  # G0
    FEED = 2  # G1
    ARC_CW = 3  # G2
    ARC_CCW = 4  # G3
    CYCLE = 5  # the roles that are not a motion block: see Role
    SPLINE = 6
    CHORD = 7
    AT = 8
    R_POINT = 9
    HOLE = 10


# the kind of a motion block, by its motion code (postproc.gcode.state: G0 -> 0, G1 -> 10, ...)
MOTION_KIND = {0: Kind.RAPID, 10: Kind.FEED, 20: Kind.ARC_CW, 30: Kind.ARC_CCW}
_ROLE_KIND = {Role.CYCLE: Kind.CYCLE, Role.SPLINE: Kind.SPLINE, Role.CHORD: Kind.CHORD, Role.AT: Kind.AT,
              Role.R_POINT: Kind.R_POINT, Role.HOLE: Kind.HOLE}


def kind_of(role: Role, motion: int) -> Kind:
    """The table kind of a move of ``role`` whose motion code is ``motion``."""
    kind = _ROLE_KIND.get(role)
    return MOTION_KIND[motion] if kind is None else kind


@dataclass(slots=True)
class Move:
    """A motion block: where the gauge point goes and how to rewrite the line.

    ``q0``/``q1``: nominal gauge positions (mm, machine frame; NaN = unknown);
    ``r``: tool vector; ``shift``: machine = program x ``unit`` + ``shift`` for absolute
    words (work + G92 + tool length offsets, or 0 under G53).
    """

    lineno: int
    kind: int
    q0: tuple[float, float, float]
    q1: tuple[float, float, float]
    r: tuple[float, float, float]
    shift: tuple[float, float, float]
    unit: float
    incremental: bool
    arc_absolute: bool
    words: list[lexer.Word]
    axis_idx: tuple[int, int, int]
    feed_idx: int
    inverse_time: bool
    feed: float
    rotary: dict[str, float]
    arc: Arc | None = None
    prefix_words: list[str] = field(default_factory=list)
    role: Role = Role.MOVE
    motion_idx: int = -1  # word index of the block's G0/G1/G2/G3, or -1 (modal)
    aux_idx: tuple[int, ...] = ()  # word indices of I/J/K/R/P (removed if an arc is linearised)
    # a second move made by the same line (G28/G30: from the intermediate point to the
    # stored position), or None
    then: Move | None = None
    cycle: Cycle | None = None  # Role.CYCLE: the canned cycle (kind is its code)
    # Role.SPLINE: the control points in the XY plane (machine mm), Z constant
    spline: list | None = None
    # Role.AT, a move to a position the program stored (G28.1/G30.1): its name, and the
    # axes it sets
    stored: tuple | None = None
    # word indices of the S, T and before-motion M words (with their parameters): written on
    # the first line of a split move (prefix_words) and removed from its own (its modal G
    # words are copied there: set again to the same value, they change nothing)
    event_idx: tuple[int, ...] = ()
    # the linear part of the programmable frame it was programmed in (Sinumerik ROT, SCALE,
    # MIRROR; postproc.gcode.frames), or None: its words are in that frame's coordinates
    frame: tuple | None = None
    # the file its line comes from, in an expanded program (a subprogram's file, or the
    # program's own); None: the program's own (a program read as written)
    path: str | None = None
