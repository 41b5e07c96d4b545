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
    """``prefix + fmt(v, d)`` for each value and its number of decimals (in one ``%``
    over all the values where they share their decimals)."""
    n = len(values)
    if n == 0:
        return []
    d = decimals[0]
    for k in range(n):
        if decimals[k] != d:
            return [prefix + fmt(values[k], decimals[k]) for k in range(n)]
    for v in values:
        if not math.isfinite(v):
            raise ValueError(f"cannot write {v} into a program")
    texts = ((prefix + "%." + str(d) + "f\n") * n % tuple(values)).split("\n")
    texts.pop()
    low = -(10.0 ** -d)  # a value above it and not above 0 may be written -0.000
    for k in range(n):
        v = values[k]
        if v <= 0.0 and v > low:
            texts[k] = prefix + fmt(v, d)
    return texts
