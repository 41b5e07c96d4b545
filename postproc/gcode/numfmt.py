"""The one number formatter of the writers: fixed point, explicit decimals, never ``-0``;
and the writers' rules for a word's number (:func:`word_text`, :func:`added_text`,
:func:`reached`), one for every line, whichever writer writes it.

Compiled at install by mypyc with the scanner (``setup.py``); runs unchanged uncompiled.
It imports nothing of the package, so that it compiles on its own.
"""

from __future__ import annotations

import math
from typing import Final


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
    if decimals.count(d) != n:
        return [prefix + fmt(values[k], decimals[k]) for k in range(n)]
    if not math.isfinite(sum(values)):  # (finite values may overflow the sum: looked at one by one)
        for v in values:
            if not math.isfinite(v):
                raise ValueError(f"cannot write {v} into a program")
    text = (prefix + "%." + str(d) + "f\n") * n % tuple(values)
    texts = text.split("\n")
    texts.pop()
    # a value above -10^-d and not above 0 is written -0.000 or 0.000: where no -0.000 is
    # written, none is to be mended
    if ("-0." + "0" * d if d else "-0") + "\n" in text:
        low = -(10.0 ** -d)
        for k in range(n):
            v = values[k]
            if v <= 0.0 and v > low:
                texts[k] = prefix + fmt(v, d)
    return texts


#: half a unit of the last of d decimals, by d (beyond these, 0: below a double's smallest step)
_HALVES: Final = tuple(0.5 * 10.0 ** (-d) for d in range(330))


def half_unit(decimals: int) -> float:
    """Half a unit of the last of ``decimals`` digits; 0 beyond a double's smallest step
    (a word written with hundreds of decimals, kept as written)."""
    return _HALVES[decimals] if decimals < 330 else 0.0


def word_text(value: float, own: float, own_decimals: int, decimals: int) -> str:
    """The new number text of a word that is to carry ``value`` (program units) where
    it carries ``own`` (the value of its text, with ``own_decimals`` digits after the
    point): "" when ``value`` is within half an output step (``decimals``) of ``own``,
    so that the word keeps its text; else ``value`` with the output's decimals, or the
    word's own where it has more."""
    if abs(value - own) < half_unit(decimals):
        return ""
    return fmt(value, own_decimals if own_decimals > decimals else decimals)


def added_text(target: float, at: float, unit: float, value: float, decimals: int) -> str:
    """The number text of a word added for an axis a line does not name, whose
    corrected ``target`` (mm) differs from where the axis is (``at``, mm; NaN: never
    positioned) by half an output step (``decimals``, of ``unit`` mm) or more: ``value``
    (the word's, program units) with ``decimals`` digits; else "" (no word)."""
    if at != at or abs(target - at) / unit < half_unit(decimals):
        return ""
    return fmt(value, decimals)


def reached(text: str, value: float) -> float:
    """The value a word written as ``text`` (from ``value``) carries, as the controller
    reads it: ``float`` of the text (the formatter's digits are correctly rounded), a
    zero with ``value``'s sign."""
    r = float(text)
    return math.copysign(0.0, value) if r == 0.0 else r


def word_texts(values: list[float], own: list[float], own_decimals: list[int], decimals: list[int],
               into: tuple[list[str], list[int]] | None = None) -> tuple[list[int], list[str]]:
    """:func:`word_text` of each word: the indices of those whose text changes and their
    new texts (one :func:`fmt_all` over them). ``into`` (``texts``, ``at``): each new
    text is also put in ``texts`` at the place ``at`` gives its word."""
    changed: list[int] = []
    new: list[float] = []
    dout: list[int] = []
    d, half = -1, 0.0
    for k in range(len(values)):
        v, dk = values[k], decimals[k]
        if dk != d:
            d, half = dk, half_unit(dk)
        if not abs(v - own[k]) < half:
            changed.append(k)
            new.append(v)
            od = own_decimals[k]
            dout.append(od if od > dk else dk)
    texts = fmt_all(new, dout, "")
    if into is not None:
        dest, at = into
        for k in range(len(changed)):
            dest[at[changed[k]]] = texts[k]
    return changed, texts


#: 10**d as doubles, exact for d <= 22 (their products and quotients rounded once)
_POWERS: Final = tuple(10.0 ** d for d in range(23))
#: 2**52: at and beyond it every double is an integer
_TWO_52: Final = 4503599627370496.0


def round_to(x: float, d: int) -> float:
    """``round(x, d)``, equal to it bit for bit, without its decimal conversion where
    that is not needed. x 10^d rounded once to a double lies on the same side of every
    half as the exact product (rounding is monotonic and the halves below 2^52 are
    doubles), so where it is no half its nearest integer is the exact product's; that
    divided by 10^d (both exact, the quotient rounded once) is the double nearest the
    decimal, as round's conversion back gives. Python's ``round`` for the rest: a half,
    x 10^d at or over 2^52, d beyond 22 or below 0 (10^d no longer exact), not finite."""
    if 0 <= d <= 22:
        p = _POWERS[d]
        a = math.fabs(x * p)
        if a < _TWO_52:
            n = (a + _TWO_52) - _TWO_52  # the nearest integer (a half goes to Python's round)
            if math.fabs(a - n) != 0.5:  # (the difference is exact)
                return math.copysign(n / p, x)
    return round(x, d)
