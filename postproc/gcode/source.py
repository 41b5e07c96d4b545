"""What a program is read with: its source's lines, and the setup the controller holds.

:class:`Setup` (work offsets, tool lengths, stored positions, start position and the
rest the program does not say), :class:`ProgramPath` (a program's sampled path),
:func:`iter_source_lines` (a program's lines, from a file or a text), and the filling of
axes not yet positioned (:func:`backfill_unknown`) and of approach directions
(:func:`motion_signs`). The readers (``correct``'s, ``diff``'s, the path sampler's) import
these from here; :mod:`postproc.gcode.path` gives them to the path API's users.
"""

from __future__ import annotations

import os
import re
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TextIO

import numpy as np

from postproc.errors import MissingSetupError, PostprocError
from postproc.fileio import Lines, read_blocks
from postproc.gcode.places import PathArray, file_of


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
    # the file of each sample's line where it is not the program's own (a subprogram's, the
    # program read expanded; None for its own lines), or None when all are its own
    # (:mod:`postproc.gcode.places`)
    files: PathArray | None = None

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


def iter_source_lines(source) -> tuple[str | None, Lines]:
    """``(path_or_None, its lines with endings)`` for a path or G-code text: an iterator
    of lines that also gives them a block at a time (:class:`postproc.fileio.Lines`); a
    file is opened when its first line is taken, read a block at a time, and closed at
    its end (or by ``close()``)."""
    if isinstance(source, os.PathLike) or (isinstance(source, str) and _looks_like_path(source)):
        path = str(source)

        def gen() -> Iterator[list[str]]:
            with open_source(path) as fh:
                yield from read_blocks(fh, path)  # a line without end is refused, not read whole

        return path, Lines(gen())
    return None, Lines([_LINE_RE.findall(str(source))])


def backfill_unknown(q: np.ndarray, lineno: np.ndarray, path: str | None,
                     files: PathArray | None = None) -> np.ndarray:
    """Replace NaN (not yet positioned) by the next known value of the same axis
    (``files``: the file of each row where not all are ``path``'s, for a refusal)."""
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
                path=file_of(files, 0, path),
                lineno=int(lineno[0]) if len(lineno) else None,
                hint=f"give the machine position of {'XYZ'[k]} at program start with --start {'XYZ'[k]}.. "
                     f"(mm, machine coordinates), or add an absolute move on {'XYZ'[k]} near the start")
        idx = np.searchsorted(good, np.flatnonzero(bad))
        if np.any(idx >= len(good)):
            last = int(np.flatnonzero(bad)[-1])
            raise MissingSetupError(f"axis {'XYZ'[k]} is not positioned before the end of the program",
                                    path=file_of(files, last, path), lineno=int(lineno[last]))
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
