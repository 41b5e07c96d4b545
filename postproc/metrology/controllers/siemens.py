"""Siemens SINUMERIK leadscrew / measuring-system error compensation (LEC) as a part
program of ``$AA_ENC_COMP`` system variables (function manual K3, "Interpolatory
compensation").

``$AA_ENC_COMP[e, N, AXi]`` is the compensation value at interpolation point N of
measuring system e; the points lie ``$AA_ENC_COMP_STEP`` apart from
``$AA_ENC_COMP_MIN`` to ``$AA_ENC_COMP_MAX``; the first and last values hold beyond
the table. "A positive compensation value causes the corresponding machine axis to
move in the negative direction": the value is the error itself. The number of points
must not exceed MD38000 $MA_MM_ENC_COMP_MAX_POINTS; the function is enabled with
MD32700 ENC_COMP_ENABLE[e] = 1 and acts once the axis is referenced.

The table is zero at the reference point (K3: the compensation value at the reference
point should be zero, since referencing sets the axis's position there): the mean error
at the reference is a shift of the whole axis and stays in the program correction
(``--remainder``).

LEC is one table for both directions: it holds the mean bidirectional positioning
error. The reversal stays in the program correction (or goes to the backlash machine
data by hand, not both).
"""

from __future__ import annotations

import re

import numpy as np

from postproc.errors import CalibrationError, MeasurementError
from postproc.metrology.controllers.axis import AxisErrors, default_step, equidistant, mm
from postproc.metrology.controllers.base import Export
from postproc.metrology.controllers.formats import Settings
from postproc.metrology.controllers.roundtrip import check_round_trip

DEFAULT_AXIS_NAMES = {"X": "X1", "Y": "Y1", "Z": "Z1"}
#: Decimals of the values and positions written (mm).
DECIMALS = 6
#: Resolution of a value read back: the value and the positions (_MIN, _STEP) are each
#: rounded to DECIMALS.
RESOLUTION_MM = 10.0 ** -DECIMALS


def export_siemens(axis_errors: list[AxisErrors], *, step: float, reference_mm: dict[str, float],
                   encoder: int = 0, axis_names: dict[str, str] | None = None) -> Export:
    """The LEC program for ``axis_errors``, each zero at its reference point
    (``reference_mm``, required for every axis)."""
    names = {**DEFAULT_AXIS_NAMES, **(axis_names or {})}
    missing = [e.axis for e in axis_errors if e.axis not in reference_mm]
    if missing:
        raise CalibrationError(f"axis {', '.join(missing)}: a Siemens LEC table is zero at the reference point; "
                               "give its position", hint=f"--reference {missing[0]}=MM (the reference point "
                                                        "in machine coordinates, MD34100)")
    lines = ["%_N_AX_EEC_INI", "CHANDATA(1)"]
    exp = Export({})
    checks = []
    for e in axis_errors:
        x, s = equidistant(e.lo, e.hi, step)
        ref = reference_mm[e.axis]
        e_ref = float(e.positioning(np.clip([ref], e.lo, e.hi))[0])
        values = e.positioning(x) - e_ref
        ax = names[e.axis]
        checks.append((e, ax, e_ref))
        exp.offsets[e.axis] = e_ref
        lines.append(f"; {e.axis}: mean bidirectional positioning error {e.column} in mm, zero at the reference "
                     f"point {ref:.3f} mm")
        lines += [f"$AA_ENC_COMP[{encoder},{i},{ax}]={mm(v, DECIMALS)}" for i, v in enumerate(values)]
        lines += [f"$AA_ENC_COMP_STEP[{encoder},{ax}]={mm(s, DECIMALS)}",
                  f"$AA_ENC_COMP_MIN[{encoder},{ax}]={mm(x[0], DECIMALS)}",
                  f"$AA_ENC_COMP_MAX[{encoder},{ax}]={mm(x[-1], DECIMALS)}", f"$AA_ENC_COMP_IS_MODULO[{encoder},{ax}]=0"]
        exp.columns.add((e.axis, e.column[:2]))
        err = float(np.abs(np.interp(np.linspace(x[0], x[-1], 16 * len(x)), x, values)
                           - e.positioning(np.linspace(x[0], x[-1], 16 * len(x))) + e_ref).max())
        exp.notes.append(f"{e.axis} ({ax}): {len(x)} points, step {s:.4f} mm over {x[0]:.3f}..{x[-1]:.3f} mm "
                         f"(MD38000 $MA_MM_ENC_COMP_MAX_POINTS >= {len(x)}); linear interpolation stays within "
                         f"{err * 1000:.3f} um of the calibration; zero at the reference {ref:.3f} mm (the mean "
                         f"error there, {e_ref * 1000:+.3f} um, stays in --remainder)")
        if e.backlash:
            exp.notes.append(f"{e.axis}: the reversal (backlash:{e.axis}) is not in the LEC table: it stays in "
                             "the program correction; leave the backlash machine data MD32450 at 0")
    lines.append("M17")
    text = "\n".join(lines) + "\n"
    # round trip: the program read back as the control interpolates it, at every point
    back = read_siemens(text)
    for e, ax, e_ref in checks:
        x, v = back[ax]
        want = e.positioning(np.clip(x, e.lo, e.hi)) - e_ref
        check_round_trip(e.axis, "siemens", x, {"both": v}, {"both": want}, RESOLUTION_MM)
    exp.files["enc_comp.spf"] = text
    exp.notes.append("enable with MD32700 ENC_COMP_ENABLE[0] = 1; the table acts once the axis is referenced")
    return exp


_ASSIGN = re.compile(r"^\$AA_ENC_COMP(_STEP|_MIN|_MAX|_IS_MODULO)?\[([^\]]+)\]=(-?[0-9.]+)$")


def read_siemens(text: str, path: str = "") -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """{axis name: (positions mm, values mm)} from a $AA_ENC_COMP program."""
    values: dict[str, dict[int, float]] = {}
    meta: dict[str, dict[str, float]] = {}
    for lineno, line in enumerate(text.splitlines(), 1):
        line = line.split(";")[0].strip()
        if not line.startswith("$AA_ENC_COMP"):
            continue
        m = _ASSIGN.match(line)
        if not m:
            raise MeasurementError(f"cannot read {line!r}", path=path, lineno=lineno)
        kind, index, value = m.group(1) or "", m.group(2).split(","), float(m.group(3))
        if kind:
            meta.setdefault(index[-1], {})[kind] = value
        else:
            values.setdefault(index[-1], {})[int(index[1])] = value
    out = {}
    for ax, v in values.items():
        n = max(v) + 1
        x = meta[ax]["_MIN"] + meta[ax]["_STEP"] * np.arange(n)
        out[ax] = (x, np.array([v[i] for i in range(n)]))
    return out


def from_settings(axis_errors: list[AxisErrors], s: Settings) -> Export:
    """:func:`export_siemens` with ``export``'s settings (the registered builder): the
    table spacing defaults to the calibration's smallest."""
    step = s.step_mm if s.step_mm is not None else min(default_step(e) for e in axis_errors)
    return export_siemens(axis_errors, step=step, reference_mm=s.reference_mm, axis_names=s.axis_names)
