"""Axis error tables and squareness (formats.md section 2): the data, in mm and rad.

``AxisTables`` holds, for each axis X, Y, Z that has a table, the table positions (mm,
strictly increasing) and the six error columns ``EX, EY, EZ`` (mm) and ``EA, EB, EC``
(rad) at those positions. ``Squareness`` holds ``EC0Y, EB0Z, EA0Z`` (rad). Signs are
the formats.md ones (the effective 21-parameter model).

The parametric engine is built on them, and the virtual machine of
:mod:`postproc.simulate` holds its truth in them. Their files are read and written by
:mod:`postproc.calibration.tables`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from postproc.constants import MIN_TABLE_SPACING_MM
from postproc.errors import CalibrationError

AXES = ("X", "Y", "Z")
COLUMNS = ("EX", "EY", "EZ", "EA", "EB", "EC")
LINEAR_COLUMNS = COLUMNS[:3]
ANGULAR_COLUMNS = COLUMNS[3:]
SQUARENESS_NAMES = ("EC0Y", "EB0Z", "EA0Z")


@dataclass
class AxisTables:
    """Per-axis error tables: ``position_mm[axis]`` (n,), ``errors[axis]`` (n, 6).

    Error columns are ``EX, EY, EZ`` in mm and ``EA, EB, EC`` in rad. An axis without a
    table has no key (a virtual machine may leave an axis perfect); a calibration has
    all three (:attr:`volume_mm` refuses tables that lack one).
    """

    position_mm: dict[str, np.ndarray]
    errors: dict[str, np.ndarray]
    path: str | None = None

    def __post_init__(self) -> None:
        given = set(self.position_mm) | set(self.errors)
        unknown = sorted(given - set(AXES))
        if unknown:
            raise CalibrationError(f"axis error tables for unknown axis {unknown}: axes are X, Y, Z",
                                   path=self.path)
        pos, err = {}, {}
        for ax in AXES:
            if ax not in given:
                continue
            if ax not in self.position_mm or ax not in self.errors:
                raise CalibrationError(f"{ax} table has positions or errors but not both", path=self.path)
            x = np.asarray(self.position_mm[ax], dtype=float)
            e = np.asarray(self.errors[ax], dtype=float)
            if x.ndim != 1 or len(x) < 2 or e.shape != (len(x), 6):
                raise CalibrationError(
                    f"{ax} table: expected at least 2 positions and (n, 6) errors, "
                    f"got positions {x.shape} and errors {e.shape}",
                    path=self.path,
                )
            if not (np.all(np.isfinite(x)) and np.all(np.isfinite(e))):
                raise CalibrationError(f"{ax} table holds a value that is not finite", path=self.path)
            if np.any(np.diff(x) <= 0):
                raise CalibrationError(f"{ax} table positions are not strictly increasing", path=self.path)
            if np.any(np.diff(x) < MIN_TABLE_SPACING_MM):
                raise CalibrationError(f"{ax} table positions are closer than {MIN_TABLE_SPACING_MM * 1000:g} um: "
                                       "no table is measured that finely (a typing or unit mistake)", path=self.path)
            pos[ax], err[ax] = x, e
        self.position_mm, self.errors = pos, err

    @property
    def axes(self) -> tuple[str, ...]:
        """The axes that have a table, in X, Y, Z order."""
        return tuple(self.position_mm)

    def require_all(self) -> None:
        """Refuse (CalibrationError) tables that lack an axis."""
        for ax in AXES:
            if ax not in self.position_mm:
                raise CalibrationError(f"axis error tables have no {ax} axis", path=self.path)

    @property
    def volume_mm(self) -> np.ndarray:
        """Calibrated volume: the table ranges, [[xmin, ymin, zmin], [xmax, ymax, zmax]]."""
        self.require_all()
        return np.array([[self.position_mm[a][0] for a in AXES], [self.position_mm[a][-1] for a in AXES]])

    def column(self, axis: str, name: str) -> np.ndarray:
        return self.errors[axis][:, COLUMNS.index(name)]

    def at(self, axis: str, s) -> np.ndarray:
        """Errors (N, 6) of ``axis`` at its positions ``s`` (N,): linear between rows,
        the end rows held beyond the ends (what a controller does with its tables)."""
        s = np.asarray(s, dtype=float)
        x, e = self.position_mm[axis], self.errors[axis]
        return np.column_stack([np.interp(s, x, e[:, k]) for k in range(6)])

    def scaled(self, angle_factor: float = 1.0, length_factor: float = 1.0) -> AxisTables:
        """A copy with the angular (and/or linear) columns multiplied by a factor."""
        f = np.array([length_factor] * 3 + [angle_factor] * 3)
        return AxisTables(dict(self.position_mm), {a: self.errors[a] * f for a in self.axes}, self.path)

    def to_dict(self) -> dict:
        out = {}
        for ax in self.axes:
            d = {"position_mm": self.position_mm[ax].tolist()}
            for j, c in enumerate(COLUMNS):
                d[f"{c}_{'mm' if j < 3 else 'rad'}"] = self.errors[ax][:, j].tolist()
            out[ax] = d
        return out

    @classmethod
    def from_dict(cls, data: dict) -> AxisTables:
        pos, err = {}, {}
        for ax in AXES:
            if ax not in data:
                raise CalibrationError(f"parametric model has no {ax} table")
            d = data[ax]
            pos[ax] = np.asarray(d["position_mm"], dtype=float)
            err[ax] = np.column_stack(
                [np.asarray(d[f"{c}_{'mm' if j < 3 else 'rad'}"], dtype=float) for j, c in enumerate(COLUMNS)]
            )
        return cls(pos, err)


@dataclass
class Squareness:
    """Squareness errors in rad: EC0Y (Y to X), EB0Z (Z to X), EA0Z (Z to Y)."""

    EC0Y: float = 0.0
    EB0Z: float = 0.0
    EA0Z: float = 0.0
    path: str | None = field(default=None, compare=False)

    def as_dict(self) -> dict[str, float]:
        return {n: float(getattr(self, n)) for n in SQUARENESS_NAMES}

    def scaled(self, factor: float) -> Squareness:
        return Squareness(EC0Y=self.EC0Y * factor, EB0Z=self.EB0Z * factor, EA0Z=self.EA0Z * factor,
                          path=self.path)

    @classmethod
    def from_mapping(cls, values: Mapping[str, float], path: str | None = None) -> Squareness:
        """From ``{name: rad}``; a name that is not EC0Y, EB0Z or EA0Z is refused, a
        missing one is zero."""
        unknown = sorted(set(values) - set(SQUARENESS_NAMES))
        if unknown:
            raise CalibrationError(
                f"unknown squareness name(s) {unknown}: use {', '.join(SQUARENESS_NAMES)}", path=path
            )
        return cls(EC0Y=float(values.get("EC0Y", 0.0)), EB0Z=float(values.get("EB0Z", 0.0)),
                   EA0Z=float(values.get("EA0Z", 0.0)), path=path)
