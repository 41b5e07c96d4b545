"""Cutter radius compensation (G41/G42/G40, LinuxCNC's G41.1/G42.1, Fanuc/Haas D registers).

The programmed contour is corrected like any other path and the compensation words stay
as they are, so the controller still offsets the corrected contour by the tool radius.
What this leaves is the change of the correction across the tool radius: the tool centre
sits ``rho`` away from the contour point whose correction it received. With ``delta`` the
engine's correction field (corrected minus nominal position), the tool centre is off by

    e(p, u) = delta(p + rho u) - delta(p)        (u: unit vector in the plane)

to first order, since the machine maps ``p + delta(p) + rho u`` to ``p + rho u - (delta(p +
rho u) - delta(p))``. :func:`radius_bound` takes the largest ``|e|`` over points sampled
along each compensated move and over :data:`BOUND_DIRECTIONS` directions ``u``, by finite
differences of the engine's own correction over exactly the tool radius (a secant, not a
derivative, so a short-period error such as a lead-screw's is not averaged away), and
divides by ``cos(pi / (2 * BOUND_DIRECTIONS))`` for the directions between those sampled.
That bounds how far the wall the tool cuts (the tool-centre path) lies from where it
should; it is reported in the summary and the header and refused above ``--tolerance``.

The controller's own rules are read as its interpreter reads them (LinuxCNC's messages
are rs274's own, checked against it in tests/test_cut_comp.py): compensation turned on
when on, a plane, tool, tool length or work offset changed, G28/G30, G53 or a canned
cycle while it is on; an entry move not longer than the radius (an entry arc of a radius
not larger); an arc as the move after G40; an inside arc not larger than the radius.
Fanuc and Haas refuse an arc as the start-up or exit move (alarm PS0034). The entry and
exit moves are never split: the controller draws them from where it is to the offset
point, so a piece of them would be drawn differently.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from postproc.errors import GcodeSyntaxError, MissingSetupError, SafetyError, UnsupportedGcodeError
from postproc.gcode.moves import Role
from postproc.gcode.state import ARC_CCW, ARC_CW, CANNED_CYCLES, CUTTER_COMP, SPLINES, WORK_SYSTEMS

if TYPE_CHECKING:
    from postproc.gcode.dialect import Dialect
    from postproc.gcode.moves import Move
    from postproc.gcode.state import ModalState


class Interpreter(Protocol):
    """What this module reads of :class:`postproc.gcode.interp.Interpreter` (which calls it)."""

    d: Dialect
    dialect: str
    state: ModalState
    setup: Any
    lenient_setup: bool
    comp_moves: list

    def error(self, cls: type, msg: str, lineno: int, col: int, hint: str | None = None) -> Any: ...

# Directions u sampled in the plane around each contour point. For a correction field
# linear across the radius, +u and -u give the same |e|, so 8 directions sample the
# half-circle every pi/8 and the largest |e| is within cos(pi/16) = 0.98 of the sampled one.
BOUND_DIRECTIONS = 8
# Points sampled along a compensated move: at most this far apart (mm) ...
BOUND_STEP_MM = 2.0
# ... and at most this many per move (a long straight move of a smooth calibration needs no more).
BOUND_MAX_SAMPLES = 64



def _linuxcnc_rules(it: Interpreter) -> bool:
    """The dialect's controller reads D on G41/G42 as a tool number and follows LinuxCNC's
    rules (LinuxCNC, Mach3, generic); else D is an offset register (Fanuc, Haas)."""
    return it.d.cutter_comp == "d-tool"


class CutterBoundError(SafetyError):
    """The change of the correction across the tool radius exceeds --tolerance."""


@dataclass
class CompMove:
    """A move the controller offsets: the move, its radius (mm) and where it came from."""

    move: Move
    radius_mm: float
    source: str
    plane: int = 170


@dataclass
class Bound:
    """The largest change of the correction across the tool radius met so far."""

    bound_mm: float = 0.0
    lineno: int = 0
    radius_mm: float = 0.0
    source: str = ""
    moves: int = 0
    radii: dict = field(default_factory=dict)  # source -> radius (mm)
    lines: set = field(default_factory=set)  # (file, line) of the moves the controller offsets (None: the program's)
    path: str | None = None  # the file of the largest's line, in an expanded program (None: the program's own)

    def note(self) -> str:
        """The header's words for it."""
        radii = ", ".join(f"{k} radius {v:g} mm" for k, v in sorted(self.radii.items())) or "radius 0"
        return f"cutter comp {radii} bound {self.bound_mm * 1000:.2f} um over {self.moves} moves"


def error(it: Interpreter, cls: type, msg: str, lineno: int, col: int, hint: str | None = None) -> Exception:
    return it.error(cls, msg, lineno, col, hint=hint)


def _controller(it: Interpreter) -> str:
    return it.d.comp_controller or it.d.title


def radius_of(it: Interpreter, key: int, vals: dict, lineno: int, col: int) -> tuple[float, str]:
    """The radius (mm) G41/G42/G41.1/G42.1 turn on with, and where it comes from."""
    st = it.state
    radii = getattr(it.setup, "tool_radii", None) or {}
    if key in (411, 421):
        if not _linuxcnc_rules(it):
            raise error(it, UnsupportedGcodeError, f"{CUTTER_COMP[key]} (LinuxCNC's dynamic cutter compensation) "
                       f"in the {it.dialect} dialect", lineno, col)
        if "D" not in vals:
            raise error(it, GcodeSyntaxError, f"{CUTTER_COMP[key]} with no D word", lineno, col,
                       hint="LinuxCNC refuses it: G41.1/G42.1 take the tool diameter on the line")
        d = vals["D"][0]
        if d < 0:
            raise error(it, GcodeSyntaxError, f"negative D word tool radius index used with {CUTTER_COMP[key]}",
                       lineno, col)
        return d * st.unit_mm / 2.0, f"{CUTTER_COMP[key]} D{d:g}"
    if "D" in vals and vals["D"][0] != int(vals["D"][0]):
        raise error(it, GcodeSyntaxError, f"{CUTTER_COMP[key]} requires D word to be a whole number", lineno, col,
                   hint=f"{_controller(it)} refuses it: D names a tool (LinuxCNC) or an offset register")
    tool: int | None
    if _linuxcnc_rules(it):
        # LinuxCNC: D names a tool; without it, the tool in the spindle (none: radius 0)
        tool = int(vals["D"][0]) if "D" in vals else st.spindle_tool
        if not tool:
            return 0.0, "D0" if "D" in vals else "no tool loaded"
        name = f"tool {tool}"
    else:
        if "D" in vals:  # Fanuc, Haas: an offset register, modal
            st.comp_d = int(vals["D"][0])
        tool = st.comp_d
        if not tool:
            return 0.0, "D0"
        name = f"D{tool}"
    r = radii.get(tool, radii.get(None))
    if r is None and it.lenient_setup:
        return 0.0, name  # two versions of one program compared: the radius is the same in both
    if r is None:
        raise error(it, MissingSetupError, f"{CUTTER_COMP[key]} offsets by the radius of {name}, which was not given",
                   lineno, col, hint=f"give --tool-radius {tool}=R, --tool-diameter {tool}=D (mm) or a --tool-table "
                                     "with a D (diameter) column")
    return float(r), name


def check_block(it: Interpreter, b, gcodes: list, tool_change: bool) -> None:
    """The controller's rules for a block read while compensation is on (before its G codes
    act: a G43 refused here must not ask for its tool length first)."""
    st = it.state
    lineno = b.lineno
    ctrl = _controller(it)
    if st.comp != 400:
        first = [(k, i) for k, i in gcodes if k in (170, 180, 190)]
        refusals = [
            (first, "Cannot change planes with cutter radius compensation on"),
            ([(k, i) for k, i in gcodes if k in (280, 300)], "Cannot use g28 or g30 with cutter radius comp"),
            ([(k, i) for k, i in gcodes if k == 530], "Cannot use g53 with cutter radius comp"),
            ([(k, i) for k, i in gcodes if k in (430, 490)],
             "Cannot change tool offset with cutter radius compensation on"),
            ([(k, i) for k, i in gcodes if k in WORK_SYSTEMS or k == 541],
             "Cannot change coordinate systems with cutter radius compensation on"),
            ([(k, i) for k, i in gcodes if k in CANNED_CYCLES or k in SPLINES],
             "Cannot use canned cycles with cutter compensation on"),
        ]
        for hits, msg in refusals:
            if hits:
                k, i = hits[0]
                if k in SPLINES:
                    msg = f"G{k / 10:g} spline with cutter radius compensation on"
                raise error(it, UnsupportedGcodeError, msg, lineno, b.col(i),
                           hint=f"{ctrl} refuses it; turn compensation off (G40) first")
        if tool_change:
            raise error(it, UnsupportedGcodeError, "Cannot change tools with cutter radius compensation on",
                       lineno, b.words[0].letter_pos + 1, hint=f"{ctrl} refuses it; G40 first")
        modal = not any(k in (0, 10, 20, 30) or k in CANNED_CYCLES or k in SPLINES for k, _i in gcodes)
        if modal and st.motion in CANNED_CYCLES and any(a in b.vals for a in "XYZ"):
            raise error(it, UnsupportedGcodeError, "Cannot use canned cycles with cutter compensation on",
                       lineno, b.words[0].letter_pos + 1)


def switch(it: Interpreter, b, gcodes: list) -> None:
    """G40/G41/G42/G41.1/G42.1 on the block (``b.comp``: key and word index): the state it
    leaves, and the controller's rules for turning compensation on."""
    st = it.state
    lineno = b.lineno
    on = st.comp != 400
    ctrl = _controller(it)
    keys = {k: i for k, i in gcodes}
    key, i = b.comp
    col = b.col(i)
    if key == 400:
        if on:  # the radius stays for the exit move
            st.comp, st.comp_edge = 400, "exit"
        return
    if it.d.cutter_comp == "none":
        raise error(it, UnsupportedGcodeError, f"{CUTTER_COMP[key]} cutter radius compensation ({it.d.title}: "
                   "none, or its rules are not modelled)", lineno, col,
                   hint="post the tool-centre path (compensation done in CAM) for this controller")
    if on and _linuxcnc_rules(it):
        raise error(it, GcodeSyntaxError, "Cannot turn cutter radius comp on when on", lineno, col,
                   hint="LinuxCNC refuses it: G40 before turning it on again")
    if st.plane == 190 or 190 in keys:
        raise error(it, UnsupportedGcodeError, "Cutter radius compensation allowed only in XY, XZ planes",
                   lineno, col)
    if st.plane == 180 and not _linuxcnc_rules(it):
        raise error(it, UnsupportedGcodeError, f"cutter radius compensation in the XZ plane (G18) on {ctrl}",
                   lineno, col, hint="postproc reads G18 compensation as LinuxCNC does only")
    radius, source = radius_of(it, key, b.vals, lineno, col)
    st.comp, st.comp_radius, st.comp_source = key, radius, source
    st.comp_edge = "entry" if not on else ""


def on_move(it: Interpreter, mv: Move) -> None:
    """A move made while compensation is on, or the first after it was turned on or off:
    the controller's rules for it, kept from being split where the controller draws it
    from where it is (entry, exit), and recorded for the bound."""
    st = it.state
    edge = st.comp_edge
    lineno = mv.lineno
    col = mv.words[0].letter_pos + 1 if mv.words else 1
    (a1, a2, _an), _ = _plane_axes(st.plane)
    ctrl = _controller(it)
    rho = st.comp_radius
    arc = mv.arc
    in_plane = math.hypot(mv.q1[a1] - mv.q0[a1], mv.q1[a2] - mv.q0[a2])
    if edge and arc is None and in_plane == 0.0 and not _linuxcnc_rules(it):
        # a move along the normal axis alone (a plunge): Fanuc and Haas start up (or cancel)
        # on the next move in the plane; LinuxCNC takes it as the entry move (refused: not
        # longer than the radius) or the exit move
        if edge == "entry":
            it.comp_moves.append(CompMove(mv, rho, st.comp_source, st.plane))
        return
    if edge == "entry":
        st.comp_edge = ""
        mv.role = Role.WHOLE
        if arc is not None and not _linuxcnc_rules(it):
            raise error(it, UnsupportedGcodeError, f"arc as the start-up move of cutter compensation on {ctrl}",
                       lineno, col, hint="alarm PS0034 (no circular interpolation in the start-up or exit "
                                         "block): the lead-in must be G0 or G1")
        if arc is not None:
            # rs274 (interp_arc.cc, convert_arc_comp1) compares the chord from where the tool
            # is to the arc's end, not the arc's radius, whatever its message says
            if in_plane <= rho:
                raise error(it, GcodeSyntaxError,
                           "Radius of cutter compensation entry arc is not greater than the tool radius", lineno, col,
                           hint="LinuxCNC refuses it")
        elif in_plane <= rho:
            raise error(it, GcodeSyntaxError,
                       "Length of cutter compensation entry move is not greater than the tool radius", lineno, col,
                       hint="LinuxCNC refuses it")
    elif edge == "exit":
        st.comp_edge = ""
        mv.role = Role.WHOLE
        if arc is not None:
            if _linuxcnc_rules(it):
                raise error(it, GcodeSyntaxError,
                           "The move just after exiting cutter compensation mode must be straight, not an arc",
                           lineno, col, hint="LinuxCNC refuses it")
            raise error(it, UnsupportedGcodeError, f"arc as the exit move of cutter compensation on {ctrl}",
                       lineno, col, hint="alarm PS0034 (no circular interpolation in the start-up or exit block): "
                                         "the lead-out must be G0 or G1")
        it.comp_moves.append(CompMove(mv, rho, st.comp_source, st.plane))
        st.comp_radius, st.comp_source = 0.0, ""
        return
    elif arc is not None and st.comp != 400 and (st.plane == 170 or not _linuxcnc_rules(it)):
        # (rs274 does not check an inside arc in the XZ plane: it draws it, and so do we)
        r_arc = math.hypot(mv.q0[a1] - arc.center[a1], mv.q0[a2] - arc.center[a2])
        left = st.comp in (410, 411)
        inside = (left and st.motion == ARC_CCW) or (not left and st.motion == ARC_CW)
        if inside and r_arc <= rho:
            raise error(it, GcodeSyntaxError, "Tool radius not less than arc radius with comp", lineno, col,
                       hint=f"{ctrl} refuses it: the tool does not fit inside the arc")
    if st.comp != 400:
        it.comp_moves.append(CompMove(mv, rho, st.comp_source, st.plane))


def _plane_axes(plane: int):
    from postproc.gcode.state import PLANES

    return PLANES[plane]


def move_samples(mv: Move) -> np.ndarray:
    """Nominal gauge positions along a move (its start, its end, and between them at most
    :data:`BOUND_STEP_MM` apart, :data:`BOUND_MAX_SAMPLES` in all)."""
    from postproc.gcode.geometry import arc_length, arc_points, line_points

    q0 = np.asarray(mv.q0, dtype=float)
    q1 = np.asarray(mv.q1, dtype=float)
    if mv.arc is not None:
        length = arc_length(mv.arc, mv.q0, mv.q1)
    else:
        length = float(np.linalg.norm(q1 - q0))
    n = min(BOUND_MAX_SAMPLES, max(2, math.ceil(length / BOUND_STEP_MM) + 1))
    s = np.linspace(0.0, 1.0, n)
    if mv.arc is not None:
        return arc_points(mv.arc, mv.q0, mv.q1, s)
    return line_points(mv.q0, mv.q1, s)


def radius_bound(correction: Callable[[np.ndarray, np.ndarray, np.ndarray, list], np.ndarray],
                 moves: list[CompMove]) -> tuple[np.ndarray, np.ndarray]:
    """The largest change of the correction across each move's tool radius, and the
    nominal point where it is met: ``(bound_mm (M,), at (M, 3))``.

    ``correction(q, r, dirs, rotary)`` gives the correction (mm, (N, 3)) at nominal gauge
    positions ``q`` with tool vectors ``r``, approach directions ``dirs`` and rotary positions
    ``rotary`` (a dict per point); the directions are the
    move's own for the point and its neighbours alike, so a direction-dependent term
    (backlash) cancels as it does on the machine, where the tool centre moves with the contour.
    """
    if not moves:
        return np.zeros(0), np.zeros((0, 3))
    angles = np.arange(BOUND_DIRECTIONS) * (math.pi / BOUND_DIRECTIONS)
    pts, rs, dirs, owner, offs, rot = [], [], [], [], [], []
    for k, cm in enumerate(moves):
        mv = cm.move
        if cm.radius_mm == 0.0:
            continue
        q = move_samples(mv)
        (a1, a2, _an), _ = _plane_axes(cm.plane)
        u = np.zeros((BOUND_DIRECTIONS, 3))
        u[:, a1] = np.cos(angles)
        u[:, a2] = np.sin(angles)
        d = np.asarray(mv.q1, dtype=float) - np.asarray(mv.q0, dtype=float)
        nd = np.linalg.norm(d)
        d = np.sign(d) if nd > 0 else np.zeros(3)
        # each sample, then each sample moved by +rho u and -rho u
        block = np.concatenate([q[:, None, :], q[:, None, :] + cm.radius_mm * u[None],
                                q[:, None, :] - cm.radius_mm * u[None]], axis=1)  # (n, 1 + 2K, 3)
        pts.append(block.reshape(-1, 3))
        rs.append(np.broadcast_to(np.asarray(mv.r, dtype=float), (block.shape[0] * block.shape[1], 3)))
        dirs.append(np.broadcast_to(d, (block.shape[0] * block.shape[1], 3)))
        owner.append(np.full(len(q), k))
        rot.extend([mv.rotary] * (block.shape[0] * block.shape[1]))
        offs.append(q)
    bound = np.zeros(len(moves))
    at = np.array([m.move.q1 for m in moves], dtype=float)
    if not pts:
        return bound, at
    P = np.concatenate(pts)
    delta = correction(P, np.concatenate(rs), np.concatenate(dirs), rot)
    delta = delta.reshape(-1, 1 + 2 * BOUND_DIRECTIONS, 3)
    change = np.linalg.norm(delta[:, 1:, :] - delta[:, :1, :], axis=2).max(axis=1)  # (n_samples,)
    change = change / math.cos(math.pi / (2 * BOUND_DIRECTIONS))
    own = np.concatenate(owner)
    Q = np.concatenate(offs)
    for k in np.unique(own).tolist():
        rows = np.flatnonzero(own == k)
        j = rows[int(np.argmax(change[rows]))]
        bound[k] = change[j]
        at[k] = Q[j]
    return bound, at


class Rerun(Exception):  # noqa: N818 - a signal, not an error
    """A program with compensated moves was corrected before its bound was known: the
    header, written first, must carry it, so the program is corrected again with it."""

    def __init__(self, bound: Bound) -> None:
        super().__init__("cutter compensation bound known: correct again")
        self.bound = bound


def check_chunk(c) -> None:
    """Bound the moves the corrector ``c`` (:class:`postproc.gcode.pipeline.Corrector`) has
    read under compensation since the last chunk, fold them into ``c.cutter`` and refuse a
    bound above ``--tolerance``, naming the line, the radius and the figure."""
    moves = c.interp.comp_moves
    if not moves:
        return
    c.interp.comp_moves = []
    eng = c.engine
    lo, hi = eng.volume_mm

    def correction(q: np.ndarray, r: np.ndarray, dirs: np.ndarray, rotary: list) -> np.ndarray:
        # beyond the calibrated volume the field is taken at its edge: the contour itself
        # is held to the volume by the corrector's own check
        qe = np.clip(q, lo, hi)
        ctx = c.planner.context(dirs, rotary)
        delta = np.asarray(eng.correction(qe + r, r, ctx).q, dtype=float)
        for add in c.opt.added:
            delta = delta + np.asarray(add.delta(q + r, ctx), dtype=float)
        return delta

    bound, at = radius_bound(correction, moves)
    b = c.cutter
    b.moves += len(moves)
    b.lines.update((cm.move.path, cm.move.lineno) for cm in moves)
    for cm in moves:
        if cm.radius_mm:
            b.radii[cm.source] = cm.radius_mm
    k = int(np.argmax(bound))
    if bound[k] > b.bound_mm:
        b.bound_mm, b.lineno, b.radius_mm, b.source = float(bound[k]), moves[k].move.lineno, moves[k].radius_mm, \
            moves[k].source
        b.path = moves[k].move.path
    tol = c.opt.tolerance_mm
    if bound[k] > tol:
        cm = moves[k]
        raise CutterBoundError(
            f"cutter radius compensation: the correction changes by {bound[k] * 1000:.2f} um across the tool "
            f"radius {cm.radius_mm:g} mm ({cm.source}) near ({at[k][0]:.3f}, {at[k][1]:.3f}, {at[k][2]:.3f}) mm, "
            f"more than the tolerance {tol:g} mm", path=cm.move.path or c.path, lineno=cm.move.lineno,
            hint="the controller offsets the corrected contour by the radius, so the tool centre is off by that "
                 f"much; allow it with postproc correct --tolerance {math.ceil(bound[k] * 1e5) / 1e5:g}, or post the "
                 "tool-centre "
                 "path (compensation done in CAM)")


def take_up(c, mv: Move) -> None:
    """Refuse a backlash take-up move inserted before a move the controller offsets: it
    would offset the take-up too, as a move of its own (corners and all)."""
    if (mv.path, mv.lineno) in c.cutter.lines:
        raise UnsupportedGcodeError(
            "a backlash take-up move would be inserted under cutter radius compensation, where the controller "
            "would offset it as a move of its own", path=mv.path or c.path, lineno=mv.lineno,
            hint="post the tool-centre path (compensation done in CAM) for a calibration with backlash")


def merge_bounds(a: Bound | None, b: Bound | None) -> Bound | None:
    """The bound of a program corrected in two parts (:mod:`postproc.gcode.split`)."""
    if a is None or b is None:
        return a or b
    worst = a if a.bound_mm >= b.bound_mm else b
    return Bound(worst.bound_mm, worst.lineno, worst.radius_mm, worst.source, a.moves + b.moves,
                 {**a.radii, **b.radii}, a.lines | b.lines, worst.path)
