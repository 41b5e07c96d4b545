"""The fast lane: plain absolute straight moves read and rewritten in one pass.

Most lines of CAM output are ``[N..] [G0|G1] X.. Y.. [Z..] [F..]``. When the modal
state is simple (G90, G94, G0/G1, no rotary axes, every axis positioned, offsets
already resolved) and the engine needs no segmentation of straight moves, such a
line is read here without building the general :class:`Move`, and written back by
splicing the new numbers into it. Every other line takes the general path; the
result is the same (tests run both paths on the same programs).
"""

from __future__ import annotations

import math

from postproc.errors import PostprocError
from postproc.gcode import emit, lexer
from postproc.gcode.interp import _GKEYS, Move
from postproc.gcode.state import LINE, MOTION_CODES, RAPID

_AXIS = {"X": 0, "Y": 1, "Z": 2, "x": 0, "y": 1, "z": 2}
# axes a line does not name, by the bit mask of those it names
_MISSING = {m: tuple(k for k in range(3) if not m & (1 << k)) for m in range(8)}
_LETTER = "XYZ"
_FINDALL = lexer._WORD_RUN.findall


class FastMove:
    """What the planner and the emitter need of a plain straight move."""

    __slots__ = ("lineno", "kind", "q0", "q1", "r", "shift", "unit", "spans", "motion_word", "rotary",
                 "arc", "arc_absolute", "feed", "missing")
    fixed = False  # never a stored-position move
    then = None
    cycle = None
    probe = 0

    def __init__(self, lineno, kind, q0, q1, r, shift, unit, spans, motion_word, arc_absolute, feed, missing):
        self.lineno = lineno
        self.kind = kind
        self.q0 = q0
        self.q1 = q1
        self.r = r
        self.shift = shift
        self.unit = unit
        self.spans = spans  # [(start, end, axis, number_text, value), ...] in line order
        self.motion_word = motion_word
        self.rotary = {}
        self.arc = None
        self.arc_absolute = arc_absolute
        self.feed = feed
        self.missing = missing  # axes the line does not name

    def to_move(self, line: str) -> Move:
        """The general Move of the same line (for the rare cases the fast emitter hands on)."""
        words = lexer.scan_words(line)
        idx = [-1, -1, -1]
        feed_idx = motion_idx = -1
        for i, w in enumerate(words):
            if w[0] in "XYZ":
                idx["XYZ".index(w[0])] = i
            elif w[0] == "F":
                feed_idx = i
            elif w[0] == "G":
                motion_idx = i
        return Move(self.lineno, self.kind, self.q0, self.q1, self.r, self.shift, self.unit, False,
                    self.arc_absolute, words, tuple(idx), feed_idx, False, self.feed, {}, None, [], False,
                    motion_idx, ())


def read_fast(interp, lineno: int, line: str) -> FastMove | None:
    """Interpret ``line`` if it is a plain absolute straight move in a simple state, else None.

    The caller checks the state conditions (see :func:`state_allows`); nothing is
    changed unless a FastMove is returned.
    """
    st = interp.state
    shift = interp._fast_shift
    unit = 25.4 if st.inch else 1.0
    q1 = list(st.pos)
    motion = st.motion
    motion_word = False
    feed = None
    spans = []
    seen = 0
    pos = 0
    for ws1, letter, ws2, num in _FINDALL(line):
        lpos = pos + len(ws1)
        start = lpos + 1 + len(ws2)
        pos = start + len(num)
        k = _AXIS.get(letter)
        if k is not None:
            bit = 1 << k
            if seen & bit:
                return None
            seen |= bit
            v = float(num)
            q1[k] = v * unit + shift[k]
            spans.append((start, pos, k, num, v))
            continue
        up = letter.upper()
        bit = 8 if up == "F" else 16 if up == "G" else 32 if up == "N" else 0
        if not bit or seen & bit:
            return None
        seen |= bit
        if bit == 8:
            feed = float(num)
        elif bit == 16:
            key = _GKEYS.get(num)
            if key is None or key > 10:
                return None
            motion = MOTION_CODES[key]
            motion_word = True
    # findall skips what it cannot read; the positions above assume it skipped nothing,
    # so anything skipped shows up as text left after the last word
    if line[pos:].strip(" \t\r\n") or not spans or motion not in (RAPID, LINE):
        return None
    q0 = tuple(st.pos)
    st.pos = q1
    st.motion = motion
    if feed is not None:
        st.feed = feed
    interp.motion_word = motion_word
    return FastMove(lineno, motion, q0, tuple(q1), interp._fast_r, shift, unit, spans, motion_word,
                    st.arc_absolute, st.feed, _MISSING[seen & 7])


def prime_shift(interp) -> bool:
    """Compute the offsets of absolute words in the current state (as the interpreter's
    own fast block does); False if they cannot be (the general path then reports why)."""
    if interp._fast_shift is None:
        try:
            shift = interp.shift(False, None, None)
        except PostprocError:
            return False
        interp._fast_shift = shift
        interp._fast_r = interp.tool_r()
    return True


def state_allows(interp, motion_word: bool = False) -> bool:
    """Whether the modal state lets the fast lane read the next line (``motion_word``:
    that line names its own G0/G1, so the modal motion does not matter)."""
    st = interp.state
    return (not interp.ended and not st.incremental and not st.inverse_time and interp._fast_shift is not None
            and not interp.used_rotary and (motion_word or st.motion in (RAPID, LINE))
            and not (math.isnan(st.pos[0]) or math.isnan(st.pos[1]) or math.isnan(st.pos[2])))


def emit_fast(corrector, line: str, fm: FastMove, target, write, decimals: int) -> bool:
    """Write the corrected line; False if the general emitter must do it."""
    if not fm.motion_word and corrector.emitted_motion != fm.kind:
        return False
    qe = corrector.qe
    shift, unit = fm.shift, fm.unit
    half = emit.HALF_UNIT
    fmt = emit.fmt
    pieces = []
    last = 0
    edits = 0
    for start, end, k, num, ov in fm.spans:
        v = (target[k] - shift[k]) / unit
        dot = num.find(".")
        dout = decimals if dot < 0 or len(num) - dot - 1 <= decimals else len(num) - dot - 1
        if abs(v - ov) < half[dout]:
            qe[k] = ov * unit + shift[k]
        else:
            pieces.append(line[last:start])
            pieces.append(fmt(v, dout))
            last = end
            qe[k] = round(v, dout) * unit + shift[k]
            edits += 1
    if fm.missing:
        added = []
        hd = half[decimals]
        for k in fm.missing:
            t = target[k]
            if abs(t - qe[k]) / unit < hd or math.isnan(qe[k]):
                continue
            v = (t - shift[k]) / unit
            added.append(_LETTER[k] + fmt(v, decimals))
            qe[k] = round(v, decimals) * unit + shift[k]
        if added:
            sep = " " if (" " in line or "\t" in line) else ""
            text = sep + sep.join(added)
            at = fm.spans[-1][1]
            pieces.append(line[last:at])
            pieces.append(text.lower() if line.islower() else text)
            last = at
            edits += 1
    corrector.emitted_motion = fm.kind
    rep = corrector.report
    rep.words_changed += edits
    rep.lines_changed += edits > 0
    rep.lines_out += 1
    if not pieces:
        write(line)
    else:
        pieces.append(line[last:])
        write("".join(pieces))
    return True
