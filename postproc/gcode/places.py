"""Where the rows of a chunk's table come from, for the errors about them.

A program read as written has one file: its rows' lines are its lines, and an error
names its path. An expanded program's rows come from several files (its subprograms'):
the table carries the file of each row (:attr:`postproc.gcode.table.Table.files`, None
for a program read as written), and an error names the file of the line it is about;
a list of lines (``at lines 2, 5``) names the file of each line that is not the error's
own (``at lines 2, main.ngc:5``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TypeAlias

import numpy as np
import numpy.typing as npt

# the file of each row (None: the program's own), or None for all rows of one file
PathArray: TypeAlias = npt.NDArray[np.object_]


def pick(files: PathArray | None, rows) -> PathArray | None:
    """The files of ``rows`` (an index, a mask or a slice), or None when all rows are the
    program's own."""
    return None if files is None else files[rows]


def repeated(path: str | None, n: int) -> PathArray | None:
    """The files of ``n`` rows of one line's, whose file is ``path`` (None: the program's
    own)."""
    return None if path is None else np.full(n, path, dtype=object)


def file_of(files: PathArray | Sequence[str | None] | None, i: int, default: str | None) -> str | None:
    """The file of row ``i`` (``default``, the program's path, where it is its own)."""
    if files is None:
        return default
    return files[i] or default


def line_place(lineno: int, path: str | None, own: str | None) -> str:
    """Line ``lineno`` of file ``path`` as an error or report names it where its own file
    is ``own``: the bare number in that file, else ``file:line``."""
    return str(lineno) if path == own else f"{path}:{lineno}"


def line_list(lineno, files: PathArray | None, rows, own: str | None, default: str | None,
              most: int = 8) -> str:
    """The lines of ``rows`` (each once, in order of line number), at most ``most`` of
    them (then `` ...``): a line of a file that is not ``own`` (the error's) as
    ``file:line``; ``default``: the program's path (the file of a row without one)."""
    lines = lineno[rows].tolist()
    if files is None:
        items = [str(n) for n in sorted(set(lines))]
    else:
        pairs = sorted({(n, f or default) for n, f in zip(lines, files[rows].tolist(), strict=True)},
                       key=lambda p: (p[0], p[1] or ""))
        items = [line_place(n, f, own) for n, f in pairs]
    return ", ".join(items[:most]) + (" ..." if len(items) > most else "")
