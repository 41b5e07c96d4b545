"""The moves of a Sinumerik drilling cycle (``CYCLE81``, ``CYCLE82``, ``CYCLE89``), as the
SINUMERIK 840D Programming Guide Cycles (chapter 2, "Drilling cycles") describes them.

Every cycle drills at the position reached before it, along Z (G17), with parameters
RTP (retraction plane, absolute), RFP (reference plane, absolute), SDIS (safety distance,
without sign), DP (final depth, absolute) and DPR (final depth relative to RFP, without
sign; when both are given the depth comes from DPR: "Drilling, centering - CYCLE81"):

- CYCLE81(RTP, RFP, SDIS, DP, DPR): G0 to RFP + SDIS, G1 to the depth at the feed
  programmed before the call, G0 to RTP;
- CYCLE82(RTP, RFP, SDIS, DP, DPR, DTB): as CYCLE81 with the dwell DTB (seconds) at the
  depth ("Drilling, counterboring - CYCLE82");
- CYCLE89(RTP, RFP, SDIS, DP, DPR, DTB): G0 to RFP + SDIS, G1 to the depth, dwell DTB,
  G1 back to RFP + SDIS at the same feed, G0 to RTP ("Boring 5 - CYCLE89").

A modal call (``MCALL CYCLE81(...)``, section 2.2 "Modal call of drilling cycles") runs the
cycle after each block that moves an axis, until a bare ``MCALL``.
"""

from __future__ import annotations

from dataclasses import dataclass

from postproc.errors import GcodeSyntaxError
from postproc.gcode.sinumerik import CycleCall

#: the cycle's code in the interpreter's cycle numbering (G81 = 810, ...)
CODES = {"CYCLE81": 810, "CYCLE82": 820, "CYCLE89": 890}
RAPID_STEP, FEED_STEP, DWELL_STEP = "G0", "G1", "G4"


@dataclass(frozen=True)
class DrillPlan:
    """A cycle's levels (program Z) and steps: ``(kind, z)`` for G0/G1 to a level along Z,
    ``("G4", seconds)`` for a dwell."""

    code: int
    start_z: float  # RFP + SDIS: where the feed starts
    bottom_z: float
    clear_z: float  # RTP
    dwell_s: float | None
    steps: tuple[tuple[str, float], ...]


def drill_plan(call: CycleCall, path: str | None, lineno: int) -> DrillPlan:
    """The levels and steps of ``call`` in program units (work coordinates along Z)."""
    def arg(i: int) -> float | None:
        return call.args[i] if i < len(call.args) else None

    def bad(what: str) -> GcodeSyntaxError:
        return GcodeSyntaxError(f"Sinumerik {call.name} {what}", path=path, lineno=lineno, col=call.col)

    rtp, rfp, sdis, dp, dpr = (arg(i) for i in range(5))
    if rtp is None or rfp is None:
        raise bad("without its RTP (retraction plane) or RFP (reference plane)")
    sdis = abs(sdis or 0.0)
    if dpr:
        bottom = rfp - abs(dpr)  # DPR is entered without sign and wins over DP
    elif dp is not None:
        bottom = dp
    else:
        raise bad("without its final depth (DP or DPR)")
    if bottom > rfp + sdis or rtp < rfp:
        raise bad("with its depth above its reference plane, or its retraction plane below it")
    start = rfp + sdis
    dwell = arg(5) if call.name in ("CYCLE82", "CYCLE89") else None
    steps: list[tuple[str, float]] = [(RAPID_STEP, start), (FEED_STEP, bottom)]
    if dwell:
        if dwell < 0:
            raise bad("with a dwell in spindle revolutions (DTB < 0), not read")
        steps.append((DWELL_STEP, dwell))
    if call.name == "CYCLE89":
        steps.append((FEED_STEP, start))
    steps.append((RAPID_STEP, rtp))
    return DrillPlan(CODES[call.name], start, bottom, rtp, dwell or None, tuple(steps))
