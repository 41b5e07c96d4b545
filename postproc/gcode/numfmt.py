"""The one number formatter of the writers: fixed point, explicit decimals, never ``-0``.

Compiled at install by mypyc with the scanner (``setup.py``); runs unchanged uncompiled.
It imports nothing of the package, so that it compiles on its own.
"""

from __future__ import annotations

import math


def fmt(value: float, decimals: int) -> str:
    """Fixed-point text of ``value`` with ``decimals`` digits (correctly rounded, as
    ``%.*f`` is); ``-0.000`` becomes ``0.000``; a non-finite value is refused."""
    text = "%.*f" % (decimals, value)  # noqa: UP031  (the fastest fixed-point formatting)
    if text[0] == "-" and not text.strip("-0."):
        return text[1:]
    if not math.isfinite(value):
        raise ValueError(f"cannot write {value} into a program")
    return text


def fmt_all(values: list[float], decimals: list[int], prefix: str) -> list[str]:
    """``prefix + fmt(v, d)`` for each value and its number of decimals."""
    out: list[str] = []
    for k in range(len(values)):
        out.append(prefix + fmt(values[k], decimals[k]))
    return out
