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

LEC is one table for both directions: it holds the mean bidirectional positioning
error. The reversal stays in the program correction (or goes to the backlash machine
data by hand, not both).
"""

from __future__ import annotations

import re

import numpy as np

from postproc.errors import MeasurementError
from postproc.metrology.controllers.axis import AxisErrors, equidistant, mm
from postproc.metrology.controllers.base import Export

DEFAULT_AXIS_NAMES = {"X": "X1", "Y": "Y1", "Z": "Z1"}


def export_siemens(axis_errors: list[AxisErrors], *, step: float, encoder: int = 0,
                   axis_names: dict[str, str] | None = None) -> Export:
    names = {**DEFAULT_AXIS_NAMES, **(axis_names or {})}
    lines = ["%_N_AX_EEC_INI", "CHANDATA(1)"]
    exp = Export({})
    for e in axis_errors:
        x, s = equidistant(e.lo, e.hi, step)
        values = e.positioning(x)
        ax = names[e.axis]
        lines.append(f"; {e.axis}: mean bidirectional positioning error {e.column}, mm")
        lines += [f"$AA_ENC_COMP[{encoder},{i},{ax}]={mm(v)}" for i, v in enumerate(values)]
        lines += [f"$AA_ENC_COMP_STEP[{encoder},{ax}]={mm(s)}", f"$AA_ENC_COMP_MIN[{encoder},{ax}]={mm(x[0])}",
                  f"$AA_ENC_COMP_MAX[{encoder},{ax}]={mm(x[-1])}", f"$AA_ENC_COMP_IS_MODULO[{encoder},{ax}]=0"]
        exp.columns.add((e.axis, e.column[:2]))
        err = float(np.abs(np.interp(np.linspace(x[0], x[-1], 16 * len(x)), x, values)
                           - e.positioning(np.linspace(x[0], x[-1], 16 * len(x)))).max())
        exp.notes.append(f"{e.axis} ({ax}): {len(x)} points, step {s:.4f} mm over {x[0]:.3f}..{x[-1]:.3f} mm "
                         f"(MD38000 $MA_MM_ENC_COMP_MAX_POINTS >= {len(x)}); linear interpolation stays within "
                         f"{err * 1000:.3f} um of the calibration")
        if e.backlash:
            exp.notes.append(f"{e.axis}: the reversal (backlash:{e.axis}) is not in the LEC table: it stays in "
                             "the program correction; leave the backlash machine data MD32450 at 0")
    lines.append("M17")
    exp.files["enc_comp.spf"] = "\n".join(lines) + "\n"
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
