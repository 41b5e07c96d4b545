"""The path sampler as it was written before it read through the lane's reader: every
line through the interpreter, one Move per line, sampled as it is visited.

The tests hold :func:`postproc.gcode.path.sample_program` bit-identical to this (the
same points, tool vectors, lines, rapid flags and context, the same errors at the same
places), so that reading runs of plain lines in bulk changes nothing of the path.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from postproc.gcode.geometry import arc_chord_steps, arc_length, arc_points
from postproc.gcode.interp import Interpreter, NeedsExpansion, plain_moves, start_position
from postproc.gcode.path import (
    MAX_SAMPLES,
    ProgramPath,
    Setup,
    backfill_unknown,
    iter_source_lines,
    motion_signs,
)
from postproc.gcode.state import RAPID
from postproc.limits import Limits, ResourceLimitError


def for_each_block(source, setup, visit, reset, *, dialect="generic", subroutine_path=(), limits=None):
    """Interpret a program line by line, calling ``visit(lineno, line, block, state)`` for
    each move a line makes; when it needs expanding, ``reset()`` and read it expanded."""
    from postproc.gcode.expand import expand

    limits = limits or Limits()
    path, lines = iter_source_lines(source)
    interp = Interpreter(setup, path, dialect=dialect)
    interp.max_arc_turns = limits.max_arc_turns
    interp.may_expand = True
    try:
        for lineno, line in enumerate(lines, start=1):
            _visit_line(interp, lineno, line, visit)
        return interp
    except NeedsExpansion:
        reset()
    _path, lines = iter_source_lines(source)
    interp = Interpreter(setup, path, dialect=dialect)
    interp.max_arc_turns = limits.max_arc_turns
    for sl in expand(list(lines), path=path, dialect=dialect, subroutine_path=[Path(p) for p in subroutine_path],
                     variables=getattr(setup, "variables", None), max_iterations=limits.max_iterations):
        interp.path = sl.path or path
        _visit_line(interp, sl.lineno, sl.text, visit)
    return interp


def _visit_line(interp, lineno, line, visit) -> None:
    block = interp.feed_line(lineno, line)
    if block is not None:
        visit(lineno, line, block, interp.state)
    if interp.cycle_move is not None:
        visit(lineno, line, interp.cycle_move, interp.state)


def _steps(length_mm: float, step_mm: float) -> int:
    pieces = length_mm / step_mm
    return math.ceil(pieces) if pieces < 1e18 else 10**18


class _Moves:
    def __init__(self, path, step_mm, chord_mm, max_samples) -> None:
        self.path, self.step_mm, self.chord_mm, self.max_samples = path, step_mm, chord_mm, max_samples
        self.reset()

    def visit(self, lineno, _line, block, _state) -> None:
        step_mm, chord_mm = self.step_mm, self.chord_mm
        for mv in plain_moves(block):
            q0, q1 = mv.q0, mv.q1
            if any(math.isnan(v) for v in q0) or mv.kind == RAPID:
                n = 1
                q0 = q1
            elif mv.arc is not None:
                n = max(1, _steps(arc_length(mv.arc, q0, q1), step_mm) if step_mm else 1,
                        arc_chord_steps(mv.arc, q0, q1, chord_mm) if chord_mm else 1)
                if self.total + n <= self.max_samples:
                    self.arcs[len(self.counts)] = arc_points(mv.arc, q0, q1, np.arange(1, n + 1) / n)
            else:
                n = max(1, _steps(math.dist(q0, q1), step_mm)) if step_mm else 1
            self.total += n
            if self.total > self.max_samples:
                every = f" every {step_mm:g} mm" if step_mm else ""
                raise ResourceLimitError(
                    f"sampling the program{every} makes more than {self.max_samples:,} points",
                    path=self.path, lineno=lineno, col=1, hint="give postproc verify a larger --max-step")
            self.q0s.append(q0)
            self.q1s.append(q1)
            self.counts.append(n)
            self.rs.append(mv.r)
            self.lns.append(lineno)
            self.rapid.append(mv.kind == RAPID)
            self.rot.append(mv.rotary)

    def reset(self) -> None:
        self.q1s, self.q0s, self.counts, self.rs, self.lns, self.rapid, self.rot = [], [], [], [], [], [], []
        self.arcs: dict = {}
        self.total = 0

    def path_of(self, setup, rotary) -> ProgramPath:
        if not self.counts:
            empty = np.zeros((0, 3))
            return ProgramPath(empty, empty.copy(), np.zeros(0, dtype=int), np.zeros(0, dtype=bool),
                               {"dirx": np.zeros(0), "diry": np.zeros(0), "dirz": np.zeros(0)})
        n = np.asarray(self.counts)
        move = np.repeat(np.arange(len(n)), n)
        k = np.arange(len(move)) - np.repeat(np.cumsum(n) - n, n) + 1
        a, b = np.asarray(self.q0s, dtype=float), np.asarray(self.q1s, dtype=float)
        q = a[move] + (b[move] - a[move]) * (k / n[move])[:, None]
        if self.arcs:
            first = np.cumsum(n) - n
            for j, pts in self.arcs.items():
                q[first[j]:first[j] + n[j]] = pts
        lineno_arr = np.asarray(self.lns)[move]
        q = backfill_unknown(q, lineno_arr, self.path)
        r = np.asarray(self.rs, dtype=float)[move]
        signs = motion_signs(q, start=np.array(start_position(setup.start), dtype=float))
        context: dict = {"dirx": signs[:, 0], "diry": signs[:, 1], "dirz": signs[:, 2]}
        for ax in sorted(rotary):
            context[ax] = np.asarray([d.get(ax, 0.0) for d in self.rot], dtype=float)[move]
        for key, v in (setup.context or {}).items():
            context[key] = np.full(len(q), float(v))
        return ProgramPath(q + r, r, lineno_arr, np.asarray(self.rapid)[move], context)


def reference_sample_program(source, setup=None, *, step_mm=None, chord_mm=None, dialect="generic",
                             subroutine_path=(), max_samples=MAX_SAMPLES, limits=None) -> ProgramPath:
    """:func:`postproc.gcode.path.sample_program`, every line through the interpreter."""
    setup = setup or Setup()
    path, _lines = iter_source_lines(source)
    moves = _Moves(path, step_mm, chord_mm, max_samples)
    interp = for_each_block(source, setup, moves.visit, moves.reset, dialect=dialect,
                            subroutine_path=subroutine_path, limits=limits)
    return moves.path_of(setup, interp.used_rotary)
