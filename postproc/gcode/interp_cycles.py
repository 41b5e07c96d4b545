"""Canned drilling cycles: G73, G81-G89 blocks (as LinuxCNC reads them, or the dialect
says otherwise) and the Sinumerik CYCLE81/82/89 calls, each into the holes it drills and
the moves the controller makes (see :mod:`postproc.gcode.interp`)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from postproc.errors import GcodeSyntaxError, MissingSetupError, UnsupportedGcodeError
from postproc.gcode.interp_core import AXES, ROTARY, Block, InterpreterCore
from postproc.gcode.moves import Cycle, Move, Role
from postproc.gcode.state import CANNED_CYCLES, DWELL, LINE, NAN, RAPID

# G83's rapid back down to this far above the last depth, and G73's retract: 0.010 inch
# (LinuxCNC G83_RAPID_DELTA)
PECK_CLEARANCE_MM = 0.254


class CyclesMixin(InterpreterCore):
    """Canned cycles (mixed into :class:`~postproc.gcode.interp.Interpreter`)."""

    def _drill_if_due(self, lineno: int, first_col: int = 1) -> None:
        """Run the Sinumerik drilling cycle this block calls (one-shot, or modal after a
        block that moves): its moves become :attr:`cycle_move`. ``first_col``: the column of
        the block's first word, where the refusals of a modal call run after it point (the
        call's own column is on another line)."""
        call, self._cycle_due = self._cycle_due, None
        if call is None:
            return
        from postproc.gcode.sinumerik_cycles import FEED_STEP, RAPID_STEP, drill_plan

        st = self.state
        col = call.col if self.call_line else first_col
        if st.plane != 170:
            raise self.error(UnsupportedGcodeError, f"Sinumerik {call.name} in a plane other than G17", lineno, col)
        if any(math.isnan(v) for v in st.pos):
            raise self.error(MissingSetupError, f"Sinumerik {call.name} from an unknown position", lineno, col,
                            hint="position every axis with a G90 move before the cycle, or give --start")
        plan = drill_plan(call, self.path, lineno, st.feed, st.unit_mm, col)
        unit, shift = st.unit_mm, self.shift(False, lineno, col)
        x, y, z0 = st.pos

        def at(v: object) -> tuple[float, float, float]:
            dx, dy, z = v if isinstance(v, tuple) else (0.0, 0.0, v)  # a level, or (dx, dy, z) off the hole
            return (x + dx * unit, y + dy * unit, z * unit + shift[2])

        kinds = {RAPID_STEP: RAPID, FEED_STEP: LINE}
        steps: list[tuple[int, tuple]] = []
        for kind, v in plan.steps:  # a dwell's seconds, or a line written as it is (str), as DWELL
            steps.append((DWELL, (v, 0.0, 0.0)) if kind not in kinds else (kinds[kind], at(v)))
        bottom, start = at(plan.bottom_z), at(plan.start_z)
        st.pos = list(at(plan.clear_z))
        self.cycle_move = Move(
            lineno=lineno, kind=plan.code, q0=(x, y, z0), q1=bottom, r=self.tool_r(), shift=shift, unit=unit,
            incremental=st.incremental, arc_absolute=st.arc_absolute, words=[], axis_idx=(-1, -1, -1),
            feed_idx=-1, inverse_time=False, feed=st.feed, rotary=dict(st.rotary) if self.used_rotary else {},
            role=Role.CYCLE, cycle=Cycle(plan.code, [(bottom, start)], st.pos[2], steps, -1, start[2], bottom[2], 1,
                                    False, plan.dwell_s))

    def motion_cycle(self, b: Block) -> Move:
        """G73, G81-G89, the canned-cycle family of :data:`~postproc.gcode.interp.MOTIONS`:
        the cycle's modal words kept or forgotten, then its moves (:meth:`_cycle`)."""
        st, motion_key = self.state, b.motion_key
        if motion_key is not None and st.motion not in CANNED_CYCLES:
            st.before_cycle = st.motion
        if motion_key is not None and motion_key != st.motion and (
                not self.d.cycle_keeps_rz or st.motion not in CANNED_CYCLES):
            # LinuxCNC wants R and Z again when the motion mode changes; Fanuc and Haas
            # keep them from one cycle to the next (until G80 or another motion)
            st.cycle_r = st.cycle_z = None
        if motion_key is not None:
            st.motion = motion_key
        return self._cycle(b)

    def _cycle(self, b: Block) -> Move:
        """A canned-cycle block: the holes it drills and the moves the controller makes.

        Follows LinuxCNC (interp_cycles.cc, checked against rs274): an initial rapid to
        R when Z is below it; per hole a rapid in X/Y at the current level, a rapid to
        R, the cycle's own moves, and a retract to R (G99) or to the higher of R and the
        level at the block's start (G98). In G91, R is relative to the current Z and Z
        to R; X/Y move by their increments for each of the L repeats. Pecks: G83 rapid
        back to R and down to 0.254 mm (0.010 in) above the last depth, G73 retract 0.254 mm.
        """
        st, words, vals, lineno, motion_idx = self.state, b.words, b.vals, b.lineno, b.motion_idx
        key = st.motion
        if key is None:  # pragma: no cover - motion_cycle sets a canned-cycle motion mode
            raise AssertionError("a canned-cycle block without its cycle")
        col = words[motion_idx].letter_pos + 1 if motion_idx >= 0 else words[min(vals[a][1] for a in AXES if a in vals)].letter_pos + 1
        name = f"G{key / 10:g}"
        if st.plane != 170:
            raise self.error(UnsupportedGcodeError, f"canned cycle {name} in a plane other than G17", lineno, col)
        if st.inverse_time:
            raise self.error(UnsupportedGcodeError, f"canned cycle {name} in G93 inverse-time mode", lineno, col)
        if any(a in vals for a in ROTARY) or any(k in vals for k in "IJ"):
            raise self.error(UnsupportedGcodeError, f"canned cycle {name} with rotary axis or I/J words",
                            lineno, col)
        unit = st.unit_mm
        r_word, z_word, peck_mm, repeats = self._cycle_words(b, name, col)
        if any(math.isnan(v) for v in st.pos):
            raise self.error(MissingSetupError, f"canned cycle {name} from an unknown position", lineno, col,
                            hint="position every axis with a G90 move before the cycle, or give --start")
        if self.unknown_after:
            self._check_known([NAN, NAN, NAN], lineno, col)
        shift = self.shift(False, lineno, col)
        x0, y0, z0 = st.pos
        if st.incremental:
            r_m = z0 + r_word * unit
            z_m = r_m + z_word * unit
            xy = (vals["X"][0] * unit if "X" in vals else 0.0, vals["Y"][0] * unit if "Y" in vals else 0.0)
        else:
            r_m = r_word * unit + shift[2]
            z_m = z_word * unit + shift[2]
            xy = (vals["X"][0] * unit + shift[0] if "X" in vals else x0, vals["Y"][0] * unit + shift[1] if "Y" in vals else y0)
        if z_m > r_m:
            raise self.error(GcodeSyntaxError, f"canned cycle {name} with its Z depth above its R plane",
                            lineno, col)
        clear = r_m if st.retract_r else max(z0, r_m)
        d = _Drilling(key, (x0, y0, z0), xy, st.incremental, r_m, z_m, clear, peck_mm, repeats, st.cycle_p)
        steps, holes, cur = _drill(d)
        axis_idx = (vals["X"][1] if "X" in vals else -1, vals["Y"][1] if "Y" in vals else -1,
                    vals["Z"][1] if "Z" in vals else -1)
        q0 = (x0, y0, z0)
        st.pos = list(cur)
        return Move(
            lineno=lineno, kind=key, q0=q0, q1=holes[0][0] if holes else q0, r=self.tool_r(), shift=shift,
            unit=unit, incremental=st.incremental, arc_absolute=st.arc_absolute, words=words,
            axis_idx=axis_idx, feed_idx=vals["F"][1] if "F" in vals else -1, inverse_time=False, feed=st.feed,
            rotary=dict(st.rotary) if self.used_rotary else {}, prefix_words=b.prefix_words(), role=Role.CYCLE,
            motion_idx=motion_idx, cycle=Cycle(key, holes, clear, steps, vals["R"][1] if "R" in vals else -1,
                                               r_m, z_m, repeats, st.retract_r, st.cycle_p))

    def _cycle_words(self, b: Block, name: str, col: int) -> tuple[float, float, float, int]:
        """The cycle's modal R, Z, Q, P words and its feed, kept in the state and checked:
        its R and Z (program units), peck depth (mm, G73/G83) and repeats (L, or the
        dialect's word)."""
        st, words, vals, lineno = self.state, b.words, b.vals, b.lineno
        key = st.motion
        unit = st.unit_mm
        if "R" in vals:
            st.cycle_r = vals["R"][0]
        if st.cycle_r is None and self.d.cycle_r_default_initial and not math.isnan(st.pos[2]):
            # Fanuc and Haas: R is optional; without it the R plane is the initial level
            if st.incremental:
                st.cycle_r = 0.0
            else:
                st.cycle_r = (st.pos[2] - self.shift(False, lineno, col)[2]) / unit
        if st.cycle_r is None:
            raise self.error(GcodeSyntaxError, f"canned cycle {name} without its R plane", lineno, col)
        if "Z" in vals:
            st.cycle_z = vals["Z"][0]
        if st.cycle_z is None:
            raise self.error(GcodeSyntaxError, f"canned cycle {name} without its Z depth", lineno, col)
        peck_mm = 0.0  # G73/G83 peck depth
        if key in (730, 830):
            if "Q" in vals:
                st.cycle_q = vals["Q"][0]
            if st.cycle_q is None or st.cycle_q <= 0:
                raise self.error(GcodeSyntaxError, f"canned cycle {name} needs a positive Q (peck depth)",
                                lineno, col)
            peck_mm = st.cycle_q * unit
        if "P" in vals:
            st.cycle_p = vals["P"][0]
        if "F" in vals:
            st.feed = vals["F"][0]
        repeat_letter = next((c for c in self.d.cycle_repeat_words if c in vals), "L")
        repeats = 1
        if repeat_letter in vals:
            given = vals[repeat_letter][0]
            if given != int(given) or given < 0:
                raise self.error(GcodeSyntaxError, f"{repeat_letter} (repeats) must be a whole number",
                                lineno, words[vals[repeat_letter][1]][4] + 1)
            repeats = int(given)
        return st.cycle_r, st.cycle_z, peck_mm, repeats


@dataclass(slots=True)
class _Drilling:
    """What a canned-cycle block drills, machine mm: from ``start``, ``repeats`` holes at
    ``xy`` (in G91: each ``xy`` from the last), from the R plane ``r`` down to ``z``."""

    key: int  # the cycle (G81: 810)
    start: tuple[float, float, float]
    xy: tuple[float, float]
    incremental: bool
    r: float
    z: float
    clear: float  # the level of the retract after each hole
    peck: float  # G73/G83 peck depth (0: none)
    repeats: int
    dwell: float | None  # P (G82, G89)


def _drill(d: _Drilling) -> tuple[list[tuple[int, tuple]], list[tuple[tuple[float, float, float],
                                                                      tuple[float, float, float]]], list[float]]:
    """The steps of a canned cycle, (bottom, R-plane point) of each hole, and where it ends."""
    key, r_m, z_m, clear = d.key, d.r, d.z, d.clear
    x0, y0, z0 = d.start
    steps: list[tuple[int, tuple]] = []
    cur = [x0, y0, z0]

    def go(kind: int, x: float, y: float, z: float) -> None:
        if (x, y, z) != tuple(cur):
            steps.append((kind, (x, y, z)))
            cur[:] = (x, y, z)

    holes: list[tuple[tuple[float, float, float], tuple[float, float, float]]] = []
    if z0 < r_m:
        go(RAPID, x0, y0, r_m)
    for _ in range(d.repeats):
        x, y = (cur[0] + d.xy[0], cur[1] + d.xy[1]) if d.incremental else d.xy
        go(RAPID, x, y, cur[2])
        go(RAPID, x, y, r_m)
        if key in (730, 830):
            q = d.peck
            depth = r_m - q
            while depth > z_m:
                go(LINE, x, y, depth)
                if key == 830:
                    go(RAPID, x, y, r_m)
                go(RAPID, x, y, depth + PECK_CLEARANCE_MM)
                depth -= q
        go(LINE, x, y, z_m)
        if key in (820, 890) and d.dwell:
            steps.append((DWELL, (d.dwell, 0.0, 0.0)))
        if key in (840, 850, 890):
            go(LINE, x, y, r_m)
        go(RAPID, x, y, clear)
        holes.append(((x, y, z_m), (x, y, r_m)))
    return steps, holes, cur
