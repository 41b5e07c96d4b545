"""The modal state of the interpreter and the tables that drive it.

G-code numbers are keyed as integers ``round(10 * value)`` (G1 -> 10, G90.1 -> 901,
G59.3 -> 593) so that ``G01``, ``g1`` and ``G1.0`` are the same code.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from postproc.constants import MM_PER_INCH

NAN = math.nan

# Motion modes (group 1)
RAPID, LINE, ARC_CW, ARC_CCW = 0, 10, 20, 30
MOTION_CODES = {0: RAPID, 10: LINE, 20: ARC_CW, 30: ARC_CCW}
CANNED_CYCLES = {730, 810, 820, 830, 840, 850, 860, 870, 880, 890}
# a pause in an expanded cycle (G4 P..), as a step kind
DWELL = -1

# Planes: (first axis, second axis, normal axis) as right-handed triples, the
# offset letters of the first and second axis. G2 is clockwise seen from +normal.
PLANES = {
    170: ((0, 1, 2), ("I", "J")),
    180: ((2, 0, 1), ("K", "I")),
    190: ((1, 2, 0), ("J", "K")),
}

# Work coordinate systems: code -> name; G54.1 Pn is handled apart.
WORK_SYSTEMS = {540: "G54", 550: "G55", 560: "G56", 570: "G57", 580: "G58", 590: "G59",
                591: "G59.1", 592: "G59.2", 593: "G59.3"}
# G10 L2 P numbers -> system name (P0 = current)
P_SYSTEMS = {1: "G54", 2: "G55", 3: "G56", 4: "G57", 5: "G58", 6: "G59",
             7: "G59.1", 8: "G59.2", 9: "G59.3"}

# Codes accepted without effect on geometry (pass through): path control, spindle
# speed modes, retract modes, dwell, stored positions, rotation cancel.
NEUTRAL_G = {610, 611, 640, 960, 970, 690, 150, 500}
# Fanuc/Haas look-ahead and smoothing modes (no geometry): G5.1 Q1/Q0 (AI contour
# control), G5 P10000/P0 (high-speed machining), G187 (Haas smoothness), G103 (Haas
# block look-ahead). Accepted only without axis or spline words (G5/G5.1 are splines
# in LinuxCNC).
LOOKAHEAD_G = {50, 51, 80, 1870, 1030}
# Stored positions: G28/G30 move through an intermediate point to the position held
# in parameters #5161-#5166 / #5181-#5186; G28.1/G30.1 store the current position.
HOME_CODES = {280: "G28", 300: "G30"}
HOME_STORE = {281: "G28", 301: "G30"}

# Codes refused with the construct's name: they change geometry in ways this
# postprocessor does not model.
# G5 cubic and G5.1 quadratic splines (LinuxCNC): motion modes, linearised when corrected
SPLINES = {50, 51}

REFUSED_G = {
    52: "G5.2 NURBS block (not supported yet)", 53: "G5.3 end of NURBS block (not supported yet)",
    70: "G7 lathe diameter mode", 80: "G8 lathe radius mode",
    330: "G33 spindle-synchronised motion", 331: "G33.1 rigid tapping",
    382: "G38.2 probing", 383: "G38.3 probing", 384: "G38.4 probing", 385: "G38.5 probing",
    431: "G43.1 dynamic tool length offset", 432: "G43.2 additional tool length offset",
    160: "G16 polar coordinates", 511: "G51 scaling", 510: "G51 scaling",
    680: "G68 coordinate rotation", 923: "G92.3 restore offsets",
    171: "G17.1 plane", 181: "G18.1 plane", 191: "G19.1 plane", 600: "G60 directional positioning",
    760: "G76 threading cycle",
    650: "G65 macro call", 660: "G66 modal macro call", 661: "G66.1 modal macro call",
    470: "G47 text engraving (Haas)", 120: "G12 circular pocket (Haas)", 130: "G13 circular pocket (Haas)",
    1500: "G150 general pocket milling (Haas)",
}

# Why some refused codes cannot be corrected (the hint shown with the refusal).
REFUSED_HINT = {
    382: "a probing move stops where the probe trips, so the positions after it are not known in advance",
    383: "a probing move stops where the probe trips, so the positions after it are not known in advance",
    384: "a probing move stops where the probe trips, so the positions after it are not known in advance",
    385: "a probing move stops where the probe trips, so the positions after it are not known in advance",
}

# Cutter radius compensation (postproc.gcode.cutter): G40 off, G41/G42 on (left/right),
# G41.1/G42.1 with the diameter on the line (LinuxCNC)
CUTTER_COMP = {400: "G40", 410: "G41", 420: "G42", 411: "G41.1", 421: "G42.1"}

# M codes refused: subprograms and modal-state restore change what follows.
REFUSED_M = {97: "M97 local subprogram call (Haas)",
             98: "M98 subprogram call (expanded only with the subprogram in the same file)",
             99: "M99 subprogram return",
             71: "M71 modal state restore", 72: "M72 modal state restore",
             73: "M73 modal state save/autorestore"}

# M codes acting after the motion of their block (LinuxCNC's order of execution puts
# stops last); M6 changes the tool, so its line is never split.
AFTER_MOTION_M = {0, 1, 2, 30, 60}
# Every other M code acts before the motion of its block (rs274ngc "Order of Execution":
# I/O, spindle, coolant, overrides, user M codes, then motion): when a move is split or
# expanded it goes, with its parameter words, on the first line written for the block
# and leaves the last, so the controller acts on it once, where it did before.
BEFORE_MOTION_M = set(range(200)) - AFTER_MOTION_M - {6, 70, 71, 72, 73, 97, 98, 99}
# The parameter words an M code reads (LinuxCNC M-code reference); user M100-M199 read P and Q.
M_PARAMS = {19: "RQP", 50: "P", 51: "P", 52: "P", 53: "P", 61: "Q", 62: "P", 63: "P", 64: "P", 65: "P",
            66: "PELQ", 67: "EQ", 68: "EQ", **{m: "PQ" for m in range(100, 200)}}
# Digital/analog I/O and input waits: their E, L, P, Q words are parameters, not axes.
IO_M = {62, 63, 64, 65, 66, 67, 68}


@dataclass
class ModalState:
    """Controller state advanced block by block (lengths in mm, machine frame).

    ``pos`` is the nominal commanded position of the spindle gauge point in machine
    coordinates (NaN while an axis has not been positioned yet).
    """

    motion: int | None = None  # no motion mode until a G0/G1/G2/G3 is read
    plane: int = 170
    incremental: bool = False
    arc_absolute: bool = False  # G90.1
    inch: bool = False
    inverse_time: bool = False  # G93
    feed: float = NAN
    work: str = "G54"
    work_explicit: bool = False
    g92: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    # the linear part of a rotating, scaling or mirroring programmable frame (Sinumerik ROT,
    # SCALE, MIRROR): 3x3 row-major, program axes to work axes; None: none (the identity)
    frame: tuple[float, ...] | None = None
    tlo: float = 0.0  # active tool length offset along Z (mm)
    tlo_active: bool = False
    tool: int | None = None  # selected tool (T word)
    spindle_tool: int | None = None  # tool loaded by M6 / M61
    pos: list[float] = field(default_factory=lambda: [NAN, NAN, NAN])
    rotary: dict[str, float] = field(default_factory=dict)
    dirs: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    # canned cycles: retract to R (G99) or to the initial level (G98); modal R, Z, Q, P
    retract_r: bool = False
    cycle_r: float | None = None
    cycle_z: float | None = None
    cycle_q: float | None = None
    cycle_p: float | None = None
    before_cycle: int | None = None  # the motion mode before the cycle (restored by G80 outside LinuxCNC)
    # cutter radius compensation: the CUTTER_COMP key in force (400: off), its radius (mm),
    # the D register Fanuc/Haas keep modal, and the move the controller takes as the
    # entry ("entry") or exit ("exit") move, still to come ("")
    comp: int = 400
    comp_radius: float = 0.0
    comp_source: str = ""  # what gave the radius ("tool 1", "D2", "G41.1 D6")
    comp_d: int | None = None
    comp_edge: str = ""

    @property
    def unit_mm(self) -> float:
        return MM_PER_INCH if self.inch else 1.0
