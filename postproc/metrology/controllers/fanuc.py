"""Fanuc bidirectional pitch error compensation (Series 16i/18i/0i, technical report
A-77810E and the parameter manuals, parameters 3605-3627).

The compensation points lie every ``interval`` (3624) from the reference position.
Point number ``n`` holds the *incremental* compensation, in detection units times
the magnification (3623), output while the axis crosses the section that ends at
``reference + (n - n_ref) * interval`` (n_ref = 3620): so the farthest point on the
- side is ``n_ref - (stroke on the - side) / interval + 1`` (3621), on the + side
``n_ref + (stroke on the + side) / interval`` (3622). Bidirectional compensation
(3605#0 = 1) holds a second table for travel in the - direction, starting at 3626,
with as many points, and 3627 is the absolute compensation at the reference
position when it is approached against the reference return direction.

A compensation is what the control adds to the command, minus the error; the table
is zero at the reference position in the reference return direction (the reference
return defines the machine zero), so the error there is taken as the zero.

The file is a parameter tape: ``N<parameter> A<axis> P<value>`` for the axis
parameters and ``N<10000 + point> P<value>`` for the pitch data.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from postproc.errors import CalibrationError, MeasurementError
from postproc.metrology.controllers.axis import WHOLE_STEPS_SLACK, AxisErrors, default_step
from postproc.metrology.controllers.base import Export
from postproc.metrology.controllers.formats import Settings
from postproc.metrology.controllers.roundtrip import check_round_trip

#: Pitch error data numbers on the parameter tape start here (N10000 = point 0).
PITCH_DATA_BASE = 10000
#: Range of one compensation value (Series 16i/18i/0i: -128..127 times the magnification).
VALUE_MIN, VALUE_MAX = -128, 127
MAX_MAGNIFICATION = 100
#: Points one axis may use between its farthest points (parameter manual).
MAX_POINTS_PER_AXIS = 128
#: Highest pitch error compensation point number of a typical 0i/16i memory.
MAX_POINT_NUMBER = 1023
DEFAULT_AXIS_NUMBERS = {"X": "1", "Y": "2", "Z": "3"}
#: A reference closer than this (mm) to the end of the axis the return cannot reach
#: from is taken as that end (a micrometre: below any reference setting).
REACH_SLACK_MM = 1e-3


def _grid(e: AxisErrors, reference: float, interval: float) -> np.ndarray:
    """Section ends reference + k * interval covering the axis range: k from kmin to kmax."""
    kmin = math.floor((e.lo - reference) / interval + WHOLE_STEPS_SLACK)
    kmax = math.ceil((e.hi - reference) / interval - WHOLE_STEPS_SLACK)
    return np.arange(min(kmin, 0), max(kmax, 0) + 1)


def check_reference(e: AxisErrors, reference: float, direction: int) -> None:
    """Refuse a reference position the reference return cannot reach: a return in +
    arrives from below, so there must be travel below the reference (it cannot be the
    axis's lower end), a return in - from above (not the upper end)."""
    if direction > 0 and reference <= e.lo + REACH_SLACK_MM:
        raise CalibrationError(
            f"axis {e.axis}: a reference return in + cannot reach the reference {reference:g} mm: it is at or "
            f"below the lower end of the axis ({e.lo:g} mm), and an axis reaches its lower end moving -",
            hint=f"give the reference and the return direction the control uses (parameters 1240 and 1006#5): "
                 f"e.g. --reference {e.axis}={e.hi:g} --return {e.axis}=+ or --reference {e.axis}={e.lo:g} "
                 f"--return {e.axis}=-")
    if direction < 0 and reference >= e.hi - REACH_SLACK_MM:
        raise CalibrationError(
            f"axis {e.axis}: a reference return in - cannot reach the reference {reference:g} mm: it is at or "
            f"above the upper end of the axis ({e.hi:g} mm), and an axis reaches its upper end moving +",
            hint=f"give the reference and the return direction the control uses (parameters 1240 and 1006#5): "
                 f"e.g. --reference {e.axis}={e.lo:g} --return {e.axis}=- or --reference {e.axis}={e.hi:g} "
                 f"--return {e.axis}=+")


def export_fanuc(axis_errors: list[AxisErrors], *, interval_mm: float, reference_mm: dict[str, float],
                 return_direction: dict[str, int], detection_unit_mm: float = 0.001,
                 axis_numbers: dict[str, str] | None = None, first_point: int = 0) -> Export:
    """The tape for ``axis_errors``; ``reference_mm`` and ``return_direction`` (+1 / -1)
    are required for every axis: no sign of the table comes from a default."""
    for e in axis_errors:
        missing = [w for w, d in (("--reference", reference_mm), ("--return", return_direction)) if e.axis not in d]
        if missing:
            raise CalibrationError(
                f"axis {e.axis}: a Fanuc table needs the reference position and the direction of the reference "
                f"return; missing {' and '.join(missing)}",
                hint=f"give --reference {e.axis}=MM --return {e.axis}=+|- as the control has them (parameters "
                     "1240 and 1006#5 ZMI), or --parameters with the control's parameter tape")
        check_reference(e, reference_mm[e.axis], return_direction[e.axis])
    numbers = {**DEFAULT_AXIS_NUMBERS, **(axis_numbers or {})}
    if not (detection_unit_mm > 0 and math.isfinite(interval_mm / detection_unit_mm)):
        raise CalibrationError(f"detection unit {detection_unit_mm * 1000:g} um: a positive length is needed "
                               f"that counts the interval {interval_mm:g} mm", hint="give --detection-unit in um, e.g. 1")
    interval_du = round(interval_mm / detection_unit_mm)
    if interval_du <= 0 or abs(interval_du - interval_mm / detection_unit_mm) > WHOLE_STEPS_SLACK * max(1, interval_du):
        raise CalibrationError(f"interval {interval_mm:g} mm is not a whole number of detection units "
                               f"({detection_unit_mm * 1000:g} um)", hint="give --step as a multiple of the detection unit")
    params: dict[int, list[tuple[str, int]]] = {}
    data: list[tuple[int, int]] = []
    exp = Export({})
    point = first_point
    checks = []
    for e in axis_errors:
        ref = reference_mm[e.axis]
        ret = return_direction[e.axis]
        ks = _grid(e, ref, interval_mm)
        x = ref + ks * interval_mm
        xc = np.clip(x, e.lo, e.hi)  # beyond the calibrated range the error is held at its end value
        up, down = e.up(xc), e.down(xc)
        zero = up if ret > 0 else down  # error at the reference, approached in the return direction
        e_ref = float(np.interp(ref, x, zero))
        # absolute compensations (detection units), then the magnification that fits the increments
        c_up, c_down = -(up - e_ref) / detection_unit_mm, -(down - e_ref) / detection_unit_mm
        mag = next((m for m in range(1, MAX_MAGNIFICATION + 1)
                    if all(VALUE_MIN <= v <= VALUE_MAX for c in (c_up, c_down) for v in np.diff(np.round(c / m)))),
                   None)
        if mag is None:
            raise CalibrationError(f"axis {e.axis}: the compensation changes too fast for one interval of "
                                   f"{interval_mm:g} mm", hint="give a smaller --step")
        a_up, a_down = np.round(c_up / mag).astype(int), np.round(c_down / mag).astype(int)
        i_ref = int(np.flatnonzero(ks == 0)[0])
        a_up -= a_up[i_ref] if ret > 0 else 0
        a_down -= a_down[i_ref] if ret < 0 else 0
        n_sections = len(ks) - 1
        if n_sections > MAX_POINTS_PER_AXIS:
            raise CalibrationError(f"axis {e.axis}: {n_sections} compensation points; a Fanuc axis takes at most "
                                   f"{MAX_POINTS_PER_AXIS}", hint="give a larger --step")
        # numbers from `point` on: the reference's own number first (it holds no data when the
        # reference is at the lower end), then the + table, then the - table
        plus_first = point + 1
        n_ref = plus_first - 1 - int(ks[0])
        minus_first = plus_first + n_sections
        for j in range(1, len(ks)):
            data.append((plus_first + j - 1, int(a_up[j] - a_up[j - 1])))
            data.append((minus_first + j - 1, int(a_down[j] - a_down[j - 1])))
        against = int(a_down[i_ref] if ret > 0 else a_up[i_ref])
        ax = numbers[e.axis]
        for num, value in ((3620, n_ref), (3621, plus_first), (3622, plus_first + n_sections - 1), (3623, mag),
                           (3624, interval_du), (3626, minus_first), (3627, against)):
            params.setdefault(num, []).append((ax, value))
        point = minus_first + n_sections
        exp.columns.add((e.axis, e.column[:2]))
        exp.offsets[e.axis] = e_ref
        if e.backlash:
            exp.backlash.add(e.axis)
        # what the table gives back, against the model, at the compensation points
        worst = max(np.abs(a_up * mag * detection_unit_mm + (up - e_ref)).max(),
                    np.abs(a_down * mag * detection_unit_mm + (down - e_ref)).max())
        exp.notes.append(
            f"{e.axis} (axis {ax}): reference {ref:.3f} mm = point {n_ref}, + table {plus_first}..{plus_first + n_sections - 1}, "
            f"- table {minus_first}..{minus_first + n_sections - 1}, interval {interval_du} detection units "
            f"({interval_mm:g} mm), magnification {mag}; rounding to detection units leaves "
            f"{worst * 1000:.3f} um at most; the error at the reference ({e_ref * 1000:+.3f} um) is the table's zero "
            f"(a shift of the whole axis: it stays in --remainder); reference return in {'+' if ret > 0 else '-'}")
        checks.append((e, ax, ref, ret, ks * interval_mm, up - e_ref, down - e_ref, mag * detection_unit_mm))
    if point - 1 > MAX_POINT_NUMBER:
        exp.notes.append(f"warning: the tables use point numbers up to {point - 1}; check the control's pitch "
                         f"memory (often 0..{MAX_POINT_NUMBER})")
    lines = ["%"]
    for num in sorted(params):
        lines.append(f"N{num}" + "".join(f"A{ax}P{v}" for ax, v in params[num]))
    for n, v in sorted(data):
        lines.append(f"N{PITCH_DATA_BASE + n}P{v}")
    lines.append("%")
    text = "\n".join(lines) + "\n"
    # round trip: the tape as the control sums it, every point, both directions
    tape_params, tape_data = read_fanuc(text)
    for e, ax, ref, ret, x_rel, err_up, err_down, unit in checks:
        x, c_up, c_down = fanuc_compensation(tape_params, tape_data, ax, detection_unit_mm, ret)
        if not np.allclose(x, x_rel, rtol=0, atol=detection_unit_mm):
            raise CalibrationError(f"round trip of the fanuc table of {e.axis}: the tape's points are not the "
                                   "table's; nothing written", hint="report it with the calibration file")
        # the compensation is minus the error relative to the reference (approached in the return direction)
        check_round_trip(e.axis, "fanuc", ref + x, {"+": c_up, "-": c_down}, {"+": -err_up, "-": -err_down},
                         0.5 * unit)
    exp.files["pitch.txt"] = text
    sides = ", ".join(f"{e.axis} in {'+' if ret > 0 else '-'} (1006#5 ZMI = {0 if ret > 0 else 1})"
                      for e, _, _, ret, *_ in checks)
    exp.notes.append(f"set 3605#0 (BDP) = 1 on each axis by hand (the tape leaves bit parameter 3605 alone); "
                     f"the table assumes the reference return {sides}: if the control returns otherwise, the "
                     "reversal is compensated with the wrong sign; set the backlash 1851/1852 to 0: the - table "
                     "already holds the reversal. Power off and on, then return to the reference position.")
    return exp


_WORD = re.compile(r"([NAP])(-?\d+)")
#: Reference position of the machine coordinate system, per axis (least input increment).
PARAM_REFERENCE = 1240
#: Bit parameter of the reference return direction: 1006#5 ZMI, 1 = return in -.
PARAM_RETURN, ZMI_BIT = 1006, 5
_PARAM_WORD = re.compile(r"([NAP])(-?[0-9]+)")


def read_reference_parameters(text: str, detection_unit_mm: float, path: str = ""
                              ) -> tuple[dict[str, float], dict[str, int]]:
    """The reference position (1240, mm) and reference return direction (1006#5 ZMI: 0
    in +, 1 in -) per axis number, from a control's parameter tape. Bit parameters are
    written as eight binary digits, bit 7 first (``N1006A1P00100000``); 1240 in detection
    units. Other parameters are skipped."""
    refs: dict[str, float] = {}
    dirs: dict[str, int] = {}
    for lineno, line in enumerate(text.splitlines(), 1):
        body = line.strip()
        if not body.startswith("N"):
            continue
        words = _PARAM_WORD.findall(body)
        if not words or "".join(a + b for a, b in words) != body:
            raise MeasurementError(f"not a parameter tape line: {body!r}", path=path, lineno=lineno, col=1)
        n = int(words[0][1])
        if n not in (PARAM_REFERENCE, PARAM_RETURN):
            continue
        axis = None
        for w, v in words[1:]:
            if w == "A":
                axis = str(int(v))
            elif w == "P" and axis is not None:
                if n == PARAM_REFERENCE:
                    refs[axis] = int(v) * detection_unit_mm
                else:
                    bits = v if len(v) == 8 and set(v) <= {"0", "1"} else format(int(v) & 0xFF, "08b")
                    dirs[axis] = -1 if bits[7 - ZMI_BIT] == "1" else 1
    return refs, dirs


def read_fanuc(text: str, path: str = "") -> tuple[dict[int, dict[str | None, int]], dict[int, int]]:
    """(axis parameters {number: {axis: value}}, pitch data {point: value}) from a tape;
    a value before any A word (a parameter that is not an axis's) is under the axis None."""
    params: dict[int, dict[str | None, int]] = {}
    data: dict[int, int] = {}
    for lineno, line in enumerate(text.splitlines(), 1):
        line = line.strip()
        if not line or line == "%":
            continue
        words = _WORD.findall(line)
        if not words or words[0][0] != "N" or "".join(a + b for a, b in words) != line:
            raise MeasurementError(f"not a parameter tape line: {line!r}", path=path, lineno=lineno)
        n = int(words[0][1])
        if n >= PITCH_DATA_BASE:
            data[n - PITCH_DATA_BASE] = int(words[1][1])
        else:
            axis: str | None = None
            for w, v in words[1:]:
                if w == "A":
                    axis = v
                else:
                    params.setdefault(n, {})[axis] = int(v)
    return params, data


def fanuc_compensation(params, data, axis: str, detection_unit_mm: float = 0.001,
                       return_direction: int = 1) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Positions relative to the reference (mm) and the absolute compensation (mm)
    moving + and moving -, rebuilt from the tape as the control sums it."""
    g = {num: params[num][axis] for num in params}
    n_ref, first, last, mag, interval, minus_first, against = (g[k] for k in (3620, 3621, 3622, 3623, 3624, 3626, 3627))
    ks = np.arange(first - 1 - n_ref, last - n_ref + 1)
    plus = np.array([data[n] for n in range(first, last + 1)])
    minus = np.array([data[n] for n in range(minus_first, minus_first + (last - first) + 1)])
    i_ref = int(np.flatnonzero(ks == 0)[0])
    c_up = np.concatenate([[0], np.cumsum(plus)])
    c_down = np.concatenate([[0], np.cumsum(minus)])
    c_up = c_up - c_up[i_ref] + (0 if return_direction > 0 else against)
    c_down = c_down - c_down[i_ref] + (against if return_direction > 0 else 0)
    unit = mag * detection_unit_mm
    return ks * interval * detection_unit_mm, c_up * unit, c_down * unit


def from_settings(axis_errors: list[AxisErrors], s: Settings) -> Export:
    """:func:`export_fanuc` with ``export``'s settings (the registered builder): the
    detection unit 1 um unless given; the interval the calibration's smallest spacing in
    whole detection units unless given; the reference and return direction of each axis
    the options leave open read from the control's parameter tape (1240, 1006#5)."""
    du = s.detection_unit_mm if s.detection_unit_mm is not None else 0.001
    interval = s.step_mm if s.step_mm is not None else max(du, round(min(default_step(e) for e in axis_errors) / du) * du)
    refs, returns = dict(s.reference_mm), dict(s.return_direction)
    if s.parameters:
        tape_refs, tape_dirs = read_reference_parameters(Path(s.parameters).read_text(encoding="utf-8-sig"), du,
                                                         path=s.parameters)
        numbers = {**DEFAULT_AXIS_NUMBERS, **s.axis_names}
        for e in axis_errors:
            n = numbers[e.axis]
            if e.axis not in refs and n in tape_refs:
                refs[e.axis] = tape_refs[n]
            if e.axis not in returns and n in tape_dirs:
                returns[e.axis] = tape_dirs[n]
    return export_fanuc(axis_errors, interval_mm=interval, detection_unit_mm=du, reference_mm=refs,
                        return_direction=returns, axis_numbers=s.axis_names)
