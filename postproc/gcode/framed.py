"""An arc move under a Sinumerik rotating, scaling or mirroring frame, seen in the
frame's coordinates, so that the writer's arc code (:mod:`postproc.gcode.emitter`,
:mod:`postproc.gcode.arcfit`) writes its end and centre words there unchanged.

Under the frame's linear part ``A`` a point programmed ``p`` is at ``q = s + A (p - s)``
in the machine (:func:`postproc.gcode.frames.machine_from_program`). The interpreter
reads an arc under ``A`` only where ``A`` keeps it a circle in its plane
(:func:`postproc.gcode.frames.keeps_circles`): ``A``'s block in the plane is ``k`` times
a rotation, or a rotation and a mirror, and it keeps the plane's normal (scaled by
``kn = |a_nn|``). The *view* of a machine point is ``v = s + k A^-1 (q - s)``: a word's
value times ``k`` units is a length in the view, so the arc code runs on a move whose
unit is ``k`` times the program's, and in the plane the view is the machine turned
(lengths kept). Along the normal the view stretches lengths by ``k / kn``; the budget of
the fits is shared by :attr:`FrameView.budget_share` so that a distance within it in the
view is within it in the machine. A mirror turns the arc's direction in the view back to
the program's (G2 stays G2 as written).

The planner's plan of the move (corrected samples, take-ups, the nominal sweep) and the
bulk planner's :class:`~postproc.gcode.vplan.ArcHint` are mapped into the view once; the
emitted position goes into it before the arc is written and back after.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import cast

import numpy as np

from postproc.gcode import frames
from postproc.gcode.moves import Arc, Move
from postproc.gcode.state import PLANES
from postproc.gcode.vplan import ArcHint, Ends, Piece, Plan, Step, TakeUp


@dataclass(frozen=True, slots=True)
class FrameView:
    """The view of one framed arc move (see the module docstring)."""

    shift: tuple[float, float, float]  # s: the frame's fixed point (work offset, TRANS, tool length)
    to_view: frames.Frame  # k A^-1
    to_machine: frames.Frame  # A / k
    scale: float  # k: the frame's scale in the arc's plane
    budget_share: float  # min(1, k / kn): a length in the view is at least the machine's
    reverses: bool  # a mirror in the plane: the arc turns the other way in the view
    isometric: bool  # k == kn: lengths are the machine's in every direction

    @classmethod
    def of(cls, mv: Move) -> FrameView:
        """The view of ``mv`` (an arc with a frame the interpreter has checked)."""
        a, arc = mv.frame, mv.arc
        if a is None or arc is None:
            raise TypeError("a frame view of a move that is no framed arc")
        p, q, n = PLANES[arc.plane][0]
        k = math.sqrt(abs(a[3 * p + p] * a[3 * q + q] - a[3 * p + q] * a[3 * q + p]))
        if abs(k - 1.0) <= frames.FRAME_EPS:
            k = 1.0  # a rotation's cos^2 + sin^2: the program's unit as it is
        kn = abs(a[3 * n + n])
        inv = frames.inverse(a)
        return cls(mv.shift, tuple(k * x for x in inv), tuple(x / k for x in a), k, min(1.0, k / kn),
                   frames.reverses_arcs(a, (p, q, n)), abs(k - kn) <= frames.FRAME_EPS * k)

    # -- points ---------------------------------------------------------------------------
    def point(self, q: Sequence[float] | np.ndarray) -> tuple[float, float, float]:
        """The view of the machine point ``q`` (an axis the frame does not mix stays NaN
        alone, as :func:`frames.apply` keeps it)."""
        return frames.machine_from_program(self.to_view, self.shift, [float(v) for v in q])

    def machine(self, v: Sequence[float]) -> tuple[float, float, float]:
        """The machine point of the view's point ``v``."""
        return frames.machine_from_program(self.to_machine, self.shift, v)

    def points(self, Q: np.ndarray) -> np.ndarray:
        """The view of machine points ``Q`` (n, 3), all known."""
        s = np.asarray(self.shift, dtype=float)
        return (np.asarray(Q, dtype=float) - s) @ np.asarray(self.to_view, dtype=float).reshape(3, 3).T + s

    def vectors(self, D: np.ndarray) -> np.ndarray:
        """The view of machine displacements ``D`` (n, 3)."""
        return np.asarray(D, dtype=float) @ np.asarray(self.to_view, dtype=float).reshape(3, 3).T

    # -- what the writer reads ----------------------------------------------------------
    def move(self, mv: Move) -> Move:
        """``mv`` in the view: no frame, its points and centre mapped, its unit ``k``
        times the program's, its direction the program's."""
        arc = cast("Arc", mv.arc)
        varc = Arc(self.point(arc.center), arc.plane, arc.clockwise != self.reverses, arc.turns, arc.offset_idx,
                   arc.r_idx)
        return replace(mv, frame=None, q0=self.point(mv.q0), q1=self.point(mv.q1), unit=mv.unit * self.scale,
                       arc=varc)

    def plan(self, plan: Plan | None) -> Plan | None:
        """The planner's plan of the move in the view (its curve stays the machine's: the
        fits map what the engine's subdivision gives, :meth:`points`)."""
        if plan is None or "seq" not in plan:
            return plan
        seq: list[Step] = []
        for st in plan["seq"]:
            if st[0] == "takeup":
                seq.append(cast("TakeUp", ("takeup", self.points(st[1][None, :])[0])))
            else:
                _tag, s, Q, nom, bulge = st
                seq.append(cast("Piece", ("piece", s, self.points(Q), self.points(nom), self.vectors(bulge))))
        out: Plan = {"seq": seq, "whole": plan["whole"], "curve": plan["curve"]}
        if "nsweep" in plan:
            out["nsweep"] = -plan["nsweep"] if self.reverses else plan["nsweep"]
        if "mismatch" in plan:
            out["mismatch"] = plan["mismatch"]  # a radius: kept in the plane
        return out

    def hint(self, hint: ArcHint, plane: int) -> ArcHint | None:
        """The bulk planner's hint in the view (its bound is in lengths: only where the
        view keeps them, else None and the move takes its general plan)."""
        if not self.isometric:
            return None
        (a1, a2, an), _ = PLANES[plane]

        def view(u1: float, u2: float, un: float) -> tuple[float, float, float]:
            q = [0.0, 0.0, 0.0]
            q[a1], q[a2], q[an] = u1, u2, un
            v = self.point(q)
            return v[a1], v[a2], v[an]

        c1, c2, _cn = view(hint.c1, hint.c2, 0.0)
        ends: Ends = view(*hint.ends[:3]) + view(*hint.ends[3:])
        return ArcHint(c1, c2, hint.rho, hint.worst, -hint.nsweep if self.reverses else hint.nsweep, ends, hint.row,
                       hint.mismatch)
