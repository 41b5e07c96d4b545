"""One large program corrected in two processes, with the output one process writes.

The program is cut at a chunk boundary, line S (about the middle, weighted so that both
processes end together). This process corrects lines 1 to S as usual. A forked child
reads the same program from its first line, but corrects nothing before a warm-up
window of a few chunks that ends at S: until then it only reads (the interpreter's modal
state advances, nothing is planned or written), in the window it corrects and throws the
output away, from S on it writes the corrected lines to a temporary file.

Whether the child's lines after S are the lines one process writes is checked, not
assumed: at S both processes take the whole state a run carries from one chunk to the
next (:func:`state_of`: the corrector's emitted position, motion and previous targets,
the interpreter's modal state, offsets, tool table, stored positions, ...), and the
child's part is used only when the two are equal, value for value. Everything after S
is a function of that state and the lines after S (the output does not depend on where
chunks end: tests check it), so the child writes what this process would have. When they
differ (the window was too short for every axis to be named, a program that stores a
corrected position before S, ...) the child is stopped and this process goes on alone
from S: the same output, only slower.

An error of the child's part is raised here, as one process would have raised it (the
state agreed); an error before S is this process's own. The child's temporary file is
removed however the run ends.
"""

from __future__ import annotations

import dataclasses
import math
import multiprocessing
import signal
import sys
import tempfile
import warnings
from collections.abc import Callable, Iterable
from typing import IO, Any, Protocol

import numpy as np

from postproc.errors import PostprocError

#: a run's report (:class:`postproc.gcode.pipeline.CorrectReport`, a dataclass)
CorrectReport = Any


class Corrector(Protocol):
    """What a split run uses of :class:`postproc.gcode.pipeline.Corrector`."""

    report: CorrectReport

    @property
    def interp(self) -> object: ...

    @property
    def linear_exact(self) -> bool: ...

    @property
    def chunk_lines(self) -> int: ...

    def run(self, lines: Iterable[str], write: Callable[[str], object],
            progress: Callable[[int], None] | None = None, source: Any = None, *, skip_until: int = 0,
            boundary: Callable[[int], bool] | None = None) -> CorrectReport: ...

#: a program is split only when it has at least this many chunks
MIN_CHUNKS = 8
#: the chunks the child corrects before S (output thrown away) to settle its state
WARMUP_CHUNKS = 2
#: the cost of reading a line without correcting it, as a share of correcting it
#: (measured on the gencam program: about 0.3 with an affine engine, 0.1 with a model
#: whose moves are sampled); sets where the program is cut so that both parts end together
READ_SHARE_AFFINE = 0.4
READ_SHARE_SAMPLED = 0.1

Write = Callable[[str], object]

# Attributes of a Corrector and its Interpreter that are the run's configuration (the
# same in both processes by construction) or caches of pure functions, not state carried
# from chunk to chunk. Everything else is compared.
_CONFIG = frozenset({"engine", "setup", "opt", "path", "cal_name", "cal_sha", "report", "interp", "_decimals",
                     "linear_exact", "bulk_plan", "accept_residual_mm", "expanded"})
_INTERP_CONFIG = frozenset({"setup", "path", "dialect", "lenient_setup"})


def usable() -> bool:
    """Whether this process may fork a child for a run: Linux with the "fork" start
    method, not from a daemon process (a ``multiprocessing.Pool`` worker)."""
    return (sys.platform == "linux" and "fork" in multiprocessing.get_all_start_methods()
            and not multiprocessing.current_process().daemon)


def count_lines(path: str) -> int:
    """The number of lines of the file (a last line without an ending counts)."""
    n = 0
    last = b"\n"
    with open(path, "rb") as fh:
        while block := fh.read(1 << 20):
            n += block.count(b"\n")
            last = block[-1:]
    return n + (last != b"\n")


def cut(lines: int, chunk: int, affine: bool) -> tuple[int, int] | None:
    """``(S, W)``: split after line S (the first chunk boundary at or after it), the child
    correcting from line W (WARMUP_CHUNKS chunks before S); None when the program is too
    short to gain. The child reads W lines at the read share of the cost and corrects the
    rest; this process corrects S lines: S = (N + W_lines (1 - r)) / (2 - r)."""
    if lines < MIN_CHUNKS * chunk:
        return None
    r = READ_SHARE_AFFINE if affine else READ_SHARE_SAMPLED
    window = WARMUP_CHUNKS * chunk
    s = int((lines + window * (1.0 - r)) / (2.0 - r))
    return s, max(0, s - window)


def state_of(c: Corrector) -> object:
    """The state a run carries from one chunk to the next, as plain comparable values
    (floats by their bits, dicts and sets in sorted order)."""
    mine = {k: v for k, v in vars(c).items() if k not in _CONFIG}
    interp = {k: v for k, v in vars(c.interp).items() if k not in _INTERP_CONFIG}
    return _canon((mine, interp))


def _canon(x: object) -> object:
    """``x`` as nested tuples of type names and values; TypeError for what is not data."""
    if x is None or isinstance(x, (bool, int, str)):
        return (type(x).__name__, x)
    if isinstance(x, float):
        return ("float", x.hex() if math.isfinite(x) else repr(x))
    if isinstance(x, np.ndarray):
        return ("ndarray", str(x.dtype), x.shape, _canon(x.ravel().tolist()))
    if isinstance(x, np.generic):
        return ("np." + type(x).__name__, _canon(x.item()))
    if isinstance(x, (list, tuple)):
        return (type(x).__name__, tuple(_canon(v) for v in x))
    if isinstance(x, dict):
        return ("dict", tuple(sorted(((_canon(k), _canon(v)) for k, v in x.items()), key=repr)))
    if isinstance(x, (set, frozenset)):
        return ("set", tuple(sorted((_canon(v) for v in x), key=repr)))
    if callable(x):
        raise TypeError(f"{type(x).__name__} is a function, not data")
    slots = getattr(type(x), "__slots__", None)
    if hasattr(x, "__dict__") or slots:
        fields = dict(vars(x)) if hasattr(x, "__dict__") else {}
        for name in slots or ():
            if hasattr(x, name):
                fields[name] = getattr(x, name)
        if any(callable(v) for v in fields.values()):
            raise TypeError(f"{type(x).__name__} holds a function")
        return (type(x).__qualname__, _canon(fields))
    raise TypeError(f"no comparable value for {type(x).__name__}")


def merge(head: CorrectReport, tail: CorrectReport) -> CorrectReport:
    """The report of a whole run from its two parts (``tail``: the child's, from S)."""
    out = dataclasses.replace(head)
    for f in dataclasses.fields(head):
        name = f.name
        a, b = getattr(head, name), getattr(tail, name)
        if name in _TAKE_TAIL:
            setattr(out, name, b)
        elif name in _LARGEST:
            setattr(out, name, max(a, b))
        elif name in _SAME:
            pass
        else:  # a count
            setattr(out, name, a + b)
    return out


# how each field of a CorrectReport merges (the others are counts, added): a test checks
# that every field that is not a count is named here
_TAKE_TAIL = frozenset({"lines_in", "g54_assumed_zero"})  # as at the program's end
_LARGEST = frozenset({"max_correction_mm", "max_residual_mm"})
_SAME = frozenset({"solver", "accept_residual_mm", "expanded", "header_lines"})


def run(make: Callable[[], Corrector], get_lines: Callable[[], Iterable[str]], write: Write,
        progress: Callable[[int], None] | None, lines: int) -> CorrectReport:
    """Correct the program ``get_lines()`` gives (``lines`` lines) in this process and a
    forked child (see the module docstring); ``make()``: a new Corrector for the run.
    The same output, report and errors as ``make().run(get_lines(), write, progress)``."""
    first = make()
    where = cut(lines, first.chunk_lines, first.linear_exact)
    if where is None:
        return first.run(get_lines(), write, progress=progress)
    s, w = where
    # the child's lines, in a file without a name (gone however the run ends), opened
    # before the fork: the child writes it, this process reads it once the child is done
    part = tempfile.TemporaryFile("w+", encoding="utf-8", errors="surrogateescape", newline="")
    ctx = multiprocessing.get_context("fork")
    recv, send = ctx.Pipe(duplex=False)
    child = ctx.Process(target=_child, args=(make, get_lines, part, s, w, max(1, lines // 100), send), daemon=True)
    try:
        with warnings.catch_warnings():
            # Python 3.12 and later warn of a fork in a process with threads (numpy's BLAS
            # pool, idle here); the child runs only this package's correcting code
            warnings.filterwarnings("ignore", message=r".*multi-threaded, use of fork\(\)",
                                    category=DeprecationWarning)
            child.start()
        send.close()
        agreed = None  # decided at the first boundary at or after S

        def boundary(n: int) -> bool:
            nonlocal agreed
            if agreed is not None or n < s:
                return False
            agreed = _agree(recv, n, first)
            if not agreed:
                _stop(child)
            return agreed

        report = first.run(get_lines(), write, progress=progress, boundary=boundary)
        if not agreed:
            return report
        while True:
            try:
                kind, payload = recv.recv()
            except EOFError:
                raise Failed("the process correcting the program's second part ended without a word") from None
            if kind == "progress":
                if progress is not None:
                    progress(payload)
            elif kind == "done":
                tail = payload
                if progress is not None:
                    progress(tail.lines_in)  # the last lines, after the child's last boundary
                break
            elif isinstance(payload, PostprocError):  # the child's part refused, as one process would have
                raise payload
            else:  # it failed otherwise (its temporary file could not be written, ...)
                raise Failed(f"the process correcting the program's second part failed: {payload!r}")
        try:
            part.seek(0)
            while text := part.read(1 << 20):
                write(text)
        except OSError as exc:
            if exc.filename is None:  # the temporary file (a failing output names itself)
                raise Failed(f"the second part could not be read back: {exc}") from None
            raise
        return merge(report, tail)
    finally:
        recv.close()
        _stop(child)
        part.close()


class Failed(Exception):
    """The child failed for a reason of its own (not the program's): the caller corrects
    the program again in one process."""


def _agree(recv, n: int, c: Corrector) -> bool:
    """Whether the child reached the same boundary ``n`` with this process's state."""
    try:
        kind, payload = recv.recv()
    except EOFError:
        return False
    if kind != "split":
        return False  # the child stopped before S (an error there is this process's to find)
    at, theirs = payload
    try:
        mine = state_of(c)
    except TypeError:
        return False
    return at == n and theirs == mine


def _stop(child) -> None:
    if child.is_alive():
        child.terminate()
    child.join()


def _child(make: Callable[[], Corrector], get_lines: Callable[[], Iterable[str]], part: IO[str], s: int, w: int,
           every: int, conn) -> None:
    """The child's side of :func:`run`: read to line W, correct to S throwing the output
    away, send the state at S, then write the rest to ``part``; send progress (about
    every ``every`` lines: the parent reads it only once its own part is done, and the
    pipe holds a few kB), then the report of the part from S, or its error."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent stops it
    live = False
    told = 0
    try:
        c = make()

        def write(text: str) -> None:
            if live:
                part.write(text)

        def boundary(n: int) -> bool:
            nonlocal live, told
            if live:
                if n - told >= every:
                    conn.send(("progress", n))
                    told = n
            elif n >= s:
                try:
                    state = state_of(c)
                except TypeError:
                    state = None
                conn.send(("split", (n, state)))
                if state is None:
                    raise _Abandon
                live = True
                told = n
                # the report counts from S (the parent's counts the lines before)
                c.report = type(c.report)(solver=c.report.solver,
                                          accept_residual_mm=c.report.accept_residual_mm)
            return False

        report = c.run(get_lines(), write, skip_until=w, boundary=boundary)
        part.flush()
        conn.send(("done", report) if live else ("abandoned", None))
    except _Abandon:
        pass
    except BaseException as exc:  # noqa: BLE001 - every failure after S is the parent's to raise
        if live:
            try:
                conn.send(("error", exc))
            except Exception:  # noqa: BLE001 - an exception that does not pickle
                conn.send(("error", RuntimeError(f"correcting the program's second part failed: {exc!r}")))
        else:
            conn.send(("abandoned", None))
    finally:
        conn.close()


class _Abandon(Exception):
    """The child's state cannot be compared: it stops."""


