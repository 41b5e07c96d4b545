"""One large program corrected in several processes, with the output one process writes.

The program is cut at chunk boundaries S1 < S2 < ... (weighted so that all processes end
together). This process corrects lines 1 to S1 as usual. Forked child j reads the same
program from its first line, but corrects nothing before a warm-up window of a few
chunks that ends at Sj: until then it only reads (the interpreter's modal state advances,
nothing is planned or written), and after its first chunk it skips, unread, the lines
before the one :mod:`postproc.gcode.skipahead` finds for it (:func:`plan`); in the window
it corrects and throws the output away, from Sj to S(j+1) (the last child: to the end)
it writes the corrected lines to a temporary file.

Whether a child's lines are the lines one process writes is checked, not assumed: at
each cut the process that ends there and the child that starts there take the whole
state a run carries from one chunk to the next (:func:`state_of`: the corrector's
emitted position, motion and previous targets, the interpreter's modal state, offsets,
tool table, stored positions, ...), and the parts are joined only when the two are
equal, value for value. Everything after a cut is a function of that state and the lines
after it (the output does not depend on where chunks end: tests check it), so each child
writes what one process would have. When they differ at S1 (the window was too short for
every axis to move, a program that stores a corrected position before S1, ...) the
children are stopped and this process goes on alone from S1; at a later cut, the program
is corrected again in one process (:class:`Failed`): the same output either way, only
slower.

An error in a child's part is raised here, as one process would have raised it (every
cut before it agreed); an error before S1 is this process's own. The children's
temporary files have no name: nothing is left however the run ends.
"""

from __future__ import annotations

import dataclasses
import math
import multiprocessing
import os
import tempfile
from collections.abc import Callable, Iterable
from typing import IO, Any, Protocol

import numpy as np

from postproc.errors import PostprocError
from postproc.gcode import forking, scanner, skipahead
from postproc.gcode.cutter import merge_bounds

#: a run's report (:class:`postproc.gcode.pipeline.CorrectReport`, a dataclass)
CorrectReport = Any


class Corrector(Protocol):
    """What a split run uses of :class:`postproc.gcode.pipeline.Corrector`."""

    report: CorrectReport

    @property
    def interp(self) -> object: ...

    @property
    def planner(self) -> object: ...

    @property
    def writer(self) -> object: ...

    @property
    def reader(self) -> object: ...

    @property
    def linear_exact(self) -> bool: ...

    @property
    def chunk_lines(self) -> int: ...

    def run(self, lines: Iterable[str], write: Callable[[str], object],
            progress: Callable[[int], None] | None = None, source: Any = None, *, skip_until: int = 0,
            boundary: Callable[[int], bool] | None = None, go_on_from: int = 0) -> CorrectReport: ...


#: a program is cut only when it has at least this many chunks
MIN_CHUNKS = 8
#: the chunks a child corrects before its cut (output thrown away) to settle its state
WARMUP_CHUNKS = 2
#: the cost of reading a line without correcting it, as a share of correcting it; sets
#: where the program is cut so that all parts end together. Measured on the gencam
#: program, 1M lines, two processes, alternated runs: with an affine engine about 0.3
#: where the reader is compiled (0.3 against 0.4: 9.35 s against 9.9 s, medians of 8;
#: 0.2 did as well as 0.3) and about half uncompiled (0.5 against 0.4 and 0.6: 15.9 s
#: against 16.3 and 17.2 s, medians of 3); about 0.1 with a model whose moves are sampled
READ_SHARE_AFFINE = 0.5 if scanner.__file__.endswith(".py") else 0.3
READ_SHARE_SAMPLED = 0.1
#: the cost of a line skipped unread (:mod:`postproc.gcode.skipahead`), the same way:
#: gencam 1M lines, static, two processes: 498,885 lines skipped in 0.043 s, and then the
#: two processes took 3.74 and 3.78 s
READ_SHARE_SKIP = 0.02
#: a further process is used only where it shortens the first part by this share
MIN_GAIN = 0.1
#: and never more processes than this (each holds its own chunk: some 60 MB)
MAX_PROCESSES = 16

Write = Callable[[str], object]

# Attributes of a Corrector and its Interpreter that are the run's configuration (the
# same in both processes by construction) or caches of pure functions, not state carried
# from chunk to chunk. Everything else is compared.
_CONFIG = frozenset({"engine", "setup", "opt", "path", "cal_name", "cal_sha", "_report", "interp",
                     "accept_residual_mm", "expanded", "planner", "writer", "reader"})
_PLANNER_CONFIG = frozenset({"engine", "opt", "report", "path", "rotary", "setup_context", "accept_residual_mm",
                             "linear_exact", "bulk_plan"})
_WRITER_CONFIG = frozenset({"opt", "report", "path", "_long_line", "_decimals", "cutter"})
_READER_CONFIG = frozenset({"interp", "planner", "opt", "report", "path", "source", "use_bulk", "dec_mm", "dec_in"})
_INTERP_CONFIG = frozenset({"setup", "path", "dialect", "lenient_setup", "d", "_g_alias", "_dialect_g", "_iso_blocks"})


def count_lines(path: str) -> int:
    """The number of lines of the file (a last line without an ending counts); a line
    longer than :data:`postproc.fileio.MAX_INPUT_LINE_CHARS` is refused once that many
    bytes of it are read (a file without line ends such as /dev/zero has no end)."""
    from postproc.fileio import count_lines as bounded_count

    return bounded_count(path)


def cuts(lines: int, chunk: int, affine: bool, processes: int, share: float | None = None) -> list[int] | None:
    """The cuts S1 < S2 < ... for at most ``processes`` processes (each part ends at the
    first chunk boundary at or after its cut), or None when the program is too short to
    gain. This process corrects S1 lines; child j reads W_j = S_j - (the window) lines at
    the read share r of the cost and corrects the rest of its part: every process's cost
    equal, S(j+1) = S1 + (1 - r) W_j, the last part ending at the program's end. A process
    is added only while it shortens the first part by :data:`MIN_GAIN` at least (the
    reading every child repeats makes each one gain less), and only while no part is
    shorter than the window. ``share``: r where it is not the reader's (children that
    skip lines)."""
    if lines < MIN_CHUNKS * chunk:
        return None
    r = share if share is not None else READ_SHARE_AFFINE if affine else READ_SHARE_SAMPLED
    window = WARMUP_CHUNKS * chunk
    best: list[int] | None = None
    for k in range(2, min(processes, MAX_PROCESSES) + 1):
        lo, hi = 0.0, float(lines)
        for _ in range(60):  # the last end grows with S1: bisection for the program's end
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if _ends(mid, k, r, window)[-1] < lines else (lo, mid)
        at = [int(x) for x in _ends(hi, k, r, window)[:-1]]
        parts = [b - a for a, b in zip([0, *at], [*at, lines], strict=True)]
        if min(parts) < window or (best is not None and at[0] > (1.0 - MIN_GAIN) * best[0]):
            break
        best = at
    return best


def plan(lines: int, chunk: int, affine: bool, processes: int, path: str | None
         ) -> tuple[list[int], list[int]] | None:
    """The cuts (:func:`cuts`) and the line each child goes on reading from after its first
    chunk (:func:`postproc.gcode.skipahead.go_on_from`; 0: it reads every line), or None
    when the program stays in one process. The cuts are placed for what each child reads:
    the lines it skips at :data:`READ_SHARE_SKIP`, the others at the reader's share."""
    read = READ_SHARE_AFFINE if affine else READ_SHARE_SAMPLED
    window = WARMUP_CHUNKS * chunk
    at = cuts(lines, chunk, affine, processes)
    if at is None or path is None:
        return None if at is None else (at, [0] * len(at))
    sc: skipahead.Scan | None = None
    share = READ_SHARE_SKIP
    for _ in range(2):  # the cuts for the lines skipped, then for those the children skip there
        at = cuts(lines, chunk, affine, processes, share) or at
        if sc is None or sc.upto < max(at):  # (a cut that moves little is scanned to once)
            sc = skipahead.scan(path, chunk, max(at) + 2 * window)
        go = [skipahead.go_on_from(path, sc, s - window, s, chunk) for s in at]
        share = max(read if not g else (READ_SHARE_SKIP * g + read * (s - window - g)) / (s - window)
                    for g, s in zip(go, at, strict=True))
    return at, go


def _ends(s1: float, k: int, r: float, window: int) -> list[float]:
    """Where each of ``k`` parts ends when the first ends at ``s1`` and all cost alike."""
    out = [s1]
    for _ in range(k - 1):
        out.append(s1 + (1.0 - r) * max(0.0, out[-1] - window))
    return out


def state_of(c: Corrector) -> object:
    """The state a run carries from one chunk to the next, as plain comparable values
    (floats by their bits, dicts and sets in sorted order)."""
    mine = {k: v for k, v in vars(c).items() if k not in _CONFIG}
    interp = {k: v for k, v in vars(c.interp).items() if k not in _INTERP_CONFIG}
    planner = {k: v for k, v in vars(c.planner).items() if k not in _PLANNER_CONFIG}
    writer = {k: v for k, v in vars(c.writer).items() if k not in _WRITER_CONFIG}
    reader = {k: v for k, v in vars(c.reader).items() if k not in _READER_CONFIG}
    return _canon((mine, interp, planner, writer, reader))


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
        elif name in _COMBINED:  # moves under cutter compensation and their bound
            setattr(out, name, merge_bounds(a, b))
        else:  # a count
            setattr(out, name, a + b)
    return out


# how each field of a CorrectReport merges (the others are counts, added): a test checks
# that every field that is not a count is named here
_TAKE_TAIL = frozenset({"lines_in", "g54_assumed_zero"})  # as at the program's end
_LARGEST = frozenset({"max_correction_mm", "max_residual_mm"})
_SAME = frozenset({"solver", "accept_residual_mm", "expanded", "header_lines"})
_COMBINED = frozenset({"cutter"})


def run(make: Callable[[], Corrector], get_lines: Callable[[], Iterable[str]], write: Write,
        progress: Callable[[int], None] | None, lines: int, processes: int = 2,
        path: str | None = None) -> CorrectReport:
    """Correct the program ``get_lines()`` gives (``lines`` lines) in this process and up
    to ``processes - 1`` forked children (see the module docstring); ``make()``: a new
    Corrector for the run. The same output, report and errors as
    ``make().run(get_lines(), write, progress)``. Every process opens the program file
    ``path`` itself: a file that changes while they read it is refused (the parts would
    come from different versions of it)."""
    before = _identity(path)
    first = make()
    planned = plan(lines, first.chunk_lines, first.linear_exact, processes, path)
    if planned is None:
        return first.run(get_lines(), write, progress=progress)
    at, go = planned
    window = WARMUP_CHUNKS * first.chunk_lines
    ctx = multiprocessing.get_context("fork")
    every = max(1, lines // 100)
    children = []  # (process, its pipe's end here, its lines: a file without a name)
    try:
        for j, start in enumerate(at):
            # opened before the fork: the child writes it, this process reads it once the
            # child is done (gone however the run ends)
            part = tempfile.TemporaryFile("w+", encoding="utf-8", errors="surrogateescape", newline="")
            recv, send = ctx.Pipe(duplex=False)
            stop = at[j + 1] if j + 1 < len(at) else None
            child = ctx.Process(target=_child, args=(make, get_lines, part, start, stop,
                                                     (max(0, start - window), go[j]), every, send), daemon=True)
            children.append((child, recv, part))
            try:
                forking.start(child)
            except OSError as exc:  # no process to be had (EAGAIN, ENOMEM): one process does it
                raise Failed(f"no process for a part of the program: {exc}") from None
            send.close()
        agreed = None  # decided at the first boundary at or after S1

        def boundary(n: int) -> bool:
            nonlocal agreed
            if agreed is not None or n < at[0]:
                return False
            agreed = _agree(children[0][1], n, first)
            if not agreed:
                for child, _recv, _part in children:
                    _stop(child)
            return agreed

        report = first.run(get_lines(), write, progress=progress, boundary=boundary)
        if not agreed:
            return report
        end: tuple[int, object] | None = None  # the boundary and state where the last part ended
        for j, (_child_process, recv, part) in enumerate(children):
            if j and not _starts_at(recv, end):
                raise Failed(f"the state at the cut before part {j + 1} disagreed")
            tail, end = _part_of(recv, progress)
            report = merge(report, tail)
            try:
                part.seek(0)
                while text := part.read(1 << 20):
                    write(text)
            except OSError as exc:
                if exc.filename is None:  # the temporary file (a failing output names itself)
                    raise Failed(f"a part could not be read back: {exc}") from None
                raise
        if _identity(path) != before:
            raise PostprocError("the program file changed while it was being corrected", path=path,
                                hint="correct it again once it is written completely")
        return report
    finally:
        for child, recv, part in children:
            recv.close()
            _stop(child)
            part.close()


def _identity(path: str | None) -> tuple[int, ...] | None:
    """What tells a version of the file at ``path`` from another: device, inode, size and
    modification time (None without a path or a file)."""
    if path is None:
        return None
    try:
        st = os.stat(path)
    except OSError:
        return None
    return (st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns)


def _starts_at(recv, end: tuple[int, object] | None) -> bool:
    """Whether the child behind ``recv`` started where the part before it ended (``end``:
    its boundary and state), from the child's first word."""
    try:
        kind, payload = recv.recv()
    except EOFError:
        return False
    return kind == "split" and end is not None and payload == end


def _part_of(recv, progress: Callable[[int], None] | None) -> tuple[CorrectReport, tuple[int, object] | None]:
    """Wait for a child's part: (its report, where it ended and its state there, None
    for the last part); raise its refusal, or Failed."""
    end = None
    while True:
        try:
            kind, payload = recv.recv()
        except EOFError:
            raise Failed("a process correcting a part of the program ended without a word") from None
        if kind == "progress":
            if progress is not None:
                progress(payload)
        elif kind == "end":
            end = payload
        elif kind == "done":
            if progress is not None:
                progress(payload.lines_in)  # the last lines, after the child's last boundary
            return payload, end
        elif isinstance(payload, PostprocError):  # the part refused, as one process would have
            raise payload
        else:  # it failed otherwise (its temporary file could not be written, ...)
            raise Failed(f"a process correcting a part of the program failed: {payload!r}")


class Failed(Exception):
    """The child failed for a reason of its own (not the program's): the caller corrects
    the program again in one process."""


def _agree(recv, n: int, c: Corrector) -> bool:
    """Whether the first child started at boundary ``n`` with this process's state there
    (one that stopped before, or a state that cannot be compared: no)."""
    try:
        mine = state_of(c)
    except TypeError:
        return False
    return _starts_at(recv, (n, mine))


def _stop(child) -> None:
    if child.pid is None:  # never started
        return
    if child.is_alive():
        child.terminate()
    child.join()


def _child(make: Callable[[], Corrector], get_lines: Callable[[], Iterable[str]], part: IO[str], start: int,
           stop: int | None, reading: tuple[int, int], every: int, conn) -> None:
    """A child's side of :func:`run`: read to line W (``reading``: W, and the line it goes
    on from after the first chunk, skipping those before), correct to the first boundary at or
    after ``start`` throwing the output away, send the state there, then write its part
    to ``part`` up to the first boundary at or after ``stop`` (None: the end), where it
    sends the state again; send progress (about every ``every`` lines: the parent reads
    it only once the parts before are done, and a pipe holds a few kB), then the report
    of its part, or its error."""
    forking.in_child()
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
                if stop is not None and n >= stop:
                    conn.send(("end", (n, state_of(c))))
                    return True
                if n - told >= every:
                    conn.send(("progress", n))
                    told = n
            elif n >= start:
                try:
                    state = state_of(c)
                except TypeError:
                    state = None
                conn.send(("split", (n, state)))
                if state is None:
                    raise _Abandon
                live = True
                told = n
                # the report counts from the cut (the part before counts the lines before)
                c.report = type(c.report)(solver=c.report.solver,
                                          accept_residual_mm=c.report.accept_residual_mm)
            return False

        report = c.run(get_lines(), write, skip_until=reading[0], boundary=boundary, go_on_from=reading[1])
        part.flush()
        conn.send(("done", report) if live else ("abandoned", None))
    except _Abandon:
        pass
    except BaseException as exc:  # noqa: BLE001 - every failure after the cut is the parent's to raise
        if live:
            try:
                conn.send(("error", exc))
            except Exception:  # noqa: BLE001 - an exception that does not pickle
                conn.send(("error", RuntimeError(f"correcting a part of the program failed: {exc!r}")))
        else:
            conn.send(("abandoned", None))
    finally:
        conn.close()


class _Abandon(Exception):
    """The child's state cannot be compared: it stops."""


