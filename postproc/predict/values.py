"""Parameter values of a chain description: numbers, variables and simple functions.

A value in a chain file is one of

- a number: ``0.012``;
- a variable name, optionally negated: ``"X"``, ``"-g1"`` (a machine axis, time ``t``,
  a load, or a random variable of a tolerance analysis);
- ``{"var": "X", "table": {"positions": [...], "values": [...]}}``: linear
  interpolation in the variable (constant beyond the ends), e.g. an error table;
- ``{"var": "load", "poly": [c0, c1, c2]}``: ``c0 + c1 v + c2 v^2``;
- ``{"var": "t", "sine": {"amplitude": A, "omega": w, "phase": f}}``: ``A sin(w v + f)``
  (``w`` in rad per unit of the variable);
- ``{"sum": [value, value, ...]}``: the sum of values (e.g. one error term from
  several axes' tables); ``{"product": [value, ...]}``: their product (e.g. an
  amplitude given as a variable times a sine);
- ``{"scale": k, "of": value}``: ``k * value``.

Values are evaluated against an environment mapping names to scalars or (N,) arrays.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from postproc.errors import PostprocError

FUNCTIONS = ("table", "poly", "sine")


def _fail(where: str, message: str, hint: str | None = None) -> PostprocError:
    return PostprocError(f"{where}: {message}", hint=hint)


def _is_number(x: Any) -> bool:
    """A finite JSON number (``true``/``false`` are not numbers here)."""
    return isinstance(x, int | float) and not isinstance(x, bool) and bool(np.isfinite(x))


def _numbers(data: Any, key: str, where: str) -> np.ndarray:
    """``data[key]`` as a 1-D array of finite numbers, or raise naming ``key``."""
    items = data.get(key) if isinstance(data, Mapping) else None
    if not isinstance(items, list) or not items or not all(_is_number(v) for v in items):
        raise _fail(where, f'table "{key}" must be a non-empty list of finite numbers, got {items!r}')
    return np.asarray(items, dtype=float)


def check_value(spec: Any, where: str) -> None:
    """Raise PostprocError if ``spec`` is not a valid value description."""
    if isinstance(spec, bool):
        raise _fail(where, f"expected a number, a variable name or a function, got {spec!r}")
    if isinstance(spec, int | float):
        if not np.isfinite(spec):
            raise _fail(where, f"value must be finite, got {spec!r}")
        return
    if isinstance(spec, str):
        name = spec[1:] if spec.startswith("-") else spec
        if not name.strip():
            raise _fail(where, "empty variable name")
        return
    if not isinstance(spec, Mapping):
        raise _fail(where, f"expected a number, a variable name or a function, got {spec!r}")
    for key in ("sum", "product"):
        if key in spec:
            if not isinstance(spec[key], list) or not spec[key]:
                raise _fail(where, f'"{key}" must be a non-empty list of values')
            for i, item in enumerate(spec[key]):
                check_value(item, f"{where}.{key}[{i}]")
            return
    if "scale" in spec:
        if not _is_number(spec["scale"]) or "of" not in spec:
            raise _fail(where, 'expected {"scale": finite number, "of": value}')
        check_value(spec["of"], f"{where}.of")
        return
    kinds = [k for k in FUNCTIONS if k in spec]
    var = spec.get("var")
    if len(kinds) != 1 or not isinstance(var, str) or not var.strip():
        raise _fail(
            where,
            f"a function value needs \"var\" (a variable name) and one of {', '.join(FUNCTIONS)}, "
            f"got keys {sorted(spec)}",
            hint='e.g. {"var": "X", "table": {"positions": [0, 100], "values": [0, 0.002]}}',
        )
    _check_function(kinds[0], spec[kinds[0]], where)


def _check_function(kind: str, body: Any, where: str) -> None:
    """Raise PostprocError if ``body`` is not a valid ``table``, ``poly`` or ``sine``."""
    if kind == "table":
        pos = _numbers(body, "positions", where)
        val = _numbers(body, "values", where)
        if pos.shape != val.shape:
            raise _fail(where, f'table needs as many "values" as "positions", got {len(val)} and {len(pos)}')
        if np.any(np.diff(pos) <= 0):
            raise _fail(where, "table positions must increase strictly")
    elif kind == "poly":
        if not isinstance(body, list) or not body or not all(_is_number(c) for c in body):
            raise _fail(where, "poly must be a non-empty list of finite coefficients [c0, c1, ...]")
    else:
        if not isinstance(body, Mapping) or not all(
            _is_number(body.get(k, 0.0)) for k in ("amplitude", "omega", "phase")
        ):
            raise _fail(where, 'sine needs finite numbers "amplitude", "omega" and optionally "phase"')


def variable(env: Mapping[str, Any], name: str, where: str) -> np.ndarray:
    """Look a variable up in ``env`` or raise naming it."""
    if name not in env:
        known = ", ".join(sorted(env)) or "none"
        raise _fail(
            where,
            f"variable {name!r} is not set",
            hint=f"give it in the operation's \"context\" or as a random variable (set: {known})",
        )
    return np.asarray(env[name], dtype=float)


def evaluate(spec: Any, env: Mapping[str, Any], where: str = "value") -> np.ndarray:
    """Value of ``spec`` in ``env``: a scalar or an array broadcast from the variables."""
    if isinstance(spec, int | float) and not isinstance(spec, bool):
        return np.asarray(float(spec))
    if isinstance(spec, str):
        if spec.startswith("-"):
            return -variable(env, spec[1:], where)
        return variable(env, spec, where)
    if isinstance(spec, Mapping):
        if "sum" in spec:
            total = np.asarray(0.0)
            for i, item in enumerate(spec["sum"]):
                total = total + evaluate(item, env, f"{where}.sum[{i}]")
            return total
        if "product" in spec:
            total = np.asarray(1.0)
            for i, item in enumerate(spec["product"]):
                total = total * evaluate(item, env, f"{where}.product[{i}]")
            return total
        if "scale" in spec:
            return float(spec["scale"]) * evaluate(spec["of"], env, f"{where}.of")
        x = variable(env, spec["var"], where)
        if "table" in spec:
            pos = np.asarray(spec["table"]["positions"], dtype=float)
            val = np.asarray(spec["table"]["values"], dtype=float)
            return np.interp(x, pos, val)
        if "poly" in spec:
            return np.polynomial.polynomial.polyval(x, np.asarray(spec["poly"], dtype=float))
        if "sine" in spec:
            body = spec["sine"]
            return float(body.get("amplitude", 0.0)) * np.sin(
                float(body.get("omega", 0.0)) * x + float(body.get("phase", 0.0))
            )
    check_value(spec, where)  # raises with the reason
    raise _fail(where, f"cannot evaluate {spec!r}")


def names_in(spec: Any) -> set[str]:
    """Variable names a value refers to."""
    if isinstance(spec, str):
        return {spec[1:] if spec.startswith("-") else spec}
    if isinstance(spec, Mapping):
        for key in ("sum", "product"):
            if key in spec:
                return set().union(*(names_in(s) for s in spec[key])) if spec[key] else set()
        if "scale" in spec:
            return names_in(spec["of"])
        return {spec["var"]} if isinstance(spec.get("var"), str) else set()
    return set()
