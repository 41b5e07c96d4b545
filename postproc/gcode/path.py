"""The nominal path of a program: points along every move, in the machine frame.

``program_path(source, setup)`` runs the modal interpreter and samples every move
(lines and arcs) at most ``max_step_mm`` apart. Points are *functional-point*
positions ``p = q + r`` (after units, work offsets, G92 and tool length); ``tool_mm``
is the tool vector ``r``, so ``q = points_mm - tool_mm`` is what the controller
commands and ``machine.forward(q, tool_mm, context)`` is where the tool really goes.

Axes not yet positioned when a program starts are where the machine is, when
``Setup.start`` gives that position; otherwise they take the value of their next known
position (the first move of most programs is a retract on one axis).
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TextIO

import numpy as np

from postproc.errors import MissingSetupError, PostprocError
from postproc.gcode.geometry import arc_chord_steps, arc_length, arc_points
from postproc.gcode.interp import Interpreter, plain_moves, start_position
from postproc.gcode.state import RAPID
from postproc.limits import Limits, ResourceLimitError

DEFAULT_MAX_STEP_MM = 0.5
# Points one program may be sampled into (verify, the path API): verify peaks near 7.5 KB
# for each (270,000 points: 2 GB), so this keeps it under 2 GB, and a step of 1e-9 mm
# (93.6 GiB asked for) is refused at its line. At verify's 0.5 mm: 125 m of path.
MAX_SAMPLES = 250_000


@dataclass
class Setup:
    """What the controller knows that the program does not say.

    ``offsets``: work offsets by name (``"G54"``, ``"G59.1"``, ``"G54.1P3"``) as
    (x, y, z) mm in the machine frame (or a dict ``{"X":.., "Y":.., "Z":..}``);
    ``tool_lengths``: tool number -> length (mm) for G43; ``tool_vector``: the tool
    vector r (mm) overriding ``(0, 0, -length)``; ``context``: constant context
    values passed to the engine (e.g. ``{"temp": 21.5}``); ``start``: machine axis
    positions (mm, the gauge point as in G53, like ``offsets``) at program start, by
    axis letter (``{"Z": 150.0}``, any subset), used for the axes the program has not
    positioned yet; the functional point there is ``start + r``; ``home``: the stored
    positions G28 and G30 go to (``{"G28": {"X":.., "Y":.., "Z":..}}``, machine mm as
    ``offsets``, any subset of axes; an axis not given is unknown after the move);
    ``variables``: values of machine-state variables the program reads (number -> value).
    """

    offsets: dict = field(default_factory=dict)
    tool_lengths: dict = field(default_factory=dict)
    tool_vector: tuple | None = None
    context: dict = field(default_factory=dict)
    start: dict = field(default_factory=dict)
    home: dict = field(default_factory=dict)
    variables: dict = field(default_factory=dict)  # machine-state variables by number (--var, --vars)
    tool_radii: dict = field(default_factory=dict)  # cutter radius (mm) by tool or D register (None: any)


@dataclass
class ProgramPath:
    points_mm: np.ndarray  # (N, 3) nominal functional-point positions
    tool_mm: np.ndarray  # (N, 3) tool vector r at each sample
    lineno: np.ndarray  # (N,) source line of each sample
    rapid: np.ndarray  # (N,) bool, True on G0 moves
    context: dict = field(default_factory=dict)  # dirx, diry, dirz, A/B/C when used

    def __len__(self) -> int:
        return len(self.points_mm)


_LINE_RE = re.compile(r"[^\r\n]*(?:\r\n|\n|\r)|[^\r\n]+$")


PROGRAM_SUFFIXES = {".nc", ".ngc", ".tap", ".gcode", ".cnc", ".iso", ".mpf", ".txt", ".out"}


def _looks_like_path(text: str) -> bool:
    if any(c in text for c in "\r\n \t"):
        return False
    return os.sep in text or Path(text).suffix.lower() in PROGRAM_SUFFIXES or Path(text).is_file()


def open_source(path: str) -> TextIO:
    """A program file opened for reading its lines as they are (line endings kept, bytes
    that are not UTF-8 carried through); PostprocError when it cannot be read."""
    try:
        return open(path, encoding="utf-8", errors="surrogateescape", newline="")
    except OSError as exc:
        raise PostprocError(f"cannot read program: {exc.strerror}", path=path) from None


def iter_source_lines(source) -> tuple[str | None, Iterator[str]]:
    """``(path_or_None, iterator of lines with endings)`` for a path or G-code text."""
    if isinstance(source, os.PathLike) or (isinstance(source, str) and _looks_like_path(source)):
        path = str(source)

        def gen():
            from postproc.fileio import read_lines

            with open_source(path) as fh:
                yield from read_lines(fh, path)  # a line without end is refused, not read whole

        return path, gen()
    return None, iter(_LINE_RE.findall(str(source)))


def for_each_block(source, setup, visit, reset, *, dialect: str = "generic", subroutine_path=(),
                   lenient_setup: bool = False, limits: Limits | None = None) -> Interpreter:
    """Interpret a program (path or text) line by line, calling ``visit(lineno, line,
    block, state)`` for each move a line makes (``state``: the modal state after it): its
    own block, then the Sinumerik drilling cycle it runs (the interpreter's
    ``cycle_move``, whose steps :func:`postproc.gcode.interp.plain_moves` gives as the
    correction writes them); the same reading as ``correct``: when the
    program needs expanding (parameters, O-words, subprograms, macros), ``reset()`` is
    called and the expanded program is read instead. Returns the interpreter. ``limits``:
    the bounds on loops and helix turns (:class:`postproc.limits.Limits`, default its own)."""
    from postproc.gcode.interp import NeedsExpansion

    limits = limits or Limits()

    path, lines = iter_source_lines(source)
    interp = Interpreter(setup, path, dialect=dialect, lenient_setup=lenient_setup)
    interp.max_arc_turns = limits.max_arc_turns
    interp.may_expand = True
    try:
        for lineno, line in enumerate(lines, start=1):
            _visit_line(interp, lineno, line, visit)
        return interp
    except NeedsExpansion:
        reset()
    from postproc.gcode.expand import expand

    _path, lines = iter_source_lines(source)
    interp = Interpreter(setup, path, dialect=dialect, lenient_setup=lenient_setup)
    interp.max_arc_turns = limits.max_arc_turns
    for sl in expand(list(lines), path=path, dialect=dialect, subroutine_path=[Path(p) for p in subroutine_path],
                     variables=getattr(setup, "variables", None), max_iterations=limits.max_iterations):
        interp.path = sl.path or path
        _visit_line(interp, sl.lineno, sl.text, visit)
    return interp


def _visit_line(interp: Interpreter, lineno: int, line: str, visit) -> None:
    """Feed one line and visit the moves it makes: its block, then the drilling cycle it
    runs (a cycle call alone makes no block; a position block under ``MCALL`` makes both)."""
    block = interp.feed_line(lineno, line)
    if block is not None:
        visit(lineno, line, block, interp.state)
    if interp.cycle_move is not None:
        visit(lineno, line, interp.cycle_move, interp.state)


def backfill_unknown(q: np.ndarray, lineno: np.ndarray, path: str | None) -> np.ndarray:
    """Replace NaN (not yet positioned) by the next known value of the same axis."""
    q = q.copy()
    for k in range(3):
        col = q[:, k]
        bad = np.isnan(col)
        if not bad.any():
            continue
        good = np.flatnonzero(~bad)
        if len(good) == 0:
            raise MissingSetupError(
                f"axis {'XYZ'[k]} is never positioned by the program, so the correction cannot be evaluated",
                path=path, lineno=int(lineno[0]) if len(lineno) else None,
                hint=f"give the machine position of {'XYZ'[k]} at program start with --start {'XYZ'[k]}.. "
                     f"(mm, machine coordinates), or add an absolute move on {'XYZ'[k]} near the start")
        idx = np.searchsorted(good, np.flatnonzero(bad))
        if np.any(idx >= len(good)):
            raise MissingSetupError(f"axis {'XYZ'[k]} is not positioned before the end of the program",
                                    path=path, lineno=int(lineno[np.flatnonzero(bad)[-1]]))
        col[bad] = col[good[idx]]
    return q


def motion_signs(q: np.ndarray, initial=(0.0, 0.0, 0.0), start=None) -> np.ndarray:
    """Sign of each axis's motion into each point; the previous sign where it does not move.

    ``start``: the position before the first point (NaN or None: no motion into it)."""
    first = q[:1] if start is None else np.where(np.isnan(start), q[:1], np.asarray(start, dtype=float))
    d = np.diff(np.vstack([first, q]), axis=0)
    sign = np.sign(np.where(np.abs(d) > MOTION_EPS_MM, d, 0.0))
    out = np.empty_like(sign)
    for k in range(3):
        col = sign[:, k]
        nz = col != 0
        idx = np.where(nz, np.arange(len(col)), -1)
        np.maximum.accumulate(idx, out=idx)
        out[:, k] = np.where(idx >= 0, col[np.maximum(idx, 0)], initial[k])
    return out


# Motions smaller than this do not change an axis's approach direction (float noise).
MOTION_EPS_MM = 1e-9


def program_path(source, setup: Setup | None = None, *, max_step_mm: float = DEFAULT_MAX_STEP_MM,
                 dialect: str = "generic", subroutine_path=(), limits: Limits | None = None) -> ProgramPath:
    """Sample the nominal path of a program (path or text); see the module docstring."""
    return sample_program(source, setup, step_mm=max_step_mm, dialect=dialect, subroutine_path=subroutine_path,
                          limits=limits)


def _steps(length_mm: float, step_mm: float) -> int:
    """Pieces of ``step_mm`` in ``length_mm`` (rounded up; huge for a step of 1e-320 mm,
    never an overflow)."""
    pieces = length_mm / step_mm
    return math.ceil(pieces) if pieces < 1e18 else 10**18


class _Moves:
    """The moves :func:`sample_program` reads: per move its end, start, number of
    samples, tool vector, line, whether it is rapid and its rotary positions; an arc's
    samples are made as it is read, straight moves' all at once at the end."""

    def __init__(self, path: str | None, step_mm: float | None, chord_mm: float | None, max_samples: int) -> None:
        self.path, self.step_mm, self.chord_mm, self.max_samples = path, step_mm, chord_mm, max_samples
        self.q1s: list = []
        self.q0s: list = []
        self.counts: list[int] = []
        self.rs: list = []
        self.lns: list[int] = []
        self.rapid: list[bool] = []
        self.rot: list[dict] = []
        self.arcs: dict[int, np.ndarray] = {}
        self.total = 0  # samples so far

    def visit(self, lineno: int, _line: str, block, _state) -> None:
        step_mm, chord_mm = self.step_mm, self.chord_mm
        for mv in plain_moves(block):
            q0, q1 = mv.q0, mv.q1
            if any(math.isnan(v) for v in q0) or mv.kind == RAPID:
                n = 1
                q0 = q1
            elif mv.arc is not None:
                n = max(1, _steps(arc_length(mv.arc, q0, q1), step_mm) if step_mm else 1,
                        arc_chord_steps(mv.arc, q0, q1, chord_mm) if chord_mm else 1)
                if self.total + n <= self.max_samples:  # (else refused below, before the points are made)
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
        for acc in (self.q1s, self.q0s, self.counts, self.rs, self.lns, self.rapid, self.rot):
            acc.clear()
        self.arcs.clear()
        self.total = 0

    def path_of(self, setup: Setup, rotary: set[str]) -> ProgramPath:
        """The samples of the moves read, with their context."""
        if not self.counts:
            empty = np.zeros((0, 3))
            return ProgramPath(empty, empty.copy(), np.zeros(0, dtype=int), np.zeros(0, dtype=bool),
                               {"dirx": np.zeros(0), "diry": np.zeros(0), "dirz": np.zeros(0)})
        n = np.asarray(self.counts)
        move = np.repeat(np.arange(len(n)), n)
        k = np.arange(len(move)) - np.repeat(np.cumsum(n) - n, n) + 1  # 1..n within each move
        a, b = np.asarray(self.q0s, dtype=float), np.asarray(self.q1s, dtype=float)
        q = a[move] + (b[move] - a[move]) * (k / n[move])[:, None]  # as line_points does
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


def sample_program(source, setup: Setup | None = None, *, step_mm: float | None = None,
                   chord_mm: float | None = None, dialect: str = "generic", subroutine_path=(),
                   max_samples: int = MAX_SAMPLES, limits: Limits | None = None) -> ProgramPath:
    """The program's moves as points: the one sampler of correct's checks, verify and the
    path API (the program is read by :func:`for_each_block`).

    Each move gives its end point, and before it, on feed moves from a known position:
    straight moves a point every ``step_mm`` (None: their end alone); arcs a point
    every ``step_mm`` of their length and, with ``chord_mm``, every chord whose
    sagitta stays below it (the finer of the two). Rapid moves give their end point
    only. The context holds each sample's approach directions (from the start position
    when ``setup.start`` gives it), the rotary axes' positions and ``setup.context``.
    More than ``max_samples`` points in all are refused
    (:class:`~postproc.limits.ResourceLimitError`, at the line that passes the bound)."""
    setup = setup or Setup()
    path, _lines = iter_source_lines(source)
    moves = _Moves(path, step_mm, chord_mm, max_samples)
    interp = for_each_block(source, setup, moves.visit, moves.reset, dialect=dialect,
                            subroutine_path=subroutine_path, limits=limits)
    return moves.path_of(setup, interp.used_rotary)
