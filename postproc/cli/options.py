"""Parsers for option values shared by several commands (they raise click.BadParameter)."""

from __future__ import annotations

import math
import re

import click

_AXES = "XYZ"


class FiniteFloat(click.FloatRange):
    """A float option that refuses nan and inf (click's float accepts them, and a
    range check lets nan through); ``min``/``max`` as in :class:`click.FloatRange`."""

    def convert(self, value, param, ctx):
        number = super().convert(value, param, ctx)
        if not math.isfinite(number):
            self.fail(f"{value!r} is not a finite number", param, ctx)
        return number


#: use as ``type=FINITE_FLOAT`` for every float option
FINITE_FLOAT = FiniteFloat()


def parse_vector(text: str, what: str = "vector") -> tuple[float, float, float]:
    """``"0,0,-100"`` -> (0.0, 0.0, -100.0)."""
    parts = [p.strip() for p in text.split(",")]
    try:
        values = tuple(float(p) for p in parts)
    except ValueError:
        values = ()
    if len(values) != 3 or not all(math.isfinite(v) for v in values):
        raise click.BadParameter(f"{what} must be three numbers X,Y,Z, got {text!r}")
    return values  # type: ignore[return-value]


_OFFSET_NAME = re.compile(r"^(G5[4-9](?:\.[1-3])?|G54\.1P\d+)$", re.IGNORECASE)


def axis_values(text: str, rest: str, letters: str, *, param_hint: str | None = None,
                 once: bool = False) -> dict[str, float]:
    """``"X100,Y50,Z-300"`` (``rest``; ending in ``in`` for inches) -> mm by upper-case axis
    letter, for the letters in ``letters``; ``once``: an axis given twice is refused."""
    scale = 1.0
    rest = rest.strip()
    if rest.lower().endswith("in"):
        scale, rest = 25.4, rest[:-2]
    values: dict[str, float] = {}
    pattern = re.compile(rf"([{letters}{letters.lower()}])\s*([-+]?(?:\d+\.?\d*|\.\d+))")
    what = "an axis letter" if len(letters) > 3 else "X, Y or Z"
    for item in filter(None, (p.strip() for p in rest.split(","))):
        m = pattern.fullmatch(item)
        if not m:
            raise click.BadParameter(f"{text!r}: {item!r} is not {what} and a number", param_hint=param_hint)
        axis = m.group(1).upper()
        if once and axis in values:
            raise click.BadParameter(f"{text!r}: {axis} is given twice", param_hint=param_hint)
        values[axis] = float(m.group(2)) * scale
    return values


def parse_offset(text: str) -> tuple[str, dict[str, float]]:
    """``"G54=X100,Y50,Z-300"`` -> ("G54", {"X": 100, "Y": 50, "Z": -300}).

    Values are machine-frame offsets in mm, or in inches when the list ends with
    ``in`` (``G55=X1,Y2,Z3in``), whatever units the program itself uses.
    """
    name, sep, rest = text.partition("=")
    name = name.strip().upper().replace(" ", "")
    if not sep or not _OFFSET_NAME.match(name):
        raise click.BadParameter(
            f"{text!r}: expected NAME=X..,Y..,Z.. with NAME one of G54..G59, G59.1..G59.3, G54.1P<n>"
        )
    values = axis_values(text, rest, "XYZABC")
    return name, values


def parse_tool_length(text: str) -> tuple[int, float]:
    """``"1=100.5"`` or ``"H1=100.5"`` -> (1, 100.5) (mm)."""
    key, sep, value = text.partition("=")
    key = key.strip().upper().lstrip("HT")
    try:
        length = float(value)
        if not math.isfinite(length):
            raise ValueError
        return int(key), length
    except ValueError:
        raise click.BadParameter(f"{text!r}: expected H=L, e.g. 1=100.5 or H1=100.5 (mm)") from None


def parse_context(text: str) -> tuple[str, float]:
    """``"temp=21.5"`` -> ("temp", 21.5)."""
    key, sep, value = text.partition("=")
    try:
        number = float(value)
        if not sep or not key.strip() or not math.isfinite(number):
            raise ValueError
        return key.strip(), number
    except ValueError:
        raise click.BadParameter(f"{text!r}: expected NAME=VALUE, e.g. temp=21.5") from None


_HOME_NAME = re.compile(r"^G(28|30)$", re.IGNORECASE)


def parse_home(text: str) -> tuple[str, dict[str, float]]:
    """``"G28=X0,Y0,Z0"`` -> ("G28", {"X": 0, "Y": 0, "Z": 0}): the stored position G28
    or G30 goes to, machine mm (end with ``in`` for inches); any subset of X, Y, Z."""
    name, sep, rest = text.partition("=")
    name = name.strip().upper()
    if not sep or not _HOME_NAME.match(name):
        raise click.BadParameter(f"{text!r}: expected G28=X..,Y..,Z.. or G30=X..,Y..,Z.. (machine mm)",
                                 param_hint="--home")
    values = axis_values(text, rest, "XYZ", param_hint="--home", once=True)
    if not values:
        raise click.BadParameter(f"{text!r}: give at least one of X, Y, Z", param_hint="--home")
    return name, values
