"""The moves of a Sinumerik drilling cycle (``CYCLE81``-``CYCLE83``, ``CYCLE85``-``CYCLE89``), as
the SINUMERIK 840D Programming Guide Cycles (PGZ 11.02, chapter 2, "Drilling cycles")
describes them.

Every cycle drills at the position reached before it, along Z (G17), with parameters
RTP (retraction plane, absolute), RFP (reference plane, absolute), SDIS (safety distance,
without sign), DP (final depth, absolute) and DPR (final depth relative to RFP, without
sign; when both are given the depth comes from DPR: "Drilling, centering - CYCLE81").
"G1" is at the feed programmed before the call unless a feed line says otherwise:

- CYCLE81(RTP, RFP, SDIS, DP, DPR): G0 to RFP + SDIS, G1 to the depth, G0 to RTP;
- CYCLE82(RTP, RFP, SDIS, DP, DPR, DTB): as CYCLE81 with the dwell DTB (seconds) at the
  depth ("Drilling, counterboring - CYCLE82");
- CYCLE83(RTP, RFP, SDIS, DP, DPR, FDEP, FDPR, DAM, DTB, DTS, FRF, VARI, _AXN, _MDEP,
  _VRT, _DTD, _DIS1) ("Deep-hole drilling - CYCLE83"): strokes from the first drilling
  depth FDEP (absolute; FDPR relative to RFP), each next stroke the last one less the
  degression DAM but not less than DAM, the last one ending at the final depth; the first
  stroke at the feed times FRF; _MDEP, the minimum stroke, is read where every stroke but the
  last is at least as long (it then changes nothing). VARI=0 (chip breaking): after each stroke and the dwell
  DTB, G1 back by _VRT (1 mm when 0) and on to the next depth. VARI=1 (swarf removal):
  after each stroke and the dwell DTB, G0 to RFP + SDIS, the dwell DTS, G0 to the depth
  reached less the anticipation distance (_DIS1, or 0.6 mm up to 30 mm of depth, else
  depth / 50 and at most 7 mm), G1 to the next depth. At the final depth the dwell _DTD
  (DTB when 0), then G0 to RTP;
- CYCLE85(RTP, RFP, SDIS, DP, DPR, DTB, FFR, RFF) ("Boring 1"): G0 to RFP + SDIS, G1 to the
  depth at FFR, dwell DTB, G1 to RFP + SDIS at RFF, G0 to RTP;
- CYCLE86(RTP, RFP, SDIS, DP, DPR, DTB, SDIR, RPA, RPO, RPAP, POSS) ("Boring 2"): the
  spindle in SDIR (M3/M4), G0 to RFP + SDIS, G1 to the depth, dwell DTB, oriented spindle
  stop at POSS (``SPOS=``), G0 by RPA, RPO, RPAP (incremental in X, Y, Z), G0 to
  RFP + SDIS, G0 back over the hole, G0 to RTP;
- CYCLE87(RTP, RFP, SDIS, DP, DPR, SDIR) ("Boring 3"): the spindle in SDIR, G0 to
  RFP + SDIS, G1 to the depth, M5, M0 (the operator starts again), G0 to RTP;
- CYCLE88(RTP, RFP, SDIS, DP, DPR, DTB, SDIR) ("Boring 4"): as CYCLE87 with the dwell DTB
  at the depth before M5 M0;
- CYCLE89(RTP, RFP, SDIS, DP, DPR, DTB): G0 to RFP + SDIS, G1 to the depth, dwell DTB,
  G1 back to RFP + SDIS at the same feed, G0 to RTP ("Boring 5 - CYCLE89").

A feed the cycle sets (FRF, FFR, RFF) is written as an ``F`` line, and the feed programmed
before the call is written again after it. CYCLE84 and CYCLE840 (tapping) are refused by the
dialect: their Z travel is tied to the spindle's turns at the thread's pitch.

A modal call (``MCALL CYCLE81(...)``, section 2.2 "Modal call of drilling cycles") runs the
cycle after each block that moves an axis, until a bare ``MCALL``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from postproc.errors import GcodeSyntaxError
from postproc.gcode.sinumerik import CycleCall, number_text

#: the cycle's code in the interpreter's cycle numbering (G81 = 810, ...)
CODES = {"CYCLE81": 810, "CYCLE82": 820, "CYCLE83": 830, "CYCLE85": 850, "CYCLE86": 860, "CYCLE87": 870,
         "CYCLE88": 880, "CYCLE89": 890}
#: step kinds: G0/G1 to a level (a Z, or (dx, dy, z) off the hole), a dwell in seconds, a line
#: written as it is (a feed, a spindle stop)
RAPID_STEP, FEED_STEP, DWELL_STEP, TEXT_STEP = "G0", "G1", "G4", "TEXT"
#: CYCLE83's defaults in mm (PGZ, "Deep-hole drilling - CYCLE83"): the chip-breaking retraction
#: when _VRT is 0, the anticipation distance up to 30 mm of depth, beyond it depth / 50 up to 7 mm
CHIP_BREAK_MM = 1.0
ANTICIPATION_MM, ANTICIPATION_DEPTH_MM, ANTICIPATION_MAX_MM = 0.6, 30.0, 7.0
#: more strokes than this: a first depth or degression too small to be meant (refused)
MAX_STROKES = 10_000
#: a stroke this much shorter than _MDEP is still as long (the rounding of program numbers)
STROKE_EPS = 1e-9

Level = float | tuple[float, float, float]
Step = tuple[str, "Level | str"]


@dataclass(frozen=True)
class DrillPlan:
    """A cycle's levels (program Z) and steps: ``(kind, level)`` for G0/G1 to a level along
    Z (or ``(dx, dy, z)``: off the hole by dx, dy), ``("G4", seconds)`` for a dwell,
    ``("TEXT", line)`` for a line written as it is."""

    code: int
    start_z: float  # RFP + SDIS: where the feed starts
    bottom_z: float
    clear_z: float  # RTP
    dwell_s: float | None
    steps: tuple[Step, ...]


class _Call:
    """A cycle call's parameters by position, and its refusals naming file, line and column."""

    def __init__(self, call: CycleCall, path: str | None, lineno: int, col: int) -> None:
        self.call, self.path, self.lineno, self.col = call, path, lineno, col

    def __getitem__(self, i: int) -> float | None:
        return self.call.args[i] if i < len(self.call.args) else None

    def bad(self, what: str) -> GcodeSyntaxError:
        return GcodeSyntaxError(f"Sinumerik {self.call.name} {what}", path=self.path, lineno=self.lineno,
                                col=self.col)

    def dwell(self, i: int, name: str) -> float:
        v = self[i] or 0.0
        if v < 0:
            raise self.bad(f"with a dwell in spindle revolutions ({name} < 0), not read")
        return v

    def spindle(self, i: int) -> str:
        sdir = self[i]
        if sdir not in (3.0, 4.0):
            raise self.bad("without its spindle direction SDIR (3 for M3, 4 for M4)")
        return f"M{int(sdir)}"


def _depths(p: _Call) -> tuple[float, float, float]:
    """RFP + SDIS, the final depth and RTP (program units)."""
    rtp, rfp, sdis, dp, dpr = (p[i] for i in range(5))
    if rtp is None or rfp is None:
        raise p.bad("without its RTP (retraction plane) or RFP (reference plane)")
    sdis = abs(sdis or 0.0)
    if dpr:
        bottom = rfp - abs(dpr)  # DPR is entered without sign and wins over DP
    elif dp is not None:
        bottom = dp
    else:
        raise p.bad("without its final depth (DP or DPR)")
    if bottom > rfp + sdis or rtp < rfp:
        raise p.bad("with its depth above its reference plane, or its retraction plane below it")
    return rfp + sdis, bottom, rtp


def drill_plan(call: CycleCall, path: str | None, lineno: int, feed: float = math.nan,
               unit_mm: float = 1.0, col: int | None = None) -> DrillPlan:
    """The levels and steps of ``call`` in program units (work coordinates along Z);
    ``feed`` is the feed programmed before the call (NaN: none), ``unit_mm`` the program's
    unit in mm (for CYCLE83's defaults, given in mm). ``col``: the column of line
    ``lineno`` its refusals point at (None: the call's own, the line being the call's; a
    block the modal call runs after gives its own start)."""
    p = _Call(call, path, lineno, call.col if col is None else col)
    start, bottom, rtp = _depths(p)
    name = call.name
    steps: list[Step] = []
    dwell: float | None = None
    restore = False
    if name in ("CYCLE81", "CYCLE82", "CYCLE89"):
        steps += [(RAPID_STEP, start), (FEED_STEP, bottom)]
        if name != "CYCLE81":
            dwell = p.dwell(5, "DTB")
            if dwell:
                steps.append((DWELL_STEP, dwell))
        if name == "CYCLE89":
            steps.append((FEED_STEP, start))
    elif name == "CYCLE83":
        steps, dwell, restore = _deep_hole(p, start, bottom, feed, unit_mm)
    elif name == "CYCLE85":
        ffr, rff = p[6], p[7]
        if not ffr or not rff or ffr < 0 or rff < 0:
            raise p.bad("without its feeds FFR (boring) and RFF (retraction)")
        dwell = p.dwell(5, "DTB")
        steps += [(RAPID_STEP, start), (TEXT_STEP, "F" + number_text(ffr)), (FEED_STEP, bottom)]
        if dwell:
            steps.append((DWELL_STEP, dwell))
        steps += [(TEXT_STEP, "F" + number_text(rff)), (FEED_STEP, start)]
        restore = True
    elif name == "CYCLE86":
        dwell = p.dwell(5, "DTB")
        rpa, rpo, rpap, poss = (p[i] or 0.0 for i in (7, 8, 9, 10))
        steps += [(TEXT_STEP, p.spindle(6)), (RAPID_STEP, start), (FEED_STEP, bottom)]
        if dwell:
            steps.append((DWELL_STEP, dwell))
        steps += [(TEXT_STEP, "SPOS=" + number_text(poss)), (RAPID_STEP, (rpa, rpo, bottom + rpap)),
                  (RAPID_STEP, (rpa, rpo, start)), (RAPID_STEP, start)]
    else:  # CYCLE87, CYCLE88
        sdir = 5 if name == "CYCLE87" else 6
        steps += [(TEXT_STEP, p.spindle(sdir)), (RAPID_STEP, start), (FEED_STEP, bottom)]
        if name == "CYCLE88":
            dwell = p.dwell(5, "DTB")
            if dwell:
                steps.append((DWELL_STEP, dwell))
        steps += [(TEXT_STEP, "M5"), (TEXT_STEP, "M0")]
    steps.append((RAPID_STEP, rtp))
    if restore and not math.isnan(feed):
        steps.append((TEXT_STEP, "F" + number_text(feed)))  # the program's feed again
    return DrillPlan(CODES[name], start, bottom, rtp, dwell or None, tuple(steps))


def strokes(first: float, bottom: float, rfp: float, dam: float) -> list[float]:
    """CYCLE83's drilling depths: ``first`` (not below ``bottom``), then each stroke the
    previous one less ``dam`` while that is more than ``dam``, else ``dam``; the last at
    ``bottom``. The first stroke is measured from ``rfp``."""
    depth = max(first, bottom)
    stroke = rfp - depth
    out = [depth]
    while depth > bottom:
        stroke = stroke - dam if stroke - dam > dam else dam
        depth = max(depth - stroke, bottom)
        out.append(depth)
        if len(out) > MAX_STROKES:
            raise ValueError(len(out))
    return out


@dataclass(frozen=True)
class _DeepHole:
    """CYCLE83's parameters as read: the first depth, the degression, the dwells, the first
    stroke's feed factor, the variant and the chip-breaking and anticipation distances (0: the
    cycle's own)."""

    first: float
    dam: float
    dtb: float
    dts: float
    dtd: float
    frf: float
    vari: float
    vrt: float
    dis1: float
    mdep: float  # the minimum stroke (_MDEP): read only where no stroke but the last is shorter


def _deep_hole_params(p: _Call, feed: float) -> _DeepHole:
    """CYCLE83's parameters, refused by name where they ask for what is not read."""
    rfp = p[1] or 0.0
    fdep, fdpr, dam = p[5], p[6], p[7] or 0.0
    dtb = p.dwell(8, "DTB")
    frf = p[10] or 1.0
    vari = p[11] or 0.0
    axn, mdep, vrt, dis1 = p[12] or 0.0, p[13] or 0.0, p[14] or 0.0, p[16] or 0.0
    if fdpr:
        first = rfp - abs(fdpr)
    elif fdep is not None:
        first = fdep
    else:
        raise p.bad("without its first drilling depth (FDEP or FDPR)")
    if first >= rfp:
        raise p.bad("with its first drilling depth not below its reference plane")
    if dam < 0:
        raise p.bad("with a degression DAM < 0 (a factor of the last stroke), not read")
    if not 0 < frf <= 1:
        raise p.bad("with a feed factor FRF outside 0.001...1")
    if vari not in (0.0, 1.0):
        raise p.bad("with VARI other than 0 (chip breaking) or 1 (swarf removal)")
    if axn not in (0.0, 3.0):
        raise p.bad("with a tool axis _AXN other than Z, not read")
    if mdep < 0:
        raise p.bad("with a negative minimum drilling depth _MDEP")
    if vrt < 0 or dis1 < 0:
        raise p.bad("with a negative retraction _VRT or anticipation distance _DIS1")
    if frf != 1.0 and math.isnan(feed):
        raise p.bad("with a feed factor FRF before any feed is programmed")
    return _DeepHole(first, dam, dtb, p.dwell(9, "DTS"), p.dwell(15, "_DTD") or dtb, frf, vari, vrt, dis1, mdep)


def _deep_hole(p: _Call, start: float, bottom: float, feed: float,
               unit_mm: float) -> tuple[list[Step], float | None, bool]:
    """CYCLE83's steps (without the final G0 to RTP), its dwell at the final depth, and
    whether the feed programmed before the call is to be written again after it."""
    rfp = p[1] or 0.0
    c = _deep_hole_params(p, feed)
    first, dam, dtb, dts, dtd, frf, vari, vrt, dis1 = (c.first, c.dam, c.dtb, c.dts, c.dtd, c.frf, c.vari, c.vrt,
                                                       c.dis1)
    try:
        depths = strokes(first, bottom, rfp, dam)
    except ValueError:
        raise p.bad(f"with more than {MAX_STROKES} strokes (a first depth or degression too small)") from None
    levels = [rfp, *depths]
    if any(levels[i] - levels[i + 1] < c.mdep - STROKE_EPS for i in range(len(levels) - 2)):
        raise p.bad("with a minimum drilling depth _MDEP larger than its strokes (how the cycle then divides the "
                    "depth is not read)")
    steps: list[Step] = [(RAPID_STEP, start)]
    if frf != 1.0:
        steps.append((TEXT_STEP, "F" + number_text(feed * frf)))
    back = (vrt or CHIP_BREAK_MM / unit_mm)
    depth_mm = (rfp - bottom) * unit_mm
    ahead = dis1 or (ANTICIPATION_MM if depth_mm <= ANTICIPATION_DEPTH_MM
                     else min(depth_mm / 50.0, ANTICIPATION_MAX_MM)) / unit_mm
    for k, depth in enumerate(depths):
        if k > 0:
            last = depths[k - 1]
            if vari == 0.0:
                steps.append((FEED_STEP, min(last + back, start)))
            else:
                steps.append((RAPID_STEP, start))
                if dts:
                    steps.append((DWELL_STEP, dts))
                steps.append((RAPID_STEP, min(last + ahead, start)))
        steps.append((FEED_STEP, depth))
        if k == 0 and frf != 1.0:
            steps.append((TEXT_STEP, "F" + number_text(feed)))  # the next strokes at the programmed feed
        pause = dtd if k == len(depths) - 1 else dtb
        if pause:
            steps.append((DWELL_STEP, pause))
    return steps, dtd or None, False
