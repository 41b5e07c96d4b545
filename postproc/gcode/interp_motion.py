"""Moves along a curve: arcs (G2/G3 with I/J/K or R, helical turns) and splines (G5,
G5.1), as LinuxCNC reads them unless the dialect says otherwise (see
:mod:`postproc.gcode.interp`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from postproc.errors import GcodeSyntaxError, MissingSetupError, UnsupportedGcodeError
from postproc.gcode import cutter, lexer
from postproc.gcode.geometry import r_center
from postproc.gcode.interp_core import AXES, MIN_ARC_RADIUS_MM, ROTARY, Block, InterpreterCore, Vals
from postproc.gcode.moves import Arc, Move, Role
from postproc.gcode.state import ARC_CCW, ARC_CW, LINE, MOTION_CODES, PLANES, RAPID
from postproc.limits import ResourceLimitError

if TYPE_CHECKING:
    import numpy.typing as npt

# chord error of the polyline the samplers use for a spline
SPLINE_SAMPLE_MM = 1e-4


def spline_points(ctrl: npt.ArrayLike, s: npt.ArrayLike) -> np.ndarray:
    """Points (k, 2) of a Bezier curve with control points ``ctrl`` at parameters ``s``."""
    s = np.asarray(s, dtype=float)[:, None]
    c = np.asarray(ctrl, dtype=float)
    if len(c) == 3:
        return (1 - s) ** 2 * c[0] + 2 * (1 - s) * s * c[1] + s ** 2 * c[2]
    return (1 - s) ** 3 * c[0] + 3 * (1 - s) ** 2 * s * c[1] + 3 * (1 - s) * s ** 2 * c[2] + s ** 3 * c[3]


def spline_samples(ctrl: npt.ArrayLike, chord_mm: float) -> np.ndarray:
    """Parameters along a spline whose chords stay within ``chord_mm`` of it (from the
    bound on the second derivative: error <= max|B''| h^2 / 8)."""
    c = np.asarray(ctrl, dtype=float)
    if len(c) == 3:
        bound = 2.0 * np.linalg.norm(c[0] - 2 * c[1] + c[2])
    else:
        bound = 6.0 * max(np.linalg.norm(c[0] - 2 * c[1] + c[2]), np.linalg.norm(c[1] - 2 * c[2] + c[3]))
    n = max(1, math.ceil(math.sqrt(bound / (8.0 * chord_mm)))) if bound > 0 else 1
    return np.linspace(0.0, 1.0, n + 1)


@dataclass(slots=True)
class _Target:
    """Where a straight or arc block goes: from ``q0`` to ``q1`` (machine mm) under ``shift``."""

    kind: int  # the motion mode
    q0: tuple[float, float, float]
    q1: list[float]  # (the state's position once the move is made)
    shift: tuple[float, float, float]
    axis_idx: tuple[int, int, int]  # the word of each axis, -1 if none
    incremental: bool  # the block's distance mode (G53 positions are absolute in G91 too)
    col: int  # the column of its first axis word


class MotionMixin(InterpreterCore):
    """Straight moves, arcs and splines: three motion families of
    :data:`~postproc.gcode.interp.MOTIONS` (mixed into :class:`~postproc.gcode.interp.Interpreter`)."""

    def motion_line(self, b: Block) -> Move | None:
        """G0 and G1, the straight family of :data:`~postproc.gcode.interp.MOTIONS` (also a
        block of rotary words alone in another mode, or of axis words in none)."""
        st, vals = self.state, b.vals
        if b.motion_key is not None:
            st.motion = MOTION_CODES[b.motion_key]
        if not b.has_axes and not b.rotary_changed:
            return None
        t = self._target(b, full_circle=False)
        if any(k in vals for k in "IJK") or ("R" in vals and st.motion in (RAPID, 10)):
            letter = next(k for k in "IJKR" if k in vals)
            raise self.error(GcodeSyntaxError, f"{letter} word on a straight move", b.lineno, b.col(vals[letter][1]))
        return self._move(b, t, None)

    def motion_arc(self, b: Block) -> Move | None:
        """G2 and G3, the arc family of :data:`~postproc.gcode.interp.MOTIONS`; a block with
        centre words alone is a full circle where the dialect reads one."""
        st, vals = self.state, b.vals
        motion_key = b.motion_key
        if motion_key is not None:
            st.motion = MOTION_CODES[motion_key]
        full_circle = False
        if not b.has_axes:
            arc_words = [vals[k][1] for k in "IJKR" if k in vals]
            if motion_key in (ARC_CW, ARC_CCW) or (arc_words and st.motion in (ARC_CW, ARC_CCW)):
                i = arc_words[0] if arc_words else next(i for k, i in b.gcodes if k == motion_key)
                _, (l1, l2) = PLANES[st.plane]
                if not self.d.full_circle_without_end or "R" in vals or not (l1 in vals or l2 in vals):
                    raise self.error(GcodeSyntaxError, "arc without end point words", b.lineno, b.col(i),
                                    hint="a full circle needs its centre offsets (I/J/K)"
                                    + ("" if self.d.full_circle_without_end else
                                       f" and {self.d.title.split()[0]} needs an end point"))
                full_circle = True  # a full circle back to the start (LinuxCNC, Fanuc)
            elif not b.rotary_changed:
                return None
        t = self._target(b, full_circle)
        return self._move(b, t, self._arc(b, t))

    def motion_spline(self, b: Block) -> Move:
        """G5 and G5.1, the spline family of :data:`~postproc.gcode.interp.MOTIONS`."""
        if b.motion_key is not None:
            self.state.motion = b.motion_key
        return self._spline(b.lineno, b.words, b.vals, b.motion_idx, b.prefix_words())

    def _target(self, b: Block, full_circle: bool) -> _Target:
        """Where a straight or arc block goes (machine mm), each axis word checked."""
        st, vals, lineno = self.state, b.vals, b.lineno
        if full_circle:
            first_axis_col = b.col(min(vals[k][1] for k in "IJK" if k in vals))
        else:
            first_axis_col = b.col(min(vals[a][1] for a in AXES + ROTARY if a in vals))
        kind = st.motion
        if kind is None:
            raise self.error(GcodeSyntaxError, "axis words with no motion mode (G0/G1/G2/G3) active",
                            lineno, first_axis_col)
        if b.g53 and kind not in (RAPID, LINE):
            raise self.error(GcodeSyntaxError, "G53 needs G0 or G1", lineno, first_axis_col)
        incremental = st.incremental
        if b.g53 and incremental:
            if not self.d.g53_absolute_in_g91:
                raise self.error(GcodeSyntaxError, "G53 is not allowed in G91 (incremental) mode", lineno,
                                first_axis_col, hint="LinuxCNC rejects it; Fanuc and Haas take G53 words as "
                                                     "machine positions in G91 too (--dialect fanuc|haas)")
            incremental = False  # Fanuc, Haas: G53 positions are absolute whatever the mode

        shift = self.shift(b.g53, lineno, first_axis_col)
        unit = st.unit_mm
        pos = st.pos
        q0 = (pos[0], pos[1], pos[2])
        q1 = list(q0)
        axis_idx = [-1, -1, -1]
        for k, a in enumerate(AXES):
            if a in vals:
                v, i = vals[a]
                axis_idx[k] = i
                if incremental:
                    if math.isnan(q1[k]):
                        raise self.error(
                            MissingSetupError,
                            f"incremental move on {a} from an unknown position (no absolute move on {a} before)",
                            lineno, b.col(i),
                            hint="position every axis with a G90 move before the first G91 move, or give its "
                                 "machine position at program start with --start")
                    q1[k] = q1[k] + v * unit
                else:
                    q1[k] = v * unit + shift[k]
                    self.unknown_after.pop(k, None)
        if self.unknown_after:
            self._check_known(q1, lineno, first_axis_col)
        if b.block_delete and st.incremental:
            raise self.error(UnsupportedGcodeError, "block-delete '/' on an incremental move", lineno, 1,
                            hint="the result would depend on the block-delete switch")
        return _Target(kind, q0, q1, shift, (axis_idx[0], axis_idx[1], axis_idx[2]), incremental, first_axis_col)

    def _move(self, b: Block, t: _Target, arc: Arc | None) -> Move:
        """The Move of a straight or arc block; the state moved to its end."""
        st, vals = self.state, b.vals
        if st.inverse_time and st.motion != RAPID and "F" not in vals:
            raise self.error(GcodeSyntaxError, "G93 inverse-time feed needs an F word on every feed move",
                            b.lineno, t.col)
        q1 = t.q1
        st.pos = q1
        move = Move(
            lineno=b.lineno, kind=t.kind, q0=t.q0, q1=(q1[0], q1[1], q1[2]), r=self.tool_r(), shift=t.shift,
            unit=st.unit_mm, incremental=t.incremental, arc_absolute=st.arc_absolute, words=b.words,
            axis_idx=t.axis_idx, feed_idx=vals["F"][1] if "F" in vals else -1,
            inverse_time=st.inverse_time, feed=st.feed,
            rotary=dict(st.rotary) if self.used_rotary else {}, arc=arc,
            prefix_words=b.prefix_words(), event_idx=tuple(b.event_idx),
            role=Role.WHOLE if b.tool_change or b.g53 else Role.MOVE,
            motion_idx=b.motion_idx,
            aux_idx=tuple(vals[k][1] for k in "IJKRP" if k in vals) if arc is not None else (),
        )
        if st.comp != 400 or st.comp_edge:
            cutter.on_move(self, move)
        return move

    def _spline(self, lineno: int, words: list[lexer.Word], vals: Vals, motion_idx: int, prefix: list[str]) -> Move:
        """G5 (cubic) and G5.1 (quadratic) splines in G17, as LinuxCNC reads them: G5's I/J
        offset the first control point from the start (the previous P/Q mirrored when
        left out), P/Q the second from the end; G5.1's I/J offset its control point."""
        st = self.state
        key = st.motion
        name = "G5" if key == 50 else "G5.1"
        col = words[motion_idx].letter_pos + 1 if motion_idx >= 0 else words[0].letter_pos + 1
        if st.plane != 170:
            raise self.error(GcodeSyntaxError, f"{name} spline outside the G17 plane", lineno, col)
        other = [a for a in "ZABCKR" if a in vals]
        if other:
            raise self.error(GcodeSyntaxError, f"{name} spline with a {other[0]} word (X and Y only)", lineno,
                            words[vals[other[0]][1]][4] + 1)
        if st.inverse_time:
            raise self.error(UnsupportedGcodeError, f"{name} spline in G93 inverse-time mode", lineno, col)
        if any(math.isnan(v) for v in st.pos):
            raise self.error(MissingSetupError, f"{name} spline from an unknown position", lineno, col,
                            hint="position every axis with a G90 move before the spline, or give --start")
        if ("I" in vals) != ("J" in vals):
            raise self.error(GcodeSyntaxError, f"{name} needs both I and J, or neither", lineno, col)
        unit = st.unit_mm
        if "F" in vals:
            st.feed = vals["F"][0]
        shift = self.shift(False, lineno, col)
        pos = st.pos
        q0 = (pos[0], pos[1], pos[2])
        q1 = list(q0)
        axis_idx = [-1, -1, -1]
        for k, a in enumerate("XY"):
            if a in vals:
                v, i = vals[a]
                axis_idx[k] = i
                q1[k] = q1[k] + v * unit if st.incremental else v * unit + shift[k]
        p0 = (q0[0], q0[1])
        p3 = (q1[0], q1[1])
        if key == 50:
            if "P" not in vals or "Q" not in vals:
                raise self.error(GcodeSyntaxError, "G5 needs both P and Q", lineno, col)
            if "I" in vals:
                ij = (vals["I"][0] * unit, vals["J"][0] * unit)
            elif self._last_pq is not None:
                ij = (-self._last_pq[0], -self._last_pq[1])
            else:
                raise self.error(GcodeSyntaxError, "the first G5 of a series needs I and J", lineno, col)
            pq = (vals["P"][0] * unit, vals["Q"][0] * unit)
            self._last_pq = pq
            ctrl = [p0, (p0[0] + ij[0], p0[1] + ij[1]), (p3[0] + pq[0], p3[1] + pq[1]), p3]
        else:
            if "I" not in vals or (vals["I"][0] == 0 and vals["J"][0] == 0):
                raise self.error(GcodeSyntaxError, "G5.1 needs I and J, not both zero", lineno, col)
            ctrl = [p0, (p0[0] + vals["I"][0] * unit, p0[1] + vals["J"][0] * unit), p3]
        st.pos = q1
        return Move(lineno=lineno, kind=LINE, q0=q0, q1=(q1[0], q1[1], q1[2]), r=self.tool_r(), shift=shift,
                    unit=unit, incremental=st.incremental, arc_absolute=st.arc_absolute, words=words,
                    axis_idx=(axis_idx[0], axis_idx[1], axis_idx[2]),
                    feed_idx=vals["F"][1] if "F" in vals else -1, inverse_time=False, feed=st.feed,
                    rotary=dict(st.rotary) if self.used_rotary else {}, prefix_words=prefix, role=Role.SPLINE,
                    motion_idx=motion_idx, spline=ctrl)

    def _lathe_arc(self, vals: Vals, q0: tuple[float, float, float], lineno: int, col: int) -> None:
        """Refuse a lathe's arc: X and Z with I/K in G17, in a program that never positions Y."""
        if self.state.plane == 170 and "K" in vals and "J" not in vals and "Y" not in vals and math.isnan(q0[1]):
            raise self.lathe.refusal(f"an arc in X and Z with I/K centre words at line {lineno} in a program "
                                     "that never positions Y (a lathe reads G18 by default, X as a diameter)",
                                     self.path, lineno, col)

    def _turns(self, vals: Vals, words: list[lexer.Word], lineno: int) -> int:
        """The turns of an arc's P word: a positive integer, at most ``max_arc_turns``."""
        p = vals["P"][0]
        p_col = words[vals["P"][1]][4] + 1
        if not (math.isfinite(p) and p >= 1 and p == math.floor(p)):
            raise self.error(GcodeSyntaxError, "arc P (turns) must be a positive integer", lineno, p_col)
        if p > self.max_arc_turns:
            raise self.error(ResourceLimitError, f"arc of {p:.0f} turns: more than {self.max_arc_turns:,} "
                            "(--max-arc-turns)", lineno, p_col,
                            hint="raise --max-arc-turns if the helix is meant to turn this often")
        return int(p)

    def _arc(self, b: Block, t: _Target) -> Arc:
        """The arc of a G2/G3 block from ``t.q0`` to ``t.q1``: its centre from R or from
        the centre words of its plane, its turns from P."""
        st, words, vals, lineno = self.state, b.words, b.vals, b.lineno
        q0, q1 = t.q0, t.q1
        (a1, a2, an), (l1, l2) = PLANES[st.plane]
        named = [vals[a][1] for a in AXES + "IJKR" if a in vals]
        if not named:  # an arc mode block of rotary words only (rs274: "R, I, J, K words all missing for arc")
            first = next((w for w in words if w.letter != "N"), words[0])
            raise self.error(GcodeSyntaxError, "arc without centre (I/J/K) or radius (R)", lineno, first.letter_pos + 1,
                            hint="give the arc's end and centre words, or a G0/G1 before a move of rotary axes only")
        col = words[min(named)][4] + 1
        self._lathe_arc(vals, q0, lineno, col)
        if math.isnan(q0[a1]) or math.isnan(q0[a2]) or (math.isnan(q0[an]) and not math.isnan(q1[an])):
            raise self.error(MissingSetupError, "arc from an unknown start position", lineno, col,
                            hint="position all axes with a G90 move before the first arc, or give their "
                                 "machine positions at program start with --start")
        turns = self._turns(vals, words, lineno) if "P" in vals else 1
        clockwise = st.motion == ARC_CW
        s, e = (q0[a1], q0[a2]), (q1[a1], q1[a2])
        wrong = [k for k in "IJK" if k in vals and k not in (l1, l2)]
        off_plane, centre_form = self.d.off_plane_arc_offset, "R" not in vals
        if wrong and (off_plane == "ignored" or (off_plane == "ignored-beside-centre" and centre_form)):
            wrong = []  # these controllers ignore an offset word off the arc's plane
        elif (wrong and off_plane == "zero-ignored" and centre_form
              and all(vals[k][0] == 0 for k in wrong)):
            wrong = []  # a zero offset off the plane (K0 on a G17 arc) means nothing
        if wrong:
            raise self.error(GcodeSyntaxError, f"{wrong[0]} word is not an arc offset in this plane", lineno,
                            words[vals[wrong[0]][1]][4] + 1,
                            hint="LinuxCNC rejects it, and Grbl beside R (Grbl ignores it beside I/J/K "
                                 "centre words; Fanuc, Haas and Mach3 ignore it: choose that --dialect if "
                                 "the program is for one of them)")
        if "R" in vals:
            if l1 in vals or l2 in vals:
                raise self.error(GcodeSyntaxError, "arc with both R and centre offsets", lineno, col)
            c1, c2 = self._r_centre(b, col, s, e)
            idx = (-1, -1)
            r_idx = vals["R"][1]
        else:
            if l1 not in vals and l2 not in vals:
                raise self.error(GcodeSyntaxError, "arc without centre (I/J/K) or radius (R)", lineno, col)
            c1, c2 = self._offset_centre(b, col, (s, e), (t.shift[a1], t.shift[a2]))
            idx = (vals[l1][1] if l1 in vals else -1, vals[l2][1] if l2 in vals else -1)
            r_idx = -1
        center = [0.0, 0.0, 0.0]
        center[a1], center[a2], center[an] = c1, c2, q0[an]
        return Arc((center[0], center[1], center[2]), st.plane, clockwise, turns, idx, r_idx)

    def _r_centre(self, b: Block, col: int, s: tuple[float, float], e: tuple[float, float]) -> tuple[float, float]:
        """The centre (in the plane's axes) of an R arc from ``s`` to ``e``: a negative R
        takes the longer way round."""
        st, words, vals, lineno = self.state, b.words, b.vals, b.lineno
        unit = st.unit_mm
        clockwise = st.motion == ARC_CW
        s1, s2 = s
        e1, e2 = e
        R = vals["R"][0] * unit
        if math.hypot(e1 - s1, e2 - s2) < MIN_ARC_RADIUS_MM:
            raise self.error(GcodeSyntaxError, "R arc with start = end (a full circle needs I/J/K)", lineno, col)
        c = r_center(s1, s2, e1, e2, R, clockwise)
        if c is None:
            raise self.error(GcodeSyntaxError, f"arc radius R {abs(R) / unit:g} is smaller than half the chord",
                            lineno, words[vals["R"][1]][4] + 1)
        return c

    def _offset_centre(self, b: Block, col: int, se: tuple[tuple[float, float], tuple[float, float]],
                       shift: tuple[float, float]) -> tuple[float, float]:
        """The centre (in the plane's axes) of an arc from its centre words (offsets from
        the start, or work positions in G90.1), the end checked on its circle by the rule
        of the dialect's controller."""
        st, vals, lineno = self.state, b.vals, b.lineno
        unit = st.unit_mm
        l1, l2 = PLANES[st.plane][1]
        (s1, s2), (e1, e2) = se
        o1 = vals[l1][0] * unit if l1 in vals else 0.0
        o2 = vals[l2][0] * unit if l2 in vals else 0.0
        if st.arc_absolute:
            c1 = (vals[l1][0] * unit + shift[0]) if l1 in vals else s1
            c2 = (vals[l2][0] * unit + shift[1]) if l2 in vals else s2
        else:
            c1, c2 = s1 + o1, s2 + o2
        rs = math.hypot(s1 - c1, s2 - c2)
        re_ = math.hypot(e1 - c1, e2 - c2)
        if rs < MIN_ARC_RADIUS_MM:
            raise self.error(GcodeSyntaxError, "arc of zero radius", lineno, col)
        ctrl = self.arc_dialect()
        if not ctrl.arc_end_radius_ok(rs, re_, unit):
            raise self.error(GcodeSyntaxError,
                            f"arc end radius differs from start radius by {abs(rs - re_):.4f} mm, more than "
                            f"{ctrl.title} accepts", lineno, col,
                            hint="the end point is not on the arc's circle, so the controller refuses the arc; "
                                 "post the arc with more decimals (or choose the --dialect of the controller "
                                 "the program is for)")
        return c1, c2
