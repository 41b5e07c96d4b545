"""The virtual machine: a known truth that simulated instruments measure.

A machine is the effective 21-parameter model of formats.md (per-axis error tables
and three squareness constants), plus optional physical effects from
:mod:`postproc.effects` (backlash, lead-screw, thermal, load ...) and the noise of
the instruments that measure it. It is defined in a JSON file::

    {
      "format": "postproc machine",
      "version": 1,
      "name": "s500",
      "description": "free text",
      "units": {"length": "mm", "angle": "rad"},
      "volume_mm": [[0, 0, 0], [315, 315, 315]],       # travel (commanded q)
      "tables": "s500_tables.csv",                       # formats.md axis error tables,
                                                         #   path relative to this file, or inline
      "squareness": "s500_tables_squareness.csv",        # file, or {"EC0Y": .., "EB0Z": .., "EA0Z": ..}
      "rotation": "finite",                              # "finite" (Rodrigues) or "first" order
      "effects": [{"name": "backlash:X", "config": {}, "params": {...}}],
      "noise": {"tracker_mm": 0.005, "interferometer_length_mm": 0.0001,
                "interferometer_angle_rad": 1e-7, "squareness_rad": 5e-7}
    }

Inline tables are ``{"X": {"position": [...], "EX": [...], ..., "EC": [...]}, ...}``.
Between table positions the errors are interpolated linearly; beyond the ends the end
value is held. The forward model is formats.md's::

    p = q + rho(q) + R(eps(q)) r  (+ sum of effect displacements)
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from postproc.calibration.axis_tables import AXES, COLUMNS, AxisTables, Squareness
from postproc.calibration.tables import read_squareness, read_tables
from postproc.constants import MAX_VOLUME_MM, SOLVER_MAX_ITER, SOLVER_TOL_MM
from postproc.engine.base import Engine, InverseResult, check_points, check_tool_vectors
from postproc.errors import CalibrationError, PostprocError
from postproc.fileio import atomic_write_text
from postproc.rotation import cross, rotate

FORMAT = "postproc machine"
VERSION = 1
UNITS = {"length": "mm", "angle": "rad"}


class MachineError(CalibrationError):
    """A machine definition that is malformed or unusable."""


class MachineGeometry(Engine):
    """The geometric part of a virtual machine as an :class:`Engine` (truth, not a fit)."""

    method = "machine"
    affine = False

    def __init__(self, tables: AxisTables | Mapping[str, Any] | None, squareness: Squareness | Mapping[str, float] | None,
                 volume_mm, rotation: str = "finite") -> None:
        """``tables``: the axis error tables (None, or an empty mapping, for none at all);
        ``squareness``: a :class:`Squareness` or ``{name: rad}`` (missing names are 0)."""
        super().__init__(volume_mm)
        if rotation not in ("finite", "first"):
            raise MachineError(f"rotation {rotation!r}: use 'finite' or 'first'")
        if tables is None or (isinstance(tables, Mapping) and not tables):
            tables = AxisTables({}, {})
        if not isinstance(tables, AxisTables):
            raise MachineError(f"machine tables must be axis error tables, got {type(tables).__name__}")
        if not isinstance(squareness, Squareness):
            squareness = Squareness.from_mapping(squareness or {})
        self.tables = tables
        self.squareness = squareness
        self.rotation = rotation

    def errors_at(self, q) -> tuple[np.ndarray, np.ndarray]:
        """(rho (N, 3) mm, eps (N, 3) rad) at commanded positions q, formats.md signs."""
        q = check_points(q, "q")
        total = np.zeros((len(q), 6))
        for j, axis in enumerate(AXES):
            if axis in self.tables.axes:
                total += self.tables.at(axis, q[:, j])
        sq = self.squareness
        rho = total[:, :3].copy()
        rho[:, 0] += -sq.EC0Y * q[:, 1] + sq.EB0Z * q[:, 2]
        rho[:, 1] += -sq.EA0Z * q[:, 2]
        return rho, total[:, 3:]

    def forward(self, q, r=None, context=None) -> np.ndarray:
        q = check_points(q, "q")
        rr = check_tool_vectors(r, len(q))
        rho, eps = self.errors_at(q)
        if self.rotation == "first":
            return q + rho + rr + cross(eps, rr)
        return q + rho + rotate(eps, rr)

    def inverse(self, p, r=None, context=None) -> InverseResult:
        return fixed_point_inverse(self, p, r, context)

    def model_to_dict(self) -> dict:
        return {
            "tables": tables_to_dict(self.tables),
            "squareness": self.squareness.as_dict(),
            "rotation": self.rotation,
        }

    @classmethod
    def model_from_dict(cls, model: dict, volume_mm) -> MachineGeometry:
        tables = tables_from_dict(model.get("tables") or {})
        return cls(tables, model.get("squareness") or {}, volume_mm, model.get("rotation", "finite"))


def fixed_point_inverse(engine: Engine, p, r=None, context=None) -> InverseResult:
    """q with F(q, r) = p by q <- q - (F(q) - p): machine errors have slopes << 1."""
    p = check_points(p, "p")
    rr = check_tool_vectors(r, len(p))
    q = p - rr
    iters = np.zeros(len(p), dtype=int)
    for _ in range(SOLVER_MAX_ITER):
        err = engine.forward(q, rr, context) - p
        res = np.linalg.norm(err, axis=1)
        todo = res > SOLVER_TOL_MM
        if not todo.any():
            break
        q = q - err
        iters += todo
    res = np.linalg.norm(engine.forward(q, rr, context) - p, axis=1)
    return InverseResult(q, res, iters)


def tables_from_dict(data: dict) -> AxisTables:
    """Inline machine tables ``{"X": {"position": [...], "EX": [...], ...}, ...}``."""
    pos, err = {}, {}
    for axis, cols in data.items():
        missing = [c for c in ("position", *COLUMNS) if c not in cols]
        if missing:
            raise MachineError(f"inline table of axis {axis} has no {', '.join(missing)}")
        n = len(cols["position"])
        if any(len(cols[c]) != n for c in COLUMNS):
            raise MachineError(f"inline table of axis {axis}: columns differ in length")
        pos[axis] = cols["position"]
        err[axis] = np.column_stack([np.asarray(cols[c], dtype=float) for c in COLUMNS])
    return AxisTables(pos, err)


def tables_to_dict(tables: AxisTables) -> dict:
    """The inline form of :func:`tables_from_dict`."""
    return {a: {"position": tables.position_mm[a].tolist(),
                **{c: tables.errors[a][:, k].tolist() for k, c in enumerate(COLUMNS)}}
            for a in tables.axes}


@dataclass
class Noise:
    """Instrument noise, one standard deviation per reading.

    ``tracker_mm``: each coordinate of one tracker shot; ``interferometer_length_mm``
    and ``interferometer_angle_rad``: each table value; ``squareness_rad``: each
    squareness constant.
    """

    tracker_mm: float = 0.0
    interferometer_length_mm: float = 0.0
    interferometer_angle_rad: float = 0.0
    squareness_rad: float = 0.0

    @classmethod
    def from_dict(cls, data: dict | None) -> Noise:
        data = dict(data or {})
        names = set(cls.__dataclass_fields__)
        unknown = set(data) - names
        if unknown:
            raise MachineError(f"unknown noise entries {sorted(unknown)}: use {', '.join(sorted(names))}")
        values = {k: float(v) for k, v in data.items()}
        if any(v < 0 or not np.isfinite(v) for v in values.values()):
            raise MachineError("noise standard deviations must be finite and >= 0")
        return cls(**values)

    def to_dict(self) -> dict:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


@dataclass
class Machine:
    """A virtual machine: geometry (truth) + effects + instrument noise.

    ``forward(q, r, context)`` is where the functional point really goes; ``model``
    is the geometry with the effects composed onto it (an :class:`Engine`).
    """

    geometry: MachineGeometry
    effects: list[dict] = field(default_factory=list)
    noise: Noise = field(default_factory=Noise)
    name: str = "machine"
    description: str = ""
    path: str | None = None

    def __post_init__(self) -> None:
        self.effects = [dict(e) for e in self.effects]
        if self.effects:
            from postproc.effects import compose  # only machines with effects need them

            self.model: Engine = compose(self.geometry, self.effects)
        else:
            self.model = self.geometry

    @property
    def volume_mm(self) -> np.ndarray:
        return self.geometry.volume_mm

    def forward(self, q, r=None, context=None) -> np.ndarray:
        """Actual functional-point positions (N, 3), noise-free."""
        return self.model.forward(q, r, context)

    def inverse(self, p, r=None, context=None) -> InverseResult:
        """The machine's exact inverse: what a perfect calibration would command."""
        return self.model.inverse(p, r, context)

    def to_dict(self, *, tables=None, squareness=None) -> dict:
        """JSON data; ``tables``/``squareness`` may name files to refer to instead of inlining."""
        model = self.geometry.model_to_dict()
        return {
            "format": FORMAT,
            "version": VERSION,
            "name": self.name,
            "description": self.description,
            "units": dict(UNITS),
            "volume_mm": self.volume_mm.tolist(),
            "tables": tables if tables is not None else model["tables"],
            "squareness": squareness if squareness is not None else model["squareness"],
            "rotation": self.geometry.rotation,
            "effects": self.effects,
            "noise": self.noise.to_dict(),
        }


def machine_from_dict(data, *, path: str | None = None) -> Machine:
    """Build a Machine from its JSON data; file references are relative to ``path``."""
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise MachineError('not a machine definition (no "format": "postproc machine")', path=path,
                           hint="see docs/virtual-machine.md for the layout")
    if data.get("version") != VERSION:
        raise MachineError(f"machine version {data.get('version')!r} is not supported (this reads {VERSION})",
                           path=path)
    if data.get("units", UNITS) != UNITS:
        raise MachineError(f"machine units {data.get('units')!r}: expected {UNITS}", path=path)
    if "volume_mm" not in data:
        raise MachineError("machine has no 'volume_mm' (travel)", path=path)
    base = Path(path).parent if path else Path(".")
    try:
        tables = data.get("tables") or {}
        if isinstance(tables, str):
            tables = read_tables(base / tables)
        else:
            tables = tables_from_dict(tables)
        sq = data.get("squareness") or {}
        if isinstance(sq, str):
            sq = read_squareness(base / sq)
        geometry = MachineGeometry(tables, sq, data["volume_mm"], data.get("rotation", "finite"))
        if not np.all(np.abs(geometry.volume_mm) <= MAX_VOLUME_MM):
            raise MachineError(f"machine volume_mm {geometry.volume_mm.tolist()} reaches beyond "
                               f"{MAX_VOLUME_MM / 1000:g} m: no machine is that large",
                               hint="volume_mm holds the machine's travel in mm")
        return Machine(
            geometry=geometry,
            effects=list(data.get("effects") or []),
            noise=Noise.from_dict(data.get("noise")),
            name=str(data.get("name") or (Path(path).stem if path else "machine")),
            description=str(data.get("description") or ""),
            path=path,
        )
    except PostprocError as exc:
        raise exc.at(path=path) from None
    except (TypeError, ValueError, KeyError, AttributeError) as exc:
        raise MachineError(f"malformed machine definition: {type(exc).__name__}: {exc}", path=path) from None


def load_machine(path) -> Machine:
    """Read a machine definition file (JSON, ``"format": "postproc machine"``)."""
    path = str(path)
    try:
        raw = Path(path).read_text(encoding="utf-8")
    except OSError as exc:
        raise MachineError(f"cannot read machine definition: {exc.strerror}", path=path) from None
    except UnicodeDecodeError as exc:
        raise MachineError(f"machine definition is not UTF-8 text ({exc.reason})", path=path) from None
    try:
        data = json.loads(raw)
    except json.JSONDecodeError as exc:
        raise MachineError(f"machine definition is not valid JSON: {exc.msg}", path=path,
                           lineno=exc.lineno, col=exc.colno) from None
    except (ValueError, RecursionError) as exc:  # a number of over 4300 digits; nesting too deep
        from postproc.calfile import _json_limit

        raise MachineError(f"machine definition is not JSON postproc can read: {_json_limit(exc)}",
                           path=path) from None
    return machine_from_dict(data, path=path)


def save_machine(path, machine: Machine, *, tables=None, squareness=None) -> None:
    """Write ``machine`` as JSON atomically (tables inline unless file names are given)."""
    text = json.dumps(machine.to_dict(tables=tables, squareness=squareness), indent=2)
    atomic_write_text(path, text + "\n")
