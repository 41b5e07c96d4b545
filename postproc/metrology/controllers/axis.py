"""What a controller's axis table can take from a calibration: the positioning error
of one axis along its own travel, per approach direction.

For axis ``a`` of a parametric calibration (formats.md signs: the tool point relative
to the workpiece) the error of the functional point along ``a`` when the axis
stands at ``t`` having approached it moving in + (up) or - (down) is::

    e_up(t)   = E<a>_<a>(t) + B(t) / 2        E<a>_<a>: the axis's positioning column
    e_down(t) = E<a>_<a>(t) - B(t) / 2        B: the backlash effect of the axis (its profile)

Everything else in the calibration (straightness, angular errors through the tool
vector, squareness, the positioning columns' dependence on the other axes, other
effects) is volumetric: an axis table cannot hold it, and it stays in the program
correction (``export --remainder``).
"""

from __future__ import annotations

import numpy as np

from postproc.calibration.axis_tables import AXES, COLUMNS
from postproc.calibration.tables import UNMEASURED_HALF_RANGE_MM
from postproc.effects.backlash import Backlash
from postproc.effects.composed import ComposedEngine
from postproc.engine.parametric import ParametricEngine
from postproc.errors import CalibrationError

#: Points per table interval at which an exported table is compared with the model.
CHECK_POINTS_PER_INTERVAL = 16
#: A range that is a whole number of steps up to float rounding (in steps) is taken
#: as whole: 300 mm in 25 mm steps is 12 intervals, not 13.
WHOLE_STEPS_SLACK = 1e-9


class AxisErrors:
    """Positioning error of one axis of a parametric calibration, per direction (mm)."""

    def __init__(self, cal, axis: str) -> None:
        engine = cal.engine
        base = engine.base if isinstance(engine, ComposedEngine) else engine
        if base.method != "parametric" or not isinstance(base, ParametricEngine):
            raise CalibrationError(
                f"a {base.method} calibration has no axis error tables to export",
                path=cal.path,
                hint="controller tables come from a parametric calibration: fit one from interferometer "
                     "runs or axis error tables ('postproc fit RUNS.csv -o CAL')",
            )
        self.cal, self.axis = cal, axis
        self.base: ParametricEngine = base
        self.k = AXES.index(axis)
        effects = engine.effects if isinstance(engine, ComposedEngine) else []
        self.backlash: list[Backlash] = [e for e in effects if isinstance(e, Backlash) and e.target == axis]
        self.other_effects = [e.name for e in effects if e not in self.backlash]
        self.lo, self.hi = (float(v) for v in engine.volume_mm[:, self.k])

    @property
    def column(self) -> str:
        """The positioning column's name in ISO 230-1 terms (EXX for X ...)."""
        return f"{COLUMNS[self.k]}{self.axis}"

    @property
    def measured(self) -> bool:
        """False when the calibration holds nothing along this axis (zero table, no backlash)."""
        x = self.base.tables.position_mm[self.axis]
        zero = not np.any(self.base.tables.column(self.axis, COLUMNS[self.k]))
        wide = x[0] <= -UNMEASURED_HALF_RANGE_MM and x[-1] >= UNMEASURED_HALF_RANGE_MM
        return not ((zero or wide) and not self.backlash)

    def nodes(self, merge_mm: float = 0.0) -> np.ndarray:
        """The calibration's own positions along the axis (table rows, reversal profile);
        positions closer than ``merge_mm`` are one (the first kept): a table read in um
        and runs in mm give 31.4 and 31.400000000000002, which a table printed to a
        nanometre would write twice."""
        xs = [self.base.tables.position_mm[self.axis]]
        for e in self.backlash:
            if "position_mm" in e.config:
                xs.append(np.asarray(e.config["position_mm"], dtype=float))
        x = np.unique(np.concatenate(xs))
        x = x[(x >= self.lo) & (x <= self.hi)]
        x = np.unique(np.concatenate([[self.lo], x, [self.hi]]))
        if merge_mm > 0 and len(x) > 1:
            keep = [0]
            for i in range(1, len(x)):
                if x[i] - x[keep[-1]] >= merge_mm:
                    keep.append(i)
            if x[-1] - x[keep[-1]] > 0 and keep[-1] != len(x) - 1:
                keep[-1] = len(x) - 1  # the range's end stays
            x = x[keep]
        return x

    def positioning(self, t) -> np.ndarray:
        return self.base.axis_errors(self.axis, t)[:, self.k]

    def reversal(self, t) -> np.ndarray:
        t = np.asarray(t, dtype=float).reshape(-1)
        out = np.zeros(len(t))
        for e in self.backlash:
            out += e.params["b_mm"] * e.profile(t)
        return out

    def up(self, t) -> np.ndarray:
        return self.positioning(t) + 0.5 * self.reversal(t)

    def down(self, t) -> np.ndarray:
        return self.positioning(t) - 0.5 * self.reversal(t)

    def linear_error(self, nodes, up_values, down_values) -> float:
        """Largest difference (mm) between a table read by linear interpolation between
        ``nodes`` and the model, over the axis range."""
        nodes = np.asarray(nodes, dtype=float)
        t = np.linspace(self.lo, self.hi, CHECK_POINTS_PER_INTERVAL * max(len(nodes) - 1, 1) + 1)
        du = np.interp(t, nodes, up_values) - self.up(t)
        dd = np.interp(t, nodes, down_values) - self.down(t)
        return float(max(np.abs(du).max(), np.abs(dd).max()))


# Most points of one axis's table: controllers hold hundreds to a few thousand
# (Fanuc 1024 pitch-error points in all, LinuxCNC's comp file is read whole at start).
MAX_TABLE_POINTS = 100_000


def equidistant(lo: float, hi: float, step: float) -> tuple[np.ndarray, float]:
    """Positions lo, lo + s, ..., hi with s <= step chosen so that the last one is hi."""
    if not step > 0:
        raise CalibrationError(f"table step {step:g} mm: must be positive")
    n = max(1, int(np.ceil(min((hi - lo) / step, 1e12) - WHOLE_STEPS_SLACK)))
    if n > MAX_TABLE_POINTS:
        raise CalibrationError(f"table step {step:g} mm makes {n:,} points over {hi - lo:g} mm: more than "
                               f"{MAX_TABLE_POINTS:,}, beyond any controller's table",
                               hint="give a --step of the spacing the controller's table holds (mm)")
    s = (hi - lo) / n
    return lo + s * np.arange(n + 1), s


def default_step(errors: AxisErrors) -> float:
    """The smallest spacing of the calibration's own positions along the axis."""
    nodes = errors.nodes()
    return float(np.diff(nodes).min()) if len(nodes) > 1 else 1.0


def mm(v: float, decimals: int = 6) -> str:
    """Fixed-point text, never '-0'."""
    s = f"{v:.{decimals}f}"
    return s[1:] if s.startswith("-") and float(s) == 0 else s
