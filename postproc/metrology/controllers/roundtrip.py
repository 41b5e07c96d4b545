"""Every export ends with a round trip: the written table, read back by our model of the
controller (LinuxCNC's comp loader, Fanuc's pitch-error summation, Siemens' LEC
interpolation, TF5280's ISG CSV reader), must give back the calibration's correction at
every table point, in both approach directions, within the table's resolution (the
rounding of the numbers written). Otherwise nothing is written: a table whose sign,
zero or order the controller would read differently is refused before it reaches a
machine.
"""

from __future__ import annotations

import numpy as np

from postproc.errors import CalibrationError

#: Float slack on top of a table's resolution (mm): sums and differences of values
#: rounded to the resolution carry a few ulps of a millimetre-sized number.
FLOAT_SLACK_MM = 1e-9


def check_round_trip(axis: str, fmt: str, x, got: dict[str, np.ndarray], want: dict[str, np.ndarray],
                     resolution_mm: float) -> float:
    """Largest |got - want| (mm) over the points ``x`` and the directions in ``got``
    ('+', '-' or 'both'); raises when it exceeds ``resolution_mm`` (plus float slack),
    naming the worst point."""
    x = np.asarray(x, dtype=float)
    worst = 0.0
    where: tuple[float, str, float, float] = (float("nan"), "", float("nan"), float("nan"))
    for d, g in got.items():
        diff = np.abs(np.asarray(g, dtype=float) - np.asarray(want[d], dtype=float))
        if len(diff) != len(x):
            raise CalibrationError(f"round trip of the {fmt} table of {axis}: {len(diff)} values read back "
                                   f"for {len(x)} points; nothing written")
        i = int(np.argmax(diff)) if len(diff) else 0
        if len(diff) and diff[i] > worst:
            worst, where = float(diff[i]), (float(x[i]), d, float(np.asarray(g)[i]), float(np.asarray(want[d])[i]))
    if worst > resolution_mm + FLOAT_SLACK_MM:
        at, side_key, g_at, w_at = where
        side = {"+": "moving +", "-": "moving -"}.get(side_key, "")
        raise CalibrationError(
            f"round trip of the {fmt} table of {axis}: read back as the controller reads it, the table gives "
            f"{g_at * 1000:+.4f} um at {at:.4f} mm {side} where the calibration asks {w_at * 1000:+.4f} um "
            f"(off by {worst * 1000:.4f} um, more than the table's resolution {resolution_mm * 1000:.4f} um); "
            "nothing written",
            hint="this is a defect of the export: report it with the calibration file")
    return worst
