"""Offsets, tool lengths and stored positions: G52, G92, G10 L1/L2/L10/L11/L20, G43 and
G28/G30, as LinuxCNC reads them (see :mod:`postproc.gcode.interp`)."""

from __future__ import annotations

import math

from postproc.errors import GcodeSyntaxError, MissingSetupError, UnsupportedGcodeError
from postproc.gcode import lexer
from postproc.gcode.interp_core import AXES, ROTARY, Block, InterpreterCore, Vals, col_of_word
from postproc.gcode.moves import Move, Role
from postproc.gcode.state import HOME_CODES, NAN, P_SYSTEMS, RAPID


class OffsetsMixin(InterpreterCore):
    """Offsets, tool lengths and G28/G30 (mixed into :class:`~postproc.gcode.interp.Interpreter`)."""

    def set_tool_length(self, h: int, lineno: int, col: int) -> None:
        """What ``G43 H<h>`` does to the state, for the readers that take such a line as
        columns (as :meth:`_block` reads it)."""
        self.apply_g43({"H": (float(h), -1)}, lineno, col)
        self.run_shift = None

    def _offset_settings(self, b: Block) -> bool:
        """The block's G10, G52 or G92, with the offset each sets from where the machine is
        (:attr:`rebase`); True when it had one (the block moves nothing then)."""
        st, vals, words = self.state, b.vals, b.words
        if b.g10:
            before = tuple(st.pos)
            self._g10(vals, b.lineno, b.col(next(i for k, i in b.gcodes if k == 100)))
            L = int(vals["L"][0]) if "L" in vals else None
            named = [a for a in AXES if a in vals] if L == 20 else ["Z"] if L in (10, 11) and "Z" in vals else []
            if named:
                self.rebase = (words, [(vals[a][1], AXES.index(a)) for a in named], before)
            return True
        if b.g52:
            self._g52(vals, b.lineno, b.col(next(i for k, i in b.gcodes if k == 520)))
            return True
        if b.g92 is not None:
            before = tuple(st.pos)
            self._g92(b.g92, vals, b.lineno, b.col(next(i for k, i in b.gcodes if k in (920, 921, 922))))
            if b.g92 == 920 and any(a in vals for a in AXES):
                self.rebase = (words, [(vals[a][1], AXES.index(a)) for a in AXES if a in vals], before)
            return True
        return False

    def motion_home(self, b: Block) -> Move | None:
        """G28/G30, the home family of :data:`~postproc.gcode.interp.MOTIONS`."""
        home_code = b.home_code
        if home_code is None:  # pragma: no cover - MOTIONS calls this for a G28/G30 block
            raise AssertionError("a G28/G30 block without its code")
        return self._home(home_code, b.words, b.vals, b.lineno, b.col(home_code[1]))

    def _home(self, home_code: tuple[int, int], words: list[lexer.Word], vals: Vals, lineno: int,
              col: int) -> Move | None:
        """G28/G30: through the intermediate point (the axis words) to the stored position."""
        key, gi = home_code
        name = HOME_CODES[key]
        st = self.state
        if any(a in vals for a in ROTARY):
            raise self.error(UnsupportedGcodeError, f"{name} with rotary axis words", lineno, col,
                            hint="the stored rotary positions are not known to postproc; home the rotary "
                                 "axes on a line of their own before or after correcting")
        if any(k in vals for k in "IJKR"):
            raise self.error(GcodeSyntaxError, f"{name} with arc words", lineno, col)
        unit = st.unit_mm
        named = [k for k, a in enumerate(AXES) if a in vals]
        pos = st.pos
        q0 = (pos[0], pos[1], pos[2])
        inter = list(q0)
        axis_idx = [-1, -1, -1]
        shift = self.shift(False, lineno, col) if named and not st.incremental else (0.0, 0.0, 0.0)
        for k in named:
            v, i = vals[AXES[k]]
            axis_idx[k] = i
            if st.incremental:
                if v != 0.0 and math.isnan(inter[k]):
                    raise self.error(MissingSetupError, f"incremental {name} on {AXES[k]} from an unknown position",
                                    lineno, col_of_word(words, i),
                                    hint=f"give the machine position at program start with --start {AXES[k]}..")
                if v != 0.0:
                    inter[k] = inter[k] + v * unit
            else:
                inter[k] = v * unit + shift[k]
                self.unknown_after.pop(k, None)
        stored = self.home.get(name, [NAN, NAN, NAN])
        after = list(inter)
        for k in named or range(3):
            after[k] = stored[k]
            if math.isnan(stored[k]):
                self.unknown_after[k] = name
            else:
                self.unknown_after.pop(k, None)
        r = self.tool_r()
        rot = dict(st.rotary) if self.used_rotary else {}
        jump = Move(lineno, RAPID, (inter[0], inter[1], inter[2]), (after[0], after[1], after[2]), r,
                    (0.0, 0.0, 0.0), unit, st.incremental, st.arc_absolute, [], (-1, -1, -1), -1, False, st.feed, rot,
                    role=Role.AT, motion_idx=gi,
                    stored=(name, tuple(named or range(3))) if name in self.program_stored else None)
        st.pos = after
        moved = [k for k in named if inter[k] != q0[k] and not (math.isnan(inter[k]) and math.isnan(q0[k]))]
        if not moved:
            return jump
        self._check_known(inter, lineno, col)
        return Move(lineno, RAPID, q0, (inter[0], inter[1], inter[2]), r, shift, unit, st.incremental,
                    st.arc_absolute, words, (axis_idx[0], axis_idx[1], axis_idx[2]), -1, False, st.feed, rot,
                    role=Role.WHOLE, motion_idx=gi, then=jump)

    def _g52(self, vals: Vals, lineno: int, col: int) -> None:
        """G52 local offset: added to the work offset for the named axes (LinuxCNC keeps it with G92's)."""
        st = self.state
        if any(a in vals for a in ROTARY):
            raise self.error(UnsupportedGcodeError, "G52 on a rotary axis", lineno, col)
        for k, a in enumerate(AXES):
            if a in vals:
                st.g92[k] = vals[a][0] * st.unit_mm

    def apply_g43(self, vals: Vals, lineno: int, col: int) -> None:
        st = self.state
        h: int | None
        if "H" in vals:
            h = int(vals["H"][0])
        else:
            h = st.spindle_tool if st.spindle_tool is not None else st.tool
            if h is None:
                raise self.error(MissingSetupError, "G43 without H and no tool selected (T word)", lineno, col,
                                hint="add H<n> to the G43 block or select the tool with T<n> M6")
        if h == 0:
            st.tlo, st.tlo_active = 0.0, True
            return
        lengths = self.tool_lengths
        if self.lenient_setup and h not in lengths:
            st.tlo, st.tlo_active = 0.0, True
            return
        if h not in lengths:
            raise self.error(MissingSetupError, f"tool length of tool {h} is used (G43) but was not given",
                            lineno, col, hint=f"give it with --tool-length {h}=L (mm) or --tool-table FILE")
        st.tlo, st.tlo_active = float(lengths[h]), True

    def _g92(self, key: int, vals: Vals, lineno: int, col: int) -> None:
        st = self.state
        if key in (921, 922):
            st.g92 = [0.0, 0.0, 0.0]
            self.rotary_g92.clear()
            return
        for a in ROTARY:
            if a in vals:
                self.rotary_g92[a] = st.rotary.get(a, 0.0) - vals[a][0]
        if not any(a in vals for a in AXES):
            if any(a in vals for a in ROTARY):
                return
            raise self.error(GcodeSyntaxError, "G92 needs at least one axis word", lineno, col)
        unit = st.unit_mm
        for k, a in enumerate(AXES):
            if a in vals:
                if math.isnan(st.pos[k]):
                    raise self.error(MissingSetupError, f"G92 on {a} at an unknown position", lineno,
                                    col, hint="position the axis with a G90 move before G92, or give its machine "
                                 "position at program start with --start")
                st.g92[k] = 0.0
                w = self._work_offset(lineno, col)
                st.g92[k] = st.pos[k] - (w[k] + (st.tlo if k == 2 else 0.0)) - vals[a][0] * unit

    def _g10(self, vals: Vals, lineno: int, col: int) -> None:
        st = self.state
        L = int(vals["L"][0]) if "L" in vals else None
        if L in (1, 10, 11):
            self._g10_tool(L, vals, lineno, col)
            return
        if L not in (2, 20) or "R" in vals:
            raise self.error(UnsupportedGcodeError, "G10 other than L2/L20 work offset setting (or with R rotation)",
                            lineno, col)
        p = int(vals["P"][0]) if "P" in vals else 0
        name = st.work if p == 0 else P_SYSTEMS.get(p)
        if name is None:
            raise self.error(GcodeSyntaxError, f"G10 P{p}: no such coordinate system", lineno, col)
        current = None
        if name in self.program_offsets:
            current = list(self.program_offsets[name])
        elif name in self.offsets:
            current = list(self.offsets[name])
        unit = st.unit_mm
        new = list(current) if current else [NAN, NAN, NAN]
        for k, a in enumerate(AXES):
            if a in vals:
                v = vals[a][0] * unit
                if L == 2:
                    new[k] = v
                else:
                    if math.isnan(st.pos[k]):
                        raise self.error(MissingSetupError, f"G10 L20 on {a} at an unknown position", lineno, col)
                    new[k] = st.pos[k] - st.g92[k] - (st.tlo if k == 2 else 0.0) - v
        if any(math.isnan(v) for v in new):
            raise self.error(MissingSetupError, f"G10 sets only some axes of {name}, whose other values were not given",
                            lineno, col, hint=f"give --offset {name}=X..,Y..,Z..")
        self.program_offsets[name] = new

    def _g10_tool(self, L: int, vals: Vals, lineno: int, col: int) -> None:
        """G10 L1/L10/L11 P<tool> Z..: write a tool length (used by later G43)."""
        st = self.state
        if "P" not in vals:
            raise self.error(GcodeSyntaxError, f"G10 L{L} needs a P word (tool number)", lineno, col)
        tool = int(vals["P"][0])
        if "Z" not in vals:
            return  # X (lathe), R (radius), Q (orientation): no tool length written
        z = vals["Z"][0] * st.unit_mm
        if L == 1:
            self.tool_lengths[tool] = z
            return
        if math.isnan(st.pos[2]):
            raise self.error(MissingSetupError, f"G10 L{L} at an unknown Z position", lineno, col,
                            hint="position Z with an absolute move first, or give --start Z..")
        if L == 10:
            w = self._work_offset(lineno, col)
            self.tool_lengths[tool] = st.pos[2] - w[2] - st.g92[2] - z
        else:
            g593 = self.program_offsets.get("G59.3") or self.offsets.get("G59.3")
            if g593 is None:
                raise self.error(MissingSetupError, "G10 L11 uses the work offset G59.3, whose value was not given",
                                lineno, col, hint="give --offset G59.3=X..,Y..,Z..")
            self.tool_lengths[tool] = st.pos[2] - g593[2] - z
