"""Reading chain and operation description files (JSON, see ``docs/predict.md``).

An operation file names the machine (a chain file, path relative to the operation
file) and says what is machined:

- ``"kind": "bore"``: a hole bored by a single-point tool (seed 004): diameter the
  tool is set to, tool overhang, spindle axis, nominal centre and its +- tolerances,
  optionally the diameter's limits;
- ``"kind": "flank"``: a wall cut by the flank of an end mill (seed 002): cutter,
  spindle speed, feed, optional spindle runout;
- ``"kind": "point"``: one tool point at given axis positions, with a nominal
  position and +- tolerances, for a tolerance analysis of any chain.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from postproc.errors import PostprocError
from postproc.predict.chain import Chain, chain_from_dict
from postproc.predict.tools import Cutter

OPERATION_FORMAT = "postproc operation"
KINDS = ("bore", "flank", "point")


def read_json(path) -> Any:
    """Parse a JSON file, naming the line and column of a syntax error."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise PostprocError(f"cannot read: {exc.strerror}", path=str(p), hint="check the file name") from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise PostprocError(f"not valid JSON: {exc.msg}", path=str(p), lineno=exc.lineno, col=exc.colno) from None
    except (ValueError, RecursionError) as exc:  # a number of over 4300 digits; nesting too deep
        from postproc.calfile import _json_limit

        raise PostprocError(f"not JSON postproc can read: {_json_limit(exc)}", path=str(p)) from None


def load_chain(path) -> Chain:
    """Chain description file -> :class:`Chain` (errors name the file and the element)."""
    data = read_json(path)
    try:
        chain = chain_from_dict(data, where="chain", base_dir=Path(path).parent)
    except PostprocError as exc:
        raise exc.at(str(path)) from None
    chain.path = str(path)
    return chain


def _number(data: Mapping, key: str, where: str, default: float | None = None, positive: bool = True) -> float:
    value = data.get(key, default)
    if isinstance(value, bool) or not isinstance(value, int | float) or not np.isfinite(value):
        raise PostprocError(f"{where}: \"{key}\" must be a number, got {value!r}")
    if positive and value <= 0:
        raise PostprocError(f"{where}: \"{key}\" must be positive, got {value!r}")
    return float(value)


def _numbers(data: Mapping, key: str, where: str, n: int, default=None, positive: bool = False) -> np.ndarray:
    value = data.get(key, default)
    ok = isinstance(value, list) and len(value) == n and all(
        isinstance(v, int | float) and not isinstance(v, bool) and np.isfinite(v) and (v > 0 or not positive)
        for v in value)
    if not ok:
        what = "positive numbers" if positive else "numbers"
        raise PostprocError(f"{where}: \"{key}\" must be a list of {n} {what}, got {value!r}")
    return np.asarray(value, dtype=float)


@dataclass
class Operation:
    """A machining operation on a machine chain; ``params`` holds the kind's fields."""

    kind: str
    chain: Chain
    name: str = ""
    context: dict[str, float] = field(default_factory=dict)
    params: dict[str, Any] = field(default_factory=dict)
    path: str | None = None


def _object(data: Mapping, key: str, where: str) -> Mapping:
    """The optional sub-object ``key`` of ``data`` (empty when absent)."""
    value = data.get(key, {})
    if not isinstance(value, Mapping):
        raise PostprocError(f'{where}: "{key}" must be an object, got {value!r}')
    return value


def operation_from_dict(data: Any, base_dir: Path, where: str = "operation", chain: Chain | None = None) -> Operation:
    """An operation from its JSON data; ``chain``, when given, is the machine instead of its "machine"."""
    if not isinstance(data, Mapping) or data.get("format") != OPERATION_FORMAT:
        raise PostprocError(f'{where}: not an operation description: "format" must be "{OPERATION_FORMAT}"')
    kind = data.get("kind")
    if kind not in KINDS:
        raise PostprocError(f"{where}: \"kind\" must be one of {', '.join(KINDS)}, got {kind!r}")
    machine = data.get("machine")
    if chain is not None:
        pass
    elif isinstance(machine, str):
        chain = load_chain(base_dir / machine)
    elif isinstance(machine, Mapping):
        chain = chain_from_dict(machine, where=f"{where}: machine", base_dir=base_dir)
    else:
        raise PostprocError(f'{where}: "machine" must be a chain file name or an embedded chain')
    context = data.get("context", {})
    if not isinstance(context, Mapping) or not all(
        isinstance(v, int | float) and not isinstance(v, bool) and np.isfinite(v) for v in context.values()
    ):
        raise PostprocError(f'{where}: "context" must map variable names to finite numbers')
    params: dict[str, Any] = {}
    mc = _object(data, "monte_carlo", where)
    params["n"] = int(_number(mc, "n", f"{where}: monte_carlo", 10000))
    params["seed"] = int(_number(mc, "seed", f"{where}: monte_carlo", 0, positive=False))
    if kind == "bore":
        params["diameter_mm"] = _number(data, "diameter_mm", where)
        # the tip's distance from the spindle frame's origin along +axis; negative for a
        # tool pointing along -axis (a vertical mill's tool hanging down)
        params["overhang_mm"] = _number(data, "overhang_mm", where, positive=False)
        params["axis"] = str(data.get("axis", "x")).lower()
        if params["axis"] not in ("x", "y", "z"):
            raise PostprocError(f'{where}: "axis" must be x, y or z')
        params["nominal_centre_mm"] = _numbers(data, "nominal_centre_mm", where, 2)
        params["tolerance_mm"] = _numbers(data, "tolerance_mm", where, 2, positive=True)
        params["spindle_var"] = str(data.get("spindle_var", "S"))
        if "diameter_limits_mm" in data:
            lim = _numbers(data, "diameter_limits_mm", where, 2)
            if lim[0] > lim[1]:
                raise PostprocError(f'{where}: "diameter_limits_mm" must be [smallest, largest]')
            params["diameter_limits_mm"] = lim
    elif kind == "point":
        params["tool_point_mm"] = _numbers(data, "tool_point_mm", where, 3)
        params["nominal_mm"] = _numbers(data, "nominal_mm", where, 3)
        params["tolerance_mm"] = _numbers(data, "tolerance_mm", where, 3, positive=True)
    else:
        cut = data.get("cutter")
        if not isinstance(cut, Mapping):
            raise PostprocError(f'{where}: "cutter" must be an object')
        params["cutter"] = Cutter(
            str(cut.get("kind", "cylindrical")),
            _number(cut, "d_mm", f"{where}: cutter"),
            _number(cut, "pitch_mm", f"{where}: cutter") if "pitch_mm" in cut else float("inf"),
            _number(cut, "length_mm", f"{where}: cutter", 1.0),
            _number(cut, "D_mm", f"{where}: cutter", cut.get("d_mm", 1.0)),
            int(_number(cut, "flutes", f"{where}: cutter", 1)),
        )
        params["rpm"] = _number(data, "rpm", where)
        params["feed_mm_min"] = _number(data, "feed_mm_min", where)
        params["heights"] = int(_number(data, "heights", where, 41))
        run = _object(data, "runout", where)
        params["runout_rad"] = _number(run, "amplitude_rad", f"{where}: runout", 0.0, positive=False)
        params["runout_phase_rad"] = _number(run, "phase_rad", f"{where}: runout", 0.0, positive=False)
    return Operation(kind, chain, str(data.get("name", "")), dict(context), params)


def load_operation(path, machine=None) -> Operation:
    """Operation file -> :class:`Operation`, with its machine chain loaded (``machine``:
    a chain file to use instead of the operation's own)."""
    p = Path(path)
    data = read_json(p)
    chain = None if machine is None else load_chain(machine)
    try:
        op = operation_from_dict(data, p.parent, chain=chain)
    except PostprocError as exc:
        raise exc.at(str(p)) from None
    op.path = str(p)
    if op.chain.path is None:  # embedded in the operation file
        op.chain.path = op.path
    return op
