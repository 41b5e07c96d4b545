"""Reading program files with bounded lines; writing output files safely (a temporary
file beside the target, renamed at the end).

Input: :func:`read_lines` yields a file's lines with their endings and refuses a line
longer than :data:`MAX_INPUT_LINE_CHARS` after reading at most that many characters of it,
so a file without line ends (``/dev/zero``, a binary) is refused at once instead of
being read whole into memory; :func:`read_blocks` gives the same lines a read at a time,
with the same refusal, for the readers that take a program's lines in blocks
(:class:`Lines`); :func:`copy_lines` copies a stream (stdin) with the same bound.

Output:

Nothing half-written is ever left under the target's name: on any error the temporary
file is removed and an existing file of that name stays as it was. Every writer of
postproc goes through :func:`output_path`:

- a symbolic link is written through: the file it points to is replaced, the link stays;
- a device, pipe or socket (``/dev/null``, ``/dev/stdout``, a FIFO) is written directly,
  never replaced by a regular file;
- only a regular file (or a new name) is written by rename.
"""

from __future__ import annotations

import errno
import io
import os
import shutil
import stat
import sys
import tempfile
from collections.abc import Iterable, Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import BinaryIO, TextIO

from postproc.errors import EXIT_USAGE, DiskFullError, OutputError, PostprocError

#: Longest input line read (characters, line ending included). No controller reads a line
#: of more than 512 characters (Sinumerik; LinuxCNC 255, Fanuc 128), and a corrected line
#: that long is refused at writing anyway; this bound only keeps a file without line ends
#: (``/dev/zero``, a binary file, a program whose line ends were lost) from being read whole
#: into memory, with room to spare for any program a controller runs.
MAX_INPUT_LINE_CHARS = 65_536
# Bytes read at a time when copying a stream (stdin) to a file.
_COPY_BLOCK = 1 << 16
# Characters read at a time by read_blocks: some 2,500 lines of a CAM program, a
# block's worth (larger reads gain nothing measurable).
_READ_CHARS = 1 << 16


def _line_too_long(path: str | None, lineno: int, limit: int) -> PostprocError:
    return PostprocError(
        f"line longer than {limit:,} characters (no line end within them): not a G-code "
        "program (no controller reads a line of more than 512)", path=path, lineno=lineno, col=1,
        hint="check that this is the program you meant: a binary file, a device such as /dev/zero, or "
             "a program whose line ends were lost")


def read_lines(fh: TextIO, path: str | None = None, limit: int = MAX_INPUT_LINE_CHARS) -> Iterator[str]:
    """The lines of the text stream ``fh`` (opened with ``newline=''``), each with its
    ending; a line of more than ``limit`` characters is refused (PostprocError naming
    ``path`` and the line) after at most ``limit + 1`` characters of it are read."""
    lineno = 0
    while True:
        line = fh.readline(limit + 1)
        if not line:
            return
        lineno += 1
        if len(line) > limit:
            raise _line_too_long(path, lineno, limit)
        yield line


def read_blocks(fh: TextIO, path: str | None = None, limit: int = MAX_INPUT_LINE_CHARS,
                size: int = _READ_CHARS) -> Iterator[list[str]]:
    """The lines :func:`read_lines` gives of ``fh`` (opened with ``newline=''``), in
    lists: each read of ``size`` characters gives the lines it completes. The lines end
    where ``readline`` ends them ("\\n", "\\r\\n", a lone "\\r", a "\\r\\n" cut between two
    reads included), each keeps its ending, and a last line without one is given as it
    is. A line of more than ``limit`` characters is refused with the same PostprocError,
    after the lines before it are given and at most ``limit + size`` characters of it
    are read."""
    lineno = 0  # lines given
    rest = ""  # the start of a line not ended yet (or ended by a "\r" the next read may follow with "\n")
    while text := fh.read(size):
        # the universal line ends of readline with newline='' (the same C routine)
        lines = io.StringIO(rest + text, newline="").readlines()
        rest = "" if lines[-1][-1] == "\n" else lines.pop()
        # only the first line holds more than one read: the others are checked where a read is longer than a line may be
        if lines and (len(lines[0]) > limit or (size > limit and max(map(len, lines)) > limit)):
            k = next(k for k, line in enumerate(lines) if len(line) > limit)
            if k:
                yield lines[:k]
            raise _line_too_long(path, lineno + k + 1, limit)
        if lines:
            lineno += len(lines)
            yield lines
        if len(rest) > limit:
            raise _line_too_long(path, lineno + 1, limit)
    if rest:
        yield [rest]


class Lines:
    """A program's lines from the lists ``blocks`` gives (:func:`read_blocks`), taken one
    at a time (it is an iterator of lines) or ``n`` at a time (:meth:`take`), the same
    lines either way; ``taken``: the lines taken so far. An error of ``blocks`` is raised
    where the line after the last it gave is taken, as by an iterator of the lines."""

    __slots__ = ("_blocks", "_buf", "_at", "taken")

    def __init__(self, blocks: Iterable[list[str]]) -> None:
        self._blocks = iter(blocks)
        self._buf: list[str] = []  # the block taken from
        self._at = 0  # where its next line is
        self.taken = 0

    def __iter__(self) -> Lines:
        return self

    def __next__(self) -> str:
        while self._at >= len(self._buf):
            self._buf = next(self._blocks)
            self._at = 0
        line = self._buf[self._at]
        self._at += 1
        self.taken += 1
        return line

    def take(self, n: int) -> list[str]:
        """The next ``n`` lines (fewer at the end, none after it), as ``list(islice(self, n))``."""
        out: list[str] = []
        self._fill(out, n)
        return out

    def lists(self, n: int) -> Iterator[list[str]]:
        """The lines not taken yet, in lists of ``n`` (the last shorter); where
        :meth:`take` raises an error of ``blocks`` at once, this gives the list of the
        lines before it first."""
        while True:
            out: list[str] = []
            try:
                self._fill(out, n)
            except Exception:
                if out:
                    yield out
                raise
            if not out:
                return
            yield out

    def _fill(self, out: list[str], n: int) -> None:
        """Take lines into ``out`` until it holds ``n`` or the lines end (those taken
        before an error of ``blocks`` stay in ``out``)."""
        while len(out) < n and (piece := self._piece(n - len(out))):
            out += piece

    def _piece(self, n: int) -> list[str]:
        """Up to ``n`` lines of the block taken from, else of the next (none at the end)."""
        while self._at >= len(self._buf):
            block = next(self._blocks, None)
            if block is None:
                return []
            self._buf, self._at = block, 0
        at = self._at
        piece = self._buf[at:at + n]
        self._at = at + len(piece)
        self.taken += len(piece)
        return piece

    def close(self) -> None:
        """Let go of the lines not taken (a file read by a generator is closed)."""
        close = getattr(self._blocks, "close", None)
        if close is not None:
            close()
        self._buf, self._at = [], 0


def bounded_blocks(src: BinaryIO, path: str | None = None, limit: int = MAX_INPUT_LINE_CHARS) -> Iterator[bytes]:
    """The bytes of the stream ``src``, a block at a time, refusing (as :func:`read_lines`)
    a line longer than ``limit`` bytes as soon as it is seen: a stream without line ends
    is not read without end."""
    lineno = 1  # of the line the reading is in (counted by line feeds)
    run = 0  # bytes of that line so far
    size = min(_COPY_BLOCK, limit)  # a line inside one block is never longer than the limit
    while block := src.read(size):
        # the length of the block's first line (up to its first \r or \n), and where its last ends
        ends = [k for k in (block.find(b"\r"), block.find(b"\n")) if k >= 0]
        first = min(ends) if ends else len(block)
        if run + first > limit:
            raise _line_too_long(path, lineno, limit)
        last = max(block.rfind(b"\r"), block.rfind(b"\n"))
        run = len(block) - last - 1 if last >= 0 else run + len(block)
        lineno += block.count(b"\n")
        yield block


def copy_lines(src: BinaryIO, dst: BinaryIO, path: str | None = None, limit: int = MAX_INPUT_LINE_CHARS) -> None:
    """Copy the byte stream ``src`` (stdin) to ``dst`` through :func:`bounded_blocks`."""
    for block in bounded_blocks(src, path, limit):
        dst.write(block)


@contextmanager
def as_regular_file(path: str) -> Iterator[str]:
    """The path of a regular file holding ``path``'s content, which can be read more than
    once (a program is: its header, its lines, again for a second pass): ``path`` itself
    when it is one; a pipe, FIFO, device or socket (``-``: standard input), such as a shell's
    ``<(...)``, is read once, each line bounded, into a temporary file removed at the end.
    An error that names the copy names ``path`` instead (``<stdin>`` for ``-``), with its
    column read while the copy is there."""
    if path != "-":
        try:
            regular = stat.S_ISREG(os.stat(path).st_mode)
        except OSError:
            regular = True  # the reader names the problem
        if regular:
            yield path
            return
    shown = "<stdin>" if path == "-" else path
    with tempfile.TemporaryDirectory(prefix="postproc-") as tmp:
        copy = os.path.join(tmp, "stdin.nc" if path == "-" else os.path.basename(path) or "program.nc")
        with open(copy, "wb") as out:
            if path == "-":
                copy_lines(sys.stdin.buffer, out, shown)
            else:
                with open(path, "rb") as src:
                    copy_lines(src, out, shown)
        try:
            yield copy
        except PostprocError as exc:
            if exc.path and os.path.realpath(exc.path) == os.path.realpath(copy):
                exc.with_column()
                exc.path = shown
            raise


def count_lines(path: str, limit: int = MAX_INPUT_LINE_CHARS) -> int:
    """The number of lines of the file at ``path`` (a last line without an ending counts),
    read through :func:`bounded_blocks`."""
    n = 0
    last = b"\n"
    with open(path, "rb") as fh:
        for block in bounded_blocks(fh, path, limit):
            n += block.count(b"\n")
            last = block[-1:]
    return n + (last != b"\n")


def output_mode(path: Path) -> int:
    """Permissions for a new output file: those of the file it replaces, else 0666 less umask.

    ``mkstemp`` creates files readable by their owner only; a corrected program or a
    calibration must be readable as any ordinary file the user writes would be.
    """
    try:
        return path.stat().st_mode & 0o777
    except OSError:
        umask = os.umask(0)
        os.umask(umask)
        return 0o666 & ~umask


@contextmanager
def output_path(path: str | os.PathLike, suffix: str = ".tmp", stage_special: bool = False) -> Iterator[str]:
    """Yield the path to write ``path``'s new content to; it becomes ``path``'s content if the block succeeds.

    A regular file (or a new name): a temporary file beside it, renamed over it at the end
    (removed on error). Through a symbolic link: the same, beside the file it points to,
    so the link stays a link. A device, pipe or socket: ``path`` itself, written directly;
    with ``stage_special``, a temporary file whose content is copied into it at the end
    (for writers that may start over: nothing reaches the device before the block ends).
    """
    target = Path(path)
    real = Path(os.path.realpath(target))
    try:
        st = os.stat(real)
    except FileNotFoundError:
        st = None
    except OSError as exc:
        raise _cannot_write(target, exc) from None
    if st is not None and stat.S_ISDIR(st.st_mode):
        raise OutputError("cannot write the output: it is a directory", path=str(target),
                          hint="give a file name")
    if st is not None and not stat.S_ISREG(st.st_mode):
        if not stage_special:
            with _disk_full_as_such(target):
                yield str(target)  # a device, pipe or socket: never replaced by a file
            return
        fd, tmp = tempfile.mkstemp(prefix="postproc-", suffix=suffix)
        os.close(fd)
        try:
            with _disk_full_as_such(target):
                yield tmp
            try:
                with open(tmp, "rb") as src, open(target, "wb") as dst:
                    shutil.copyfileobj(src, dst)
            except OSError as exc:
                raise _cannot_write(target, exc) from None
        finally:
            Path(tmp).unlink(missing_ok=True)
        return
    try:
        fd, tmp = tempfile.mkstemp(dir=real.parent, prefix=f".{real.name}.", suffix=suffix)
    except OSError as exc:
        raise _cannot_write(real, exc) from None
    os.close(fd)
    try:
        with _disk_full_as_such(target):
            yield tmp
        os.chmod(tmp, output_mode(real))
        try:
            os.replace(tmp, real)
        except OSError as exc:
            raise _cannot_write(real, exc) from None
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


#: the earlier name of :func:`output_path`
atomic_path = output_path


@contextmanager
def _disk_full_as_such(target) -> Iterator[None]:
    """Raise an ENOSPC met inside the block as the :func:`disk_full` error of ``target``."""
    try:
        yield
    except OSError as exc:
        full = disk_full(exc, target)
        if full is None:
            raise
        raise full from None


def disk_full(exc: OSError, target) -> DiskFullError | None:
    """The error to raise for ``exc`` met while writing ``target``, when it is ENOSPC
    (disk full, exit :data:`postproc.errors.EXIT_DISK_FULL`); None for any other error."""
    if exc.errno not in (errno.ENOSPC, errno.EDQUOT):
        return None
    return DiskFullError("disk full (no space left on the device): nothing was written",
                         path=str(target) if target is not None else None,
                         hint="free some space, or write the output (-o) and temporary files (TMPDIR) elsewhere")


def _cannot_write(target: Path, exc: OSError) -> OutputError:
    """The error for an output that cannot be created where it was asked for."""
    full = disk_full(exc, target)
    if full is not None:
        return full
    if not target.parent.is_dir():
        return OutputError(f"cannot write the output: directory {str(target.parent)!r} does not exist",
                           path=str(target), hint="create the directory first, or give another output path")
    return OutputError(f"cannot write the output: {exc.strerror}", path=str(target),
                       hint="check the output path and its permissions")


def atomic_write_text(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` (UTF-8, line endings as given) atomically to ``path``."""
    with atomic_path(path) as tmp, open(tmp, "w", encoding="utf-8", newline="") as fh:
        fh.write(text)


def atomic_write_texts(files: dict) -> None:
    """Write several files together: every temporary file is written first, then all are
    renamed, so a failure while writing leaves none of them (a set such as axis tables
    and their squareness file is never half new, half old)."""
    with ExitStack() as stack:
        for path, text in files.items():
            tmp = stack.enter_context(atomic_path(path))
            with open(tmp, "w", encoding="utf-8", newline="") as fh:
                fh.write(text)


def save_figure(fig, path: str | os.PathLike, **savefig_kwargs) -> None:
    """Save a matplotlib figure atomically and close it (figures are not kept open)."""
    import matplotlib.pyplot as plt

    suffix = Path(path).suffix or ".png"
    try:
        with atomic_path(path, suffix=suffix) as tmp:
            fig.savefig(tmp, **savefig_kwargs)
    finally:
        plt.close(fig)


class MissingDependencyError(PostprocError):
    """An optional package that the asked-for output needs is not installed."""

    exit_code = EXIT_USAGE


def require_matplotlib(option: str = "--plot") -> None:
    """Refuse ``option`` up front (exit 2, with the install command) when matplotlib is missing."""
    import importlib.util

    if importlib.util.find_spec("matplotlib") is None:
        raise MissingDependencyError(f"{option} needs matplotlib, which is not installed",
                                     hint="install it with: python -m pip install matplotlib "
                                          "(or leave out " + option + ")")
