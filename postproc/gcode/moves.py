"""The records the interpreter makes of a program's motion: a :class:`Move` per motion
block, with its :class:`Arc` or canned :class:`Cycle`. They are read by the planner and
the writer, and by modules the interpreter itself calls (cutter compensation, arc
geometry), so they live apart from the interpreter."""

from __future__ import annotations

from dataclasses import dataclass, field

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
    stays: bool = False  # a tool-change or G53 line: must not be split
    motion_idx: int = -1  # word index of the block's G0/G1/G2/G3, or -1 (modal)
    aux_idx: tuple[int, ...] = ()  # word indices of I/J/K/R/P (removed if an arc is linearised)
    # a second move made by the same line (G28/G30: from the intermediate point to the
    # stored position), or None
    then: Move | None = None
    # the target is where the machine goes uncorrected (a stored position reached by
    # G28/G30): not corrected, no words written for it; NaN axes are unknown
    fixed: bool = False
    cycle: Cycle | None = None  # a canned-cycle block (kind is its code)
    # corrected but not written: 1 = the R point of the cycle block before it, 2 = a hole
    # of a cycle block kept as it is, whose correction must round to nothing
    probe: int = 0
    # a G5/G5.1 spline: its control points in the XY plane (machine mm), Z constant
    spline: list | None = None
    # already cut within tolerance (a spline's chords): not split again by the planner
    planned: bool = False
    # a move to a position the program stored (G28.1/G30.1): its name, and the axes it sets
    stored: tuple | None = None
    # word indices of the S, T and before-motion M words (with their parameters): written on
    # the first line of a split move (prefix_words) and removed from its own (its modal G
    # words are copied there: set again to the same value, they change nothing)
    event_idx: tuple[int, ...] = ()
    # the linear part of the programmable frame it was programmed in (Sinumerik ROT, SCALE,
    # MIRROR; postproc.gcode.frames), or None: its words are in that frame's coordinates
    frame: tuple | None = None
