"""Where a process correcting a later part of a program may go on reading from.

A child of :mod:`postproc.gcode.split` must reach its warm-up with the modal state one
process would have there. Reading every line before it costs about a third of
correcting them, and most of those lines only move the machine: the position, motion
and feed they leave are set again by the lines that follow. So the child reads the
first chunk (the program's setup), skips the lines up to a line from which the state
at its cut is most likely set again, and reads on from there: the last tool change (the
program sets the tool, its length, the spindle and the position again after it); in a
program with none there, the last rapid move naming X and Y, or, where no arc follows
up to the cut, the last line with a G0 or G1 word; in either case no later than the last
line naming each axis before the cut (a 2D contour leaves Z where a line long before
put it).

It skips only lines in which a byte scan of the file finds none of the words that set
state the lines after them need not set again: work offsets and G92, units, cutter
compensation, frames, canned cycles, parameters, assignments and subprograms
(:data:`DURABLE_G`, :data:`DURABLE_BYTES`, :data:`DURABLE_WORDS`). All of this is a
guess at where reading can start, not a promise: the state at the cut is still compared
value for value with the process that corrected up to it, and a child whose state
differs is not used (:func:`postproc.gcode.split.run`); the output is the same either
way, only the time differs.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

#: two-digit G codes (and their .n forms) whose state outlasts the lines after them:
#: local and work offsets, G92, units, cutter compensation, polar coordinates,
#: scaling and rotation, macro calls, stored positions, canned cycles (their Z, R, P and
#: Q stay after G80)
DURABLE_G = frozenset({
    b"G10", b"G15", b"G16", b"G20", b"G21", b"G41", b"G42", b"G50", b"G51", b"G52", b"G54", b"G55", b"G56",
    b"G57", b"G58", b"G59", b"G65", b"G66", b"G68", b"G69", b"G92", b"G28.1", b"G30.1", b"G54.1",
    b"G73", b"G74", b"G76", b"G81", b"G82", b"G83", b"G84", b"G85", b"G86", b"G87", b"G88", b"G89",
})
#: characters of parameters, expressions and assignments
DURABLE_BYTES = b"#=["
#: words of subprograms and of calls (the file upper-cased): O words, M98 and M99 (each
#: pattern on its own: one with a literal start is searched for much faster)
DURABLE_WORDS = (re.compile(rb"O[0-9]"), re.compile(rb"M9[89](?![0-9])"))
_G_CODE = re.compile(rb"G[1-9][0-9](?:\.[0-9])?")
_TOOL_CHANGE = re.compile(rb"M0?6(?![0-9])")
_T_WORD = re.compile(rb"(?<![A-Z])T[0-9]")
_RAPID_XY = re.compile(rb"^[ \t]*(?:N[0-9]+[ \t]*)?G0?0(?![0-9.])[^(;\n]*X[^(;\n]*Y")
_STRAIGHT = re.compile(rb"(?<![A-Z])G0?[01](?![0-9.])")
_ARC = re.compile(rb"(?<![A-Z])G0?[23](?![0-9.])")
#: the axes whose last position a skipped line may have set
_AXES = {a: re.compile(a + rb"[ \t]*[-+.0-9]") for a in (b"X", b"Y", b"Z", b"A", b"B", b"C")}
#: lines looked at before a cut for the line to go on from (the child reads them all where
#: this is not enough), and the most bytes of them
LOOK_BACK = 50_000
LOOK_BACK_BYTES = 4 << 20
#: lines read a block at a time by the scan (bytes)
_BLOCK = 1 << 17
#: how many lines before a tool change a T word of it may stand
_T_BEFORE = 3
_ALL = bytes(range(256))
_NOT_DURABLE = _ALL.translate(None, DURABLE_BYTES)


@dataclass
class Scan:
    """What the scan of a program's lines up to ``upto`` found: the line of its first
    durable word after ``since`` (0: none), each block of lines it read (first line, byte
    offset, size), and the blocks with a tool change (by index). Its size does not grow
    with what a block holds: where a tool change starts is worked out again from the file
    for the few blocks a child may go on from."""

    since: int
    upto: int
    durable: int = 0
    usable: bool = True  # False: a line ends in a lone CR (lines counted otherwise than read)
    blocks: list[tuple[int, int, int]] = field(default_factory=list)
    tools: list[int] = field(default_factory=list)

    def tool_starts(self, path: str, upto: int | None = None) -> list[int]:
        """The lines where tool changes start, up to line ``upto`` (all that were scanned)."""
        last = min(upto or self.upto, self.durable or self.upto)
        return [t for b in self.tools for t in self._starts_in(path, b) if t <= last]

    def last_tool_start(self, path: str, after: int, upto: int) -> int:
        """The last line after ``after`` and up to ``upto`` where a tool change starts (0: none)."""
        for b in reversed(self.tools):
            if self.blocks[b][0] > upto:
                continue
            starts = [t for t in self._starts_in(path, b) if after < t <= upto]
            if starts:
                return starts[-1]
            if self.blocks[b][0] <= after:
                break
        return 0

    def _starts_in(self, path: str, b: int) -> list[int]:
        line, offset, size = self.blocks[b]
        with open(path, "rb") as fh:
            fh.seek(offset)
            data = fh.read(size).upper()
        return [line - 1 + t for t in _tool_starts(data, [m.start() for m in _TOOL_CHANGE.finditer(data)])]


def scan(path: str, since: int, upto: int) -> Scan:
    """Scan the lines ``1..upto`` of the program at ``path`` (lines numbered from 1, a line
    ended by LF; durable words looked for after line ``since``)."""
    out = Scan(since, upto)
    line = 0  # lines before the block
    rest = b""
    with open(path, "rb") as fh:
        while line < upto:
            offset = fh.tell() - len(rest)
            raw = fh.read(_BLOCK)
            data = rest + raw
            cut = data.rfind(b"\n") + 1 if raw else len(data)
            if not data:
                break
            data, rest = data[:cut], data[cut:]
            if not data:  # a line longer than a block: read on (it is all in ``rest``)
                continue
            n = data.count(b"\n") + (not data.endswith(b"\n"))
            out.blocks.append((line + 1, offset, len(data)))
            data = data.upper()
            if b"\r" in data and data.count(b"\r") != data.count(b"\r\n"):
                out.usable = False
                return out
            first = _first_durable(data, since - line) if line + n > since and _has_durable(data) else 0
            if _TOOL_CHANGE.search(data, 0, _offset_of_line(data, first) if first else len(data)):
                out.tools.append(len(out.blocks) - 1)
            if first:
                out.durable = line + first
                return out  # nothing after it is skipped
            line += n
    return out


def _offset_of_line(data: bytes, k: int) -> int:
    """Where line ``k`` (numbered from 1) of ``data`` ends."""
    at = -1
    for _ in range(k):
        at = data.find(b"\n", at + 1)
        if at < 0:
            return len(data)
    return at + 1


def _first_durable(data: bytes, after: int) -> int:
    """The first line of a block (numbered from 1 in it) after its line ``after`` with a
    durable word, or 0."""
    for k, text in enumerate(data.split(b"\n")):
        if k >= after and _has_durable(text):
            return k + 1
    return 0


def _has_durable(data: bytes) -> bool:
    if len(data.translate(None, _NOT_DURABLE)):
        return True
    if any(p.search(data) for p in DURABLE_WORDS):
        return True
    return any(g in DURABLE_G for g in set(_G_CODE.findall(data)))


def _tool_starts(data: bytes, at: list[int]) -> list[int]:
    """The lines (numbered from 1 in the block ``data``) where the tool changes whose M6
    words stand at ``at`` start: the line of the M6, or of a T word up to
    :data:`_T_BEFORE` lines before it."""
    out: list[int] = []
    line, last = 1, 0  # the line of position ``last``
    for p in at:
        line += data.count(b"\n", last, p)
        last = p
        begin = data.rfind(b"\n", 0, p) + 1
        start = line
        for back in range(_T_BEFORE + 1):
            end = data.find(b"\n", begin)
            if _T_WORD.search(data, begin, len(data) if end < 0 else end):
                start = line - back
                break
            if begin == 0:
                break
            begin = data.rfind(b"\n", 0, begin - 1) + 1
        out.append(start)
    return out


def go_on_from(path: str, sc: Scan, warm_up: int, cut: int, chunk: int) -> int:
    """The line a child whose warm-up starts after line ``warm_up`` and whose part starts
    after line ``cut`` goes on reading from (0: it reads every line); never in the first
    two chunks (the first is read in any case)."""
    if not sc.usable:
        return 0
    top = min(cut, sc.upto)
    first = max(sc.since + 1, top - LOOK_BACK + 1)
    first, lines = _lines(path, sc, first, top)
    if not lines:
        return 0  # (none, or more bytes than the budget: every line read)
    limit = min(warm_up, top, sc.durable or top)
    # the axes: X, Y and Z, and the rotary axes the lines looked at name (one named only
    # before them is left where the first chunk put it: a guess, as the rest)
    joined = b"\n".join(lines)
    axes = [a for a, p in _AXES.items() if a in b"XYZ" or p.search(joined)]
    last_arc = 0
    named: dict[bytes, int] = {}
    for k in range(len(lines) - 1, -1, -1):  # the last line naming each axis, and the last arc
        text = lines[k]
        if not last_arc and _ARC.search(text):
            last_arc = first + k
        named.update((a, first + k) for a in axes if a not in named and _AXES[a].search(text))
        if last_arc and len(named) == len(axes):
            break
    if len(named) < len(axes) and first > sc.since + 1:
        return 0  # an axis last named before the lines looked at, no one knows where
    # (where they reach back to the first chunk, an axis they do not name was named there,
    # which is read, or never)
    limit = min(limit, *named.values())
    at = sc.last_tool_start(path, sc.since, limit)
    for k in range(limit - first, -1, -1) if not at else ():
        text = lines[k]
        if _RAPID_XY.match(text) or (first + k > last_arc and _STRAIGHT.search(text)):
            at = first + k
            break
    return at if at > 2 * chunk else 0


def _lines(path: str, sc: Scan, first: int, last: int) -> tuple[int, list[bytes]]:
    """Lines ``first..last`` of the program (upper case, without their endings), or only
    the last of them where they hold more than :data:`LOOK_BACK_BYTES` (none where even
    those hold twice as many): (the first line given, the lines)."""
    starts = [b for b in sc.blocks if b[0] <= first]
    ends = [b for b in sc.blocks if b[0] <= last]
    if not starts or last < first:
        return first, []
    line, offset, _size = starts[-1]
    end_offset = ends[-1][1] + ends[-1][2]
    if end_offset - offset > LOOK_BACK_BYTES:  # from the block where the budget starts
        within = [b for b in sc.blocks if b[1] >= end_offset - LOOK_BACK_BYTES]
        if not within:
            return first, []
        line, offset, _size = within[0]
        first = max(first, line)
    out: list[bytes] = []
    size = 0
    with open(path, "rb") as fh:
        fh.seek(offset)
        for raw in fh:
            if line > last:
                break
            if size > 2 * LOOK_BACK_BYTES:
                return first, []
            if line >= first:
                out.append(raw.rstrip(b"\r\n").upper())
                size += len(raw)
            line += 1
    return first, out
