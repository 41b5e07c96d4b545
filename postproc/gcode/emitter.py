"""Emitting corrected lines: splicing numbers, inserted lines, kept and linearised arcs.

A mixin of :class:`postproc.gcode.pipeline.Corrector`: it uses the corrector's
emitted position ``qe``, options, report and engine-call helpers.
"""

from __future__ import annotations

import math

import numpy as np

from postproc.constants import MM_PER_INCH
from postproc.errors import PostprocError
from postproc.gcode import emit
from postproc.gcode.fastlane import FastMove, emit_fast
from postproc.gcode.geometry import arc_chord_steps, arc_params
from postproc.gcode.interp import Arc, Move
from postproc.gcode.segment import arc_deviation, centre_estimate, r_center
from postproc.gcode.state import ARC_CCW, ARC_CW, LINE, PLANES, RAPID

MOTION_TEXT = {RAPID: "0", LINE: "1", ARC_CW: "2", ARC_CCW: "3"}
HALF_UNIT = emit.HALF_UNIT


def _mismatch(mv: Move) -> float:
    """End radius minus start radius of the input arc (mm)."""
    _, _, _, r0, r1 = arc_params(mv.arc, mv.q0, mv.q1)
    return abs(r1 - r0)


def _unit_decimals(options, unit: float) -> int:
    if options.decimals is not None:
        return options.decimals
    return 5 if unit == MM_PER_INCH else 4


class EmitterMixin:
    """Line emission for the corrector (see the module docstring)."""

    def _axis_words(self, mv: Move, target, qe: list[float], d: int, present_only: bool = False):
        """Edits for the axis words of ``mv``'s line and the words to add; updates qe."""
        edits, added = [], []
        unit, shift, inc = mv.unit, mv.shift, mv.incremental
        half = HALF_UNIT[d]
        fmt = emit.fmt
        for k in range(3):
            t = target[k]
            idx = mv.axis_idx[k]
            if idx >= 0:
                _letter, num, start, end, _lpos = mv.words[idx]
                ov = float(num)
                v = (t - qe[k]) / unit if inc else (t - shift[k]) / unit
                dot = num.find(".")
                dout = d if dot < 0 or len(num) - dot - 1 <= d else len(num) - dot - 1
                if abs(v - ov) < HALF_UNIT[dout]:
                    val = ov
                else:
                    text = fmt(v, dout)
                    edits.append((start, end, text))
                    val = round(v, dout)  # == float(text): both correctly rounded
                qe[k] = qe[k] + val * unit if inc else val * unit + shift[k]
            elif not present_only:
                if math.isnan(qe[k]) or abs(t - qe[k]) / unit < half:
                    continue
                v = (t - qe[k]) / unit if inc else (t - shift[k]) / unit
                text = fmt(v, d)
                added.append("XYZ"[k] + text)
                val = float(text)
                qe[k] = qe[k] + val * unit if inc else val * unit + shift[k]
        return edits, added

    def _emit_move(self, line: str, mv: Move, target, plan, write) -> None:
        self.report.moves += 1
        d = self._decimals.get(mv.unit)
        if d is None:
            d = self._decimals[mv.unit] = _unit_decimals(self.opt, mv.unit)
        if type(mv) is FastMove:
            if emit_fast(self, line, mv, target, write, d):
                return
            mv = mv.to_move(line)
        if plan is None and mv.arc is None:
            # the common case: a move that is not split; only its words change
            edits, added = self._axis_words(mv, target, self.qe, d)
            if added or (mv.motion_idx < 0 and self.emitted_motion != mv.kind):
                sep, lower = emit.style_of(line)
                if mv.motion_idx < 0 and self.emitted_motion != mv.kind:
                    text = "G" + MOTION_TEXT[mv.kind]
                    edits.append(self._insert_motion(mv, (text.lower() if lower else text) + sep))
                if added:
                    pos = self._insert_pos(mv)
                    text = "".join(sep + w for w in added)
                    edits.append((pos, pos, text.lower() if lower else text))
            self.emitted_motion = mv.kind
            self._write_line(line, edits, write)
            return
        linearise = bool(plan and plan.get("linearise"))
        split_q = plan.get("split_q") if plan else None
        split_s = plan.get("split_s") if plan else None
        if mv.arc is not None and not linearise:
            if self._emit_arc(line, mv, target, plan, d, write):
                return
            # the rounded arc failed its check: linearise it now
            linearise = True
            c = plan["curve"]
            rerr = self._round_err(mv.unit)
            n0 = arc_chord_steps(mv.arc, mv.q0, mv.q1, (self.opt.tolerance_mm - rerr) * 0.5)
            (split_s, split_q), = self._subdivide([c], [np.linspace(0.0, 1.0, n0 + 1)], mv.unit)
        inner = split_q[1:-1] if split_q is not None else np.zeros((0, 3))
        if len(inner) and mv.stays:
            raise PostprocError(
                "this move must be split to stay within tolerance, but its line also changes the tool "
                "or uses G53", path=self.path, lineno=mv.lineno,
                hint="put the tool change or G53 on a line of its own")
        sep, lower = emit.style_of(line)
        ending = emit.line_ending(line) or "\n"
        qe = self.qe
        # inserted lines for intermediate points
        fracs = np.diff(split_s) if split_s is not None else np.array([1.0])
        for j, q in enumerate(inner):
            words = []
            if j == 0:
                words.extend(mv.prefix_words)
            words.append("G1")
            _e, added = self._axis_words_free(mv, q, qe, d)
            words.extend(added)
            if mv.inverse_time:
                words.append("F" + emit.fmt(mv.feed / max(fracs[j], 1e-12), 4))
            elif j == 0 and mv.feed_idx >= 0:
                words.append("F" + mv.words[mv.feed_idx][1])
            text = sep.join(words)
            write((text.lower() if lower else text) + ending)
            self.report.lines_inserted += 1
            self.report.lines_out += 1
        edits, added = self._axis_words(mv, target, qe, d)
        if linearise and mv.arc is not None:
            self.report.arcs_linearised += 1
            g1 = "g1" if lower else "G1"
            if mv.motion_idx >= 0:
                _l, num, start, end, _p = mv.words[mv.motion_idx]
                edits.append((start, end, ("0" if num.startswith("0") else "") + "1"))
            else:
                edits.append(self._insert_motion(mv, g1 + sep))
            spans = [(mv.words[ai][4], mv.words[ai][3]) for ai in mv.aux_idx]
            edits.extend((a, b, "") for a, b in emit.removal_spans(line, spans))
            self.emitted_motion = LINE
        else:
            if mv.motion_idx < 0 and self.emitted_motion != mv.kind:
                text = "G" + MOTION_TEXT[mv.kind]
                edits.append(self._insert_motion(mv, (text.lower() if lower else text) + sep))
            self.emitted_motion = mv.kind
        if mv.inverse_time and len(inner) and mv.feed_idx >= 0:
            _l, num, start, end, _p = mv.words[mv.feed_idx]
            edits.append((start, end, emit.fmt(mv.feed / max(fracs[-1], 1e-12), max(4, emit.decimals_of(num)))))
        if added:
            pos = self._insert_pos(mv)
            text = "".join(sep + w for w in added) if pos > 0 else "".join(w + sep for w in added)
            edits.append((pos, pos, text.lower() if lower else text))
        self._write_line(line, edits, write)

    def _axis_words_free(self, mv: Move, q, qe, d):
        """Words for an inserted line (no original words): every axis that moves."""
        fake = Move(mv.lineno, LINE, mv.q0, mv.q1, mv.r, mv.shift, mv.unit, mv.incremental, mv.arc_absolute,
                    [], (-1, -1, -1), -1, mv.inverse_time, mv.feed, mv.rotary)
        return self._axis_words(fake, q, qe, d)

    def _insert_pos(self, mv: Move) -> int:
        idx = [i for i in mv.axis_idx if i >= 0]
        if idx:
            return mv.words[max(idx)][3]
        if mv.motion_idx >= 0:
            return mv.words[mv.motion_idx][3]
        return mv.words[-1][3]

    def _insert_motion(self, mv: Move, text: str) -> tuple[int, int, str]:
        first = next((w for w in mv.words if w[0] != "N"), mv.words[0])
        return (first[4], first[4], text)

    def _write_line(self, line: str, edits, write) -> None:
        self.report.words_changed += len(edits)
        self.report.lines_changed += bool(edits)
        write(emit.edit_line(line, edits))
        self.report.lines_out += 1

    def _emit_arc(self, line: str, mv: Move, target, plan, d: int, write) -> bool:
        """Emit a kept arc if the rounded arc passes its checks; False to linearise."""
        S = list(self.qe)
        qe = list(self.qe)
        edits, added = self._axis_words(mv, target, qe, d)
        E = list(qe)
        arc = mv.arc
        (a1, a2, an), (l1, l2) = PLANES[arc.plane]
        centre = plan.get("centre")
        if centre is None:
            centre = centre_estimate(arc, plan["s"], plan["qn"], plan["q"])
        unit = mv.unit
        sep, lower = emit.style_of(line)
        arc_edits, arc_added = [], []
        if "nsweep" in plan:
            nsweep, mismatch = plan["nsweep"], plan["mismatch"]
        else:
            _, _, nsweep, _, _ = arc_params(arc, mv.q0, mv.q1)
            mismatch = _mismatch(mv)
        budget = self.opt.tolerance_mm - self._round_err(unit)
        if arc.r_idx >= 0:
            # R arcs: the controller finds the centre from R, which is ill-conditioned
            # near half circles; try the rounded neighbours and keep the best.
            _l, num, start, end, _p = mv.words[arc.r_idx]
            orig = float(num)
            rad = 0.5 * (math.hypot(S[a1] - centre[a1], S[a2] - centre[a2])
                         + math.hypot(E[a1] - centre[a1], E[a2] - centre[a2]))
            v = math.copysign(rad / unit, orig)
            dout = max(d, emit.decimals_of(num))
            step = 10.0 ** (-dout)
            half_chord = 0.5 * math.hypot(E[a1] - S[a1], E[a2] - S[a2]) / unit
            cands = [orig] if abs(v - orig) < 0.5 * step else []
            base_v = float(emit.fmt(v, dout))
            cands += [base_v + k * step for k in (0, 1, -1, 2, -2)]
            cands += [math.copysign(float(emit.fmt(half_chord, dout)) + k * step, orig) for k in (0, 1)]
            best = None
            for val in cands:
                val = float(emit.fmt(val, dout)) if val != orig else orig
                c = r_center(S[a1], S[a2], E[a1], E[a2], val * unit, arc.clockwise)
                if c is None:
                    continue
                ctrl = [0.0, 0.0, 0.0]
                ctrl[a1], ctrl[a2], ctrl[an] = c[0], c[1], S[an]
                cand = Arc(tuple(ctrl), arc.plane, arc.clockwise, arc.turns, arc.offset_idx, arc.r_idx)
                dev = arc_deviation(cand, tuple(S), tuple(E), plan["s"], plan["q"], nsweep, mismatch)
                if best is None or dev < best[0]:
                    best = (dev, val, ctrl)
            if best is None or not best[0] <= budget:
                return False
            _dev, val, ctrl = best
            if val != orig:
                arc_edits.append((start, end, emit.fmt(val, dout)))
        else:
            ctrl = [0.0, 0.0, 0.0]
            ctrl[an] = S[an]
            for axis, letter, idx in ((a1, l1, arc.offset_idx[0]), (a2, l2, arc.offset_idx[1])):
                base = mv.shift[axis] if mv.arc_absolute else S[axis]
                v = (centre[axis] - base) / unit
                if idx >= 0:
                    _l, num, start, end, _p = mv.words[idx]
                    orig = float(num)
                    dout = max(d, emit.decimals_of(num))
                    if abs(v - orig) < 0.5 * 10.0 ** (-dout):
                        val = orig
                    else:
                        text = emit.fmt(v, dout)
                        arc_edits.append((start, end, text))
                        val = float(text)
                else:
                    text = emit.fmt(v, d)
                    val = float(text)
                    if val != 0.0 or mv.arc_absolute:
                        arc_added.append(letter + text)
                    else:
                        val = 0.0
                    if mv.arc_absolute and val == 0.0 and not arc_added:
                        arc_added.append(letter + text)
                ctrl[axis] = base + val * unit
        cand = Arc(tuple(ctrl), arc.plane, arc.clockwise, arc.turns, arc.offset_idx, arc.r_idx)
        dev = arc_deviation(cand, tuple(S), tuple(E), plan["s"], plan["q"], nsweep, mismatch)
        if not dev <= budget:
            return False
        self.qe[:] = qe
        self.report.arcs_kept += 1
        if mv.motion_idx < 0 and self.emitted_motion != mv.kind:
            text = "G" + MOTION_TEXT[mv.kind]
            edits.append(self._insert_motion(mv, (text.lower() if lower else text) + sep))
        self.emitted_motion = mv.kind
        words_added = added + arc_added
        if words_added:
            aux = [i for i in (arc.offset_idx + (arc.r_idx,)) if i >= 0]
            pos = mv.words[max(aux)][3] if aux else self._insert_pos(mv)
            text = "".join(sep + w for w in words_added)
            edits.append((pos, pos, text.lower() if lower else text))
        self._write_line(line, edits + arc_edits, write)
        return True
