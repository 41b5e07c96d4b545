"""The move table: a chunk's moves, a row each in program order, as columns.

The reader (:mod:`postproc.gcode.reader`) reads a chunk; the corrector gathers its moves
into a :class:`Table` (runs of plain lines by slices, other moves row by row); the
planner (:mod:`postproc.gcode.planner`) fills the rest of its columns; the writer
(:mod:`postproc.gcode.writer`) writes from it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from postproc.gcode.moves import Kind
from postproc.gcode.places import PathArray
from postproc.gcode.vplan import ArcParams, FloatArray, IntArray, KindArray, PlanMove

if TYPE_CHECKING:
    from postproc.gcode import bulk

_NO_POINTS = np.zeros((0, 3))


@dataclass(eq=False)
class Table:
    """A chunk's moves, a row each in program order, as columns. The reader fills what it
    read (targets, lines and, in an expanded program, their files, tool vectors, rotary
    positions, the moves read line by line and the runs of plain lines); the planner the
    rest."""

    q1: FloatArray  # (M, 3) nominal targets (machine mm; unknown axes filled by the planner)
    lineno: IntArray  # (M,) source line of each row
    r: FloatArray  # (M, 3) tool vectors
    rot: list[dict[str, float]]  # rotary axis positions of each row ({} without rotary axes)
    moves: list[tuple[int, PlanMove]]  # (row, move) of the rows read line by line, and the runs' arcs
    kind: KindArray  # (M,) what each row is (Kind): the motion of a motion block, or its role
    runs: Sequence[bulk.Run] = ()  # runs of plain lines (each knows its first row, trow)
    # the file of each row's line, in an expanded program (None: all the program's own;
    # postproc.gcode.places)
    files: PathArray | None = None
    # -- filled by Planner.approach
    q0: FloatArray = field(default_factory=lambda: _NO_POINTS)  # nominal starts
    dirs: FloatArray = field(default_factory=lambda: _NO_POINTS)  # approach direction of each axis (-1, 0, 1)
    arc_prm: dict[int, ArcParams] = field(default_factory=dict)  # arc_params of the arcs, by row
    breaks: dict[int, FloatArray] = field(default_factory=dict)  # quadrant breaks of arcs, by row
    fixed_rows: list[int] = field(default_factory=list)  # rows that go to a stored position, uncorrected
    fixed_q: FloatArray | None = None  # their targets as given
    # -- filled by Planner.plan
    target: FloatArray = field(default_factory=lambda: _NO_POINTS)  # corrected targets (unrounded)
    start: FloatArray = field(default_factory=lambda: _NO_POINTS)  # corrected starts: the target before
    d_in: FloatArray = field(default_factory=lambda: _NO_POINTS)  # directions before each row

    def __len__(self) -> int:
        return len(self.q1)

    def run_rows(self, kind: Kind) -> tuple[IntArray, IntArray]:
        """The rows of ``kind`` in the runs of plain lines, in order, and the index in
        :attr:`runs` of the run of each."""
        rows = np.flatnonzero(self.kind == kind)
        if not self.runs:
            return rows[:0], rows[:0]
        first = np.array([r.trow for r in self.runs])
        owner = np.searchsorted(first, rows, side="right") - 1
        end = first + np.array([len(r) for r in self.runs])
        inside = (owner >= 0) & (rows < end[np.maximum(owner, 0)])
        return rows[inside], owner[inside]
