"""Table-driven modal interpreter: one line in, the state advanced, a :class:`Move` out.

Semantics follow LinuxCNC (rs274ngc) where they matter to geometry:

- machine gauge position = program value x units + work offset + G92 offset + tool
  length offset (G43, along Z); G53 values are machine positions of the gauge point
  (no work, G92 or tool length offset: LinuxCNC's G53);
- within a block, modal settings (units, distance mode, plane, offsets, G43/G49,
  G92) take effect before the motion;
- G2 is clockwise seen from the positive end of the plane's normal axis (G17: Z,
  G18: Y, G19: X); P on an arc counts turns.

Anything that changes geometry in a way not modelled here is refused with
UnsupportedGcodeError naming line, column and construct.

A block is read in this order (:meth:`Interpreter._block`): its words into a
:class:`~postproc.gcode.interp_core.Block`, its M codes, the handler of each G code
(:data:`_G_HANDLERS`), the settings that end a block (G10, G52, G92), then the handler of
its motion family (:data:`MOTIONS`). The parts live beside this module and are mixed into
:class:`Interpreter`: the state and shared helpers in ``interp_core``, reading a line into
words in ``interp_words``, offsets and G28/G30 in ``interp_offsets``, canned cycles in
``interp_cycles``, straight moves, arcs and splines in ``interp_motion``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator

from postproc.errors import (
    GcodeSyntaxError,
    MissingSetupError,
    UnsupportedGcodeError,
)
from postproc.gcode import cutter, lexer
from postproc.gcode.interp_core import (
    AXES,
    EXPANDABLE_G,
    EXPANDABLE_M,
    MAX_WORD_VALUE,
    MIN_ARC_RADIUS_MM,
    ROTARY,
    Block,
    NeedsExpansion,
    Vals,
    col_of_word,
    gkey,
    start_position,
)
from postproc.gcode.interp_cycles import CyclesMixin
from postproc.gcode.interp_motion import (
    SPLINE_SAMPLE_MM,
    MotionMixin,
    spline_points,
    spline_samples,
)
from postproc.gcode.interp_offsets import OffsetsMixin
from postproc.gcode.interp_words import WordsMixin, blank_nested_comments, classify_construct
from postproc.gcode.moves import Arc, Cycle, Move, Role
from postproc.gcode.state import (
    ARC_CCW,
    ARC_CW,
    BEFORE_MOTION_M,
    CANNED_CYCLES,
    CUTTER_COMP,
    DWELL,
    HOME_CODES,
    HOME_STORE,
    IO_M,
    LINE,
    LOOKAHEAD_G,
    M_PARAMS,
    NEUTRAL_G,
    PLANES,
    RAPID,
    REFUSED_G,
    REFUSED_HINT,
    REFUSED_M,
    SPLINES,
    WORK_SYSTEMS,
)

# the names other modules import from here (some defined in interp_core)
__all__ = [
    "MAX_WORD_VALUE", "MIN_ARC_RADIUS_MM", "Arc", "Cycle", "Interpreter", "Move", "NeedsExpansion",
    "blank_nested_comments", "classify_construct", "col_of_word", "plain_moves", "spline_points",
    "spline_samples", "start_position",
]


class Interpreter(WordsMixin, OffsetsMixin, CyclesMixin, MotionMixin):
    """Advance a :class:`ModalState` line by line; see the module docstring."""

    # -- the block ---------------------------------------------------------------------
    def feed_line(self, lineno: int, line: str) -> Move | None:
        """Interpret one line (with its ending); return the Move it makes, if any."""
        self.motion_word = False
        self.rebase = None
        self.stored_here = None
        self.cycle_move, self.call_line, self.call_col = None, "", 0
        if self.ended:
            return None  # after M2/M30 the controller reads no further
        bom = line.startswith("\ufeff")
        if bom:  # a UTF-8 byte-order mark before the first line: not part of the block
            line = line[1:]
        words = lexer.scan_words(line) if self._iso_blocks else None
        block_delete = False
        if words is None:
            words, block_delete = self._slow_words(lineno, line)
        elif words and words[0].letter == "O" and len(words) == 1 and words[0].number.isdigit():
            return None  # O1234: a program number (or label): no geometry
        elif (self.d.numbered_program_line and len(words) == 2 and words[0].letter == "N"
              and words[1].letter == "O"):
            return None  # N1 O2: a program number after a sequence number (Fadal)
        if bom:
            words = [lexer.Word(a, b, c + 1, d + 1, e + 1) for a, b, c, d, e in words]
        if not words:
            self._drill_if_due(lineno)
            return None
        self.run_shift = None  # the slow path may change offsets, units or tool length
        if self.state.frame is not None:
            return self._framed_block(lineno, words, block_delete, self.state.frame)
        return self._block_and_cycle(lineno, words, block_delete)

    def _block_and_cycle(self, lineno: int, words: list[lexer.Word], block_delete: bool) -> Move | None:
        if self._arc_absolute_once:  # Sinumerik I=AC() J=AC(): G90.1 for this block only
            st, saved = self.state, self.state.arc_absolute
            st.arc_absolute, self._arc_absolute_once = True, False
            try:
                mv = self._block(lineno, words, block_delete)
            finally:
                st.arc_absolute = saved
        else:
            mv = self._block(lineno, words, block_delete)
        self._drill_if_due(lineno, max(words[0].letter_pos, 0) + 1)
        return mv

    def _framed_block(self, lineno: int, words: list[lexer.Word], block_delete: bool,
                      a: tuple[float, ...]) -> Move | None:
        """A block under a rotating, scaling or mirroring frame (Sinumerik): read as if the
        frame had no linear part, from the position seen in the frame's coordinates, then its
        points mapped to the machine (:func:`frames.machine_from_program`); a mirror turns
        G2 into G3 and back (Fundamentals, "MIRROR")."""
        from postproc.gcode import frames

        st = self.state
        try:
            s0 = self.shift(False, lineno, 1)
        except MissingSetupError:
            return self._block_and_cycle(lineno, words, block_delete)  # no move can be made here
        real = (st.pos[0], st.pos[1], st.pos[2])
        st.pos = list(frames.program_from_machine(a, s0, real))
        try:
            mv = self._block_and_cycle(lineno, words, block_delete)
        finally:
            s1 = self.shift(False, lineno, 1)
            st.pos = list(frames.machine_from_program(a, s1, st.pos))  # a list of 3
        for m in (mv, self.cycle_move):
            prev = real if m is mv or m is None else frames.machine_from_program(a, m.shift, m.q0)
            while m is not None:
                m.q0 = prev
                m.q1 = frames.machine_from_program(a, m.shift, m.q1)
                m.frame = a
                if m.arc is not None:
                    axes = PLANES[m.arc.plane][0]
                    if not frames.keeps_circles(a, axes):
                        raise self.error(UnsupportedGcodeError, "Sinumerik arc under a frame that does not keep it a "
                                        "circle in its plane (SCALE with unequal factors, or ROT about Z with "
                                        "G18/G19)", lineno, 1,
                                        hint="post the arc as its moves, or scale the plane's axes alike")
                    m.arc.center = frames.machine_from_program(a, m.shift, m.arc.center)
                    m.arc.clockwise = m.arc.clockwise != frames.reverses_arcs(a, axes)
                if m.cycle is not None:
                    c = m.cycle
                    c.steps = [(k, q if k == DWELL else frames.machine_from_program(a, m.shift, q))
                               for k, q in c.steps]
                    c.holes = [tuple(frames.machine_from_program(a, m.shift, q) for q in h) for h in c.holes]
                prev, m = m.q1, m.then
        return mv

    def _block(self, lineno: int, words: list[lexer.Word], block_delete: bool) -> Move | None:
        """One block: its words gathered into a :class:`Block`, its M codes, the handlers of
        its G codes (:data:`_G_HANDLERS`), the settings that take effect before the motion,
        then the handler of its motion family (:data:`MOTIONS`)."""
        b = self._gather(lineno, words, block_delete)
        self._m_codes(b)
        self._g_codes(b)
        if self._settings(b):
            return None
        return self._motion(b)

    def _gather(self, lineno: int, words: list[lexer.Word], block_delete: bool) -> Block:
        """The block's G and M codes and its other words by letter; a word the dialect does
        not read, or a letter given twice, is refused at its place."""
        gcodes: list[tuple[int, int]] = []  # (key, word index)
        mcodes: list[tuple[int, int]] = []
        vals: dict[str, tuple[float, int]] = {}
        for i, (letter, num, _start, _end, _lpos) in enumerate(words):
            if letter in "GM" and not abs(float(num)) <= MAX_WORD_VALUE:
                raise self.error(UnsupportedGcodeError, f"unknown code {letter}{num[:12]}...", lineno, _lpos + 1)
            if letter == "G":
                key = gkey(num)
                gcodes.append((self._g_alias.get(key, key) if self._g_alias else key, i))
            elif letter == "M":
                mcodes.append((gkey(num), i))
            else:
                if letter in vals:
                    raise self.error(GcodeSyntaxError, f"word {letter} appears twice in one block",
                                    lineno, _lpos + 1)
                if letter == "O":
                    self._foreign(" ".join(w.letter + w.number for w in words), lineno)
                    raise self.error(UnsupportedGcodeError, "O-word (subroutine or flow control)", lineno, _lpos + 1,
                                    hint="expand subroutines and loops in the CAM system before correcting")
                if letter == "E" and self.d.fixture_offset_word == "E":
                    vals[letter] = (float(num), i)  # Fadal E1..E48: a fixture offset
                    continue
                if letter in "UW" and not self.d.uvw_axes:
                    raise self.lathe.refusal(f"{letter} word (incremental {'X' if letter == 'U' else 'Z'} of a "
                                             f"lathe) at line {lineno}", self.path, lineno, _lpos + 1)
                if letter in "UVW" or (letter == "E" and not any(
                        (w.letter == "M" and gkey(w.number) // 10 in IO_M and gkey(w.number) % 10 == 0)
                        or (w.letter == "G" and gkey(w.number) in (1870, 470)) for w in words)):
                    raise self.error(UnsupportedGcodeError, f"{letter} axis word (axes other than XYZABC)",
                                    lineno, _lpos + 1)
                value = float(num)
                if not abs(value) <= MAX_WORD_VALUE:  # (also inf and nan)
                    raise self.error(GcodeSyntaxError, f"{letter} value {num[:12]}{'...' if len(num) > 12 else ''} is "
                                    f"beyond {MAX_WORD_VALUE:g}: no machine moves that far", lineno, _lpos + 1)
                vals[letter] = (value, i)
        if self.d.call_words and not gcodes and any(k in vals for k in self.d.call_words):
            self._foreign(" ".join(w.letter + w.number for w in words), lineno)  # Fadal L0102: a call
        return Block(lineno, words, vals, gcodes=gcodes, mcodes=mcodes, block_delete=block_delete)

    def _m_codes(self, b: Block) -> None:
        """The block's M codes and T word: program end, tool change, and the words that act
        before the motion (:attr:`Block.event_idx`)."""
        st, vals, lineno = self.state, b.vals, b.lineno
        tool_change = False
        # words acting before the motion, moved onto the first line when the block is split
        event_idx: list[int] = [vals[k][1] for k in "ST" if k in vals]
        for key, i in b.mcodes:
            if key % 10:
                raise self.error(UnsupportedGcodeError, f"M{key / 10:g} (unknown M code)", lineno, b.col(i))
            m = key // 10
            if m == 99 and "P" not in vals:
                # M99 reached in the main program (a call would have started the expansion,
                # which consumes the subprograms' own M99): the end of a pass, as the
                # expansion stage reads it too
                if st.incremental:
                    raise self.error(UnsupportedGcodeError, "M99 repeats the program from where it ended, in G91 "
                                    "(incremental): each pass starts elsewhere", lineno, b.col(i),
                                    hint="end the program with G90 before M99, or with M30")
                self.ended = True
                self.repeats = True
                continue
            if m in REFUSED_M:
                raise self.error(NeedsExpansion if (m in EXPANDABLE_M and self.may_expand) else UnsupportedGcodeError,
                                REFUSED_M[m], lineno, b.col(i),
                                hint="postproc expands M98/M99 subprograms defined in the same program; "
                                     "put the subprogram in the file")
            if m > 199:
                raise self.error(UnsupportedGcodeError, f"M{m} (unknown M code)", lineno, b.col(i))
            if m in BEFORE_MOTION_M:
                event_idx.append(i)
                event_idx.extend(vals[k][1] for k in M_PARAMS.get(m, "") if k in vals)
            if m == 6:
                tool_change = True
            if m in self.d.program_end_m:
                self.ended = True
            if m == 61:
                if "Q" not in vals:
                    raise self.error(GcodeSyntaxError, "M61 needs a Q word (tool number)", lineno, b.col(i))
                st.spindle_tool = int(vals["Q"][0])

        if "T" in vals:
            st.tool = int(vals["T"][0])
        if tool_change:
            st.spindle_tool = st.tool
        b.tool_change = tool_change
        b.event_idx = sorted(set(event_idx))

    def _g_codes(self, b: Block) -> None:
        """Run the handler of each G code of the block (:data:`_G_HANDLERS`, the dialect's
        own first), with cutter compensation's checks around them."""
        if self.state.comp != 400:
            cutter.check_block(self, b, b.gcodes, b.tool_change)
        for key, i in b.gcodes:
            handler = _G_HANDLERS.get(key)
            if self._dialect_g and key in self._dialect_g:
                handler = self._dialect_g[key]
            if handler is None and key in self.d.turning_cycles and self.lathe.weak:
                raise self.lathe.refusal(f"G{b.words[i].number} turning cycle at line {b.lineno}", self.path,
                                         b.lineno, b.col(i))
            if handler is None:
                raise self.error(UnsupportedGcodeError, f"G{b.words[i].number} (unknown G code)", b.lineno, b.col(i))
            handler(self, b, key, i)
        if b.comp is not None:
            cutter.switch(self, b, b.gcodes)

    def _settings(self, b: Block) -> bool:
        """The tool length and work offset the block selects (the dialect's D and E words
        too); True when the block ends there: a look-ahead code, G10, G52 or G92."""
        st, vals = self.state, b.vals
        if self.d.tool_length_word and self.d.tool_length_word in vals:  # Sinumerik D: the length register
            self.apply_g43({"H": vals[self.d.tool_length_word]}, b.lineno, b.col(vals[self.d.tool_length_word][1]))
        if self.d.fixture_offset_word and self.d.fixture_offset_word in vals:
            b.work_name = f"{self.d.fixture_offset_word}{int(vals[self.d.fixture_offset_word][0])}"
        if b.work_name is not None:
            st.work = b.work_name
            st.work_explicit = True
        if b.lookahead is not None:
            return True
        return self._offset_settings(b)

    def _motion(self, b: Block) -> Move | None:
        """The block's feed, then its move: the handler of its motion family in
        :data:`MOTIONS`, by the block's motion code, else by the modal motion mode (a modal
        cycle or spline only on a block with axis words)."""
        st, vals = self.state, b.vals
        if "F" in vals and not (self.d.dwell_f_is_time and any(k == 40 for k, _ in b.gcodes)):
            st.feed = vals["F"][0]
        if b.home_code is not None:
            return MOTIONS[b.home_code[0]](self, b)
        # Rotary axes: passed through, tracked for the engine's context.
        for a in ROTARY:
            if a in vals:
                v = vals[a][0]
                self.used_rotary.add(a)
                if st.incremental:
                    st.rotary[a] = st.rotary.get(a, 0.0) + v
                else:
                    st.rotary[a] = v + self.rotary_g92.get(a, 0.0)
                b.rotary_changed = True
        b.has_axes = any(a in vals for a in AXES)
        if b.cancel_cycle:
            if st.motion in CANNED_CYCLES:
                st.motion = None if self.d.g80_clears_motion else st.before_cycle
            elif self.d.g80_clears_motion:
                st.motion = None
            st.cycle_r = st.cycle_z = st.cycle_q = st.cycle_p = None
        key = b.motion_key
        if key is None and (b.has_axes or st.motion not in _NEEDS_AXES):
            key = st.motion
        return MOTIONS.get(key, Interpreter.motion_line)(self, b)

    @staticmethod
    def _is_lookahead(key: int, vals: Vals) -> bool:
        """Fanuc/Haas look-ahead and smoothing codes (G5 P.., G5.1 Q.., G8 P.., G187, G103)."""
        if key in (1870, 1030):
            return True
        if any(a in vals for a in "XYZIJKR"):
            return False
        if key == 50:
            return "P" in vals and "Q" not in vals
        if key == 51:
            return "Q" in vals
        if key == 80:
            return "P" in vals
        return False


def _g_motion(it: Interpreter, b: Block, key: int, i: int) -> None:
    """G0-G3, canned cycles, splines: the block's motion code (one per block)."""
    if b.motion_key is not None:
        raise it.error(GcodeSyntaxError, "two motion codes in one block", b.lineno, b.col(i))
    b.motion_key, b.motion_idx = key, i
    it.motion_word = True


def _g_retract(it: Interpreter, b: Block, key: int, i: int) -> None:
    it.state.retract_r = key == 990


def _g_cancel_cycle(it: Interpreter, b: Block, key: int, i: int) -> None:
    b.cancel_cycle = True
    it.motion_word = True


def _g_refused(it: Interpreter, b: Block, key: int, i: int) -> None:
    cls = NeedsExpansion if (key in EXPANDABLE_G and it.may_expand) else UnsupportedGcodeError
    raise it.error(cls, REFUSED_G[key], b.lineno, b.col(i), hint=REFUSED_HINT.get(key))


def _g_lookahead_spline_or_refused(it: Interpreter, b: Block, key: int, i: int) -> None:
    """G5, G5.1, G8: Fanuc/Haas look-ahead codes with their P/Q alone, else splines (G5,
    G5.1) or refused (G8 lathe radius mode)."""
    if it._is_lookahead(key, b.vals):
        b.lookahead = key
    elif key in SPLINES:
        _g_motion(it, b, key, i)
    else:
        _g_refused(it, b, key, i)


def _g_lookahead(it: Interpreter, b: Block, key: int, i: int) -> None:
    b.lookahead = key


def _g_home(it: Interpreter, b: Block, key: int, i: int) -> None:
    b.home_code = (key, i)


def _g_home_store(it: Interpreter, b: Block, key: int, i: int) -> None:
    if any(a in b.vals for a in AXES):
        raise it.error(UnsupportedGcodeError, f"{b.gtext(i)} with axis words", b.lineno, b.col(i))
    it.home[HOME_STORE[key]] = list(it.state.pos)
    it.stored_here = HOME_STORE[key]
    it.program_stored.add(HOME_STORE[key])


def _g_local_offset(it: Interpreter, b: Block, key: int, i: int) -> None:
    b.g52 = True


def _g_plane(it: Interpreter, b: Block, key: int, i: int) -> None:
    it.state.plane = key
    b.prefix.append(b.gtext(i))


def _g_units(it: Interpreter, b: Block, key: int, i: int) -> None:
    it.state.inch = key == 200
    b.prefix.append(b.gtext(i))


def _g_distance(it: Interpreter, b: Block, key: int, i: int) -> None:
    it.state.incremental = key == 910
    b.prefix.append(b.gtext(i))


def _g_arc_distance(it: Interpreter, b: Block, key: int, i: int) -> None:
    it.state.arc_absolute = key == 901
    b.prefix.append(b.gtext(i))


def _g_feed_mode(it: Interpreter, b: Block, key: int, i: int) -> None:
    it.state.inverse_time = key == 930
    b.prefix.append(b.gtext(i))


def _g_work(it: Interpreter, b: Block, key: int, i: int) -> None:
    b.work_name = WORK_SYSTEMS[key]
    b.prefix.append(b.gtext(i))


def _g_work_extended(it: Interpreter, b: Block, key: int, i: int) -> None:
    vals = b.vals
    if "P" not in vals:
        raise it.error(GcodeSyntaxError, "G54.1 needs a P word", b.lineno, b.col(i))
    b.work_name = f"G54.1P{int(vals['P'][0])}"
    b.prefix.append(f"{b.gtext(i)} P{b.words[vals['P'][1]][1]}")


def _g_tool_length(it: Interpreter, b: Block, key: int, i: int) -> None:
    vals = b.vals
    b.prefix.append(b.gtext(i) + (f" H{b.words[vals['H'][1]][1]}" if "H" in vals else ""))
    it.apply_g43(vals, b.lineno, b.col(i))


def _g_tool_length_cancel(it: Interpreter, b: Block, key: int, i: int) -> None:
    it.state.tlo, it.state.tlo_active = 0.0, False
    b.prefix.append(b.gtext(i))


def _g_machine(it: Interpreter, b: Block, key: int, i: int) -> None:
    b.g53 = True
    b.prefix.append(b.gtext(i))


def _g_g92(it: Interpreter, b: Block, key: int, i: int) -> None:
    b.g92 = key


def _g_g10(it: Interpreter, b: Block, key: int, i: int) -> None:
    b.g10 = True


def _g_cutter(it: Interpreter, b: Block, key: int, i: int) -> None:
    """G40/G41/G42/G41.1/G42.1: read by :func:`postproc.gcode.cutter.check_block`."""
    b.comp = (key, i)


def _g_neutral(it: Interpreter, b: Block, key: int, i: int) -> None:
    """No geometry: dwell G4 (P is seconds), path control, spindle modes, ..."""


def _g_g50(it: Interpreter, b: Block, key: int, i: int) -> None:
    """G50: scaling cancel on a mill (no words of its own); a lathe's spindle speed clamp
    (G50 S) or coordinate setting (G50 X.. Z..)."""
    lathe = [k for k in "SXZUW" if k in b.vals]
    if lathe:
        raise it.lathe.refusal(f"G50 {lathe[0]}{b.words[b.vals[lathe[0]][1]].number} at line {b.lineno} "
                               "(a lathe's spindle speed clamp or coordinate setting)", it.path, b.lineno, b.col(i))


def _g_css(it: Interpreter, b: Block, key: int, i: int) -> None:
    """G96: constant surface speed, a lathe's (noted as a mark; neutral on its own)."""
    it.lathe.note(f"G96 (constant surface speed) at line {b.lineno}")


def _g_diameter_mode(it: Interpreter, b: Block, key: int, i: int) -> None:
    raise it.lathe.refusal(f"G7 (diameter mode) at line {b.lineno}", it.path, b.lineno, b.col(i))


def _g_g15(it: Interpreter, b: Block, key: int, i: int) -> None:
    """G15: polar coordinates off (Fanuc, neutral); G15 H<n> selects work coordinate
    system n where the dialect says so (Okuma)."""
    if it.d.g15_work_select:
        if "H" not in b.vals:
            raise it.error(GcodeSyntaxError, "G15 needs H (the work coordinate system number)", b.lineno, b.col(i))
        b.work_name = f"G15H{int(b.vals['H'][0])}"
        b.prefix.append(f"{b.gtext(i)} H{b.words[b.vals['H'][1]].number}")


#: motion mode (G code key), or G28/G30 -> the handler that makes the block's move, one per
#: motion family. A G code with geometry is its handler and its row here; its row of
#: _G_HANDLERS follows (G28/G30 set the block's home code, the others its motion code).
MOTIONS: dict[int | None, Callable[[Interpreter, Block], Move | None]] = {
    RAPID: Interpreter.motion_line, LINE: Interpreter.motion_line,
    ARC_CW: Interpreter.motion_arc, ARC_CCW: Interpreter.motion_arc,
    **dict.fromkeys(CANNED_CYCLES, Interpreter.motion_cycle),
    **dict.fromkeys(SPLINES, Interpreter.motion_spline),
    **dict.fromkeys(HOME_CODES, Interpreter.motion_home),
}
# motion modes whose modal blocks move only with an axis word (else read as a G0/G1 block's)
_NEEDS_AXES = CANNED_CYCLES | SPLINES

#: G code key (10 x number) -> handler(interpreter, block, key, word index)
_G_HANDLERS: dict = {}
for _keys, _handler in (
    (NEUTRAL_G | {40}, _g_neutral), (REFUSED_G, _g_refused), (CUTTER_COMP, _g_cutter),
    (MOTIONS.keys() - HOME_CODES.keys(), _g_motion), ({980, 990}, _g_retract), ({800}, _g_cancel_cycle),
    (LOOKAHEAD_G, _g_lookahead), ({50, 51, 80}, _g_lookahead_spline_or_refused),
    (HOME_CODES, _g_home), (HOME_STORE, _g_home_store), ({520}, _g_local_offset),
    (PLANES, _g_plane), ({200, 210}, _g_units), ({900, 910}, _g_distance), ({901, 911}, _g_arc_distance),
    ({930, 940, 950}, _g_feed_mode), (WORK_SYSTEMS, _g_work), ({541}, _g_work_extended),
    ({430}, _g_tool_length), ({490}, _g_tool_length_cancel), ({530}, _g_machine), ({920, 921, 922}, _g_g92),
    ({100}, _g_g10), ({500}, _g_g50), ({960}, _g_css), ({70}, _g_diameter_mode), ({150}, _g_g15),
):
    for _key in _keys:
        _G_HANDLERS[_key] = _handler


def plain_moves(mv: Move) -> Iterator[Move]:
    """The straight and arc moves a Move stands for, in order: a cycle block's rapids
    and feeds, a G28/G30 line's two legs, or the move itself."""
    if mv.cycle is not None:
        q0 = mv.q0
        for kind, q in mv.cycle.steps:
            if kind == DWELL:
                continue
            yield Move(mv.lineno, kind, q0, q, mv.r, mv.shift, mv.unit, mv.incremental, mv.arc_absolute, [],
                       (-1, -1, -1), -1, False, mv.feed, mv.rotary)
            q0 = q
        return
    if mv.spline is not None:
        s = spline_samples(mv.spline, SPLINE_SAMPLE_MM)[1:]
        xy = spline_points(mv.spline, s)
        q0 = mv.q0
        for x, y in xy.tolist():
            q = (x, y, mv.q1[2])
            yield Move(mv.lineno, LINE, q0, q, mv.r, mv.shift, mv.unit, mv.incremental, mv.arc_absolute, [],
                       (-1, -1, -1), -1, False, mv.feed, mv.rotary)
            q0 = q
        return
    leg: Move | None = mv
    while leg is not None:
        if not (leg.role is Role.AT and any(math.isnan(v) for v in leg.q1)):  # an unknown stored position
            yield leg
        leg = leg.then


