"""Parsers for option values shared by several commands (they raise click.BadParameter),
and the options declared once for every command that runs a program (:func:`setup_options`)."""

from __future__ import annotations

import contextlib
import functools
import math
import re
from pathlib import Path

import click

from postproc.errors import PostprocError

# The controllers --dialect names (postproc.gcode.dialect.DIALECTS; a test keeps them equal,
# and this module stays light for --help).
DIALECT_CHOICE = click.Choice(["generic", "linuxcnc", "fanuc", "haas", "grbl", "mach3"], case_sensitive=False)

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


def parse_start(text: str) -> dict[str, float]:
    """``"X10,Y20,Z150"`` (any of X, Y, Z; end with ``in`` for inches) -> machine mm by axis."""
    values = axis_values(text, text, "XYZ", param_hint="--start", once=True)
    if not values:
        raise click.BadParameter(f"{text!r}: expected X..,Y..,Z.. (any of them)", param_hint="--start")
    return values


def read_tool_table(path: str) -> dict[int, float]:
    """Tool lengths (mm) from a LinuxCNC tool table: lines like ``T1 P1 Z100.5 D6 ;comment``."""
    lengths: dict[int, float] = {}
    try:
        text = Path(path).read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise PostprocError(f"cannot read tool table: {exc.strerror}", path=path) from None
    for lineno, raw in enumerate(text.splitlines(), start=1):
        body = raw.split(";", 1)[0].strip()
        if not body:
            continue
        fields = {}
        for item in body.split():
            letter, value = item[:1].upper(), item[1:]
            try:
                fields[letter] = float(value)
                if not math.isfinite(fields[letter]):
                    raise ValueError
            except ValueError:
                raise PostprocError(f"tool table field {item!r} is not a letter and a finite number",
                                    path=path, lineno=lineno, col=raw.find(item) + 1) from None
        if "T" not in fields:
            raise PostprocError("tool table line without a T word", path=path, lineno=lineno, col=1)
        lengths[int(fields["T"])] = fields.get("Z", 0.0)
    return lengths


@contextlib.contextmanager
def _option(flag: str):
    """Name ``flag`` in a click.BadParameter raised inside that does not name its option."""
    try:
        yield
    except click.BadParameter as exc:
        if exc.param is None and exc.param_hint is None:
            exc.param_hint = flag
        raise


def build_setup(offset=(), tool_length=(), tool_table=None, tool_vector=None, context=(), start=None, home=()):
    """The :class:`postproc.gcode.path.Setup` the options of :func:`setup_options` give (their
    texts as typed); a partial work offset, a home or an axis given twice is refused."""
    from postproc.gcode.path import Setup

    offsets = {}
    for text in offset:
        with _option("--offset"):
            name, values = parse_offset(text)
        missing = [a for a in "XYZ" if a not in values]
        if missing:
            raise click.BadParameter(f"{text!r}: give all of X, Y and Z (missing {', '.join(missing)})",
                                     param_hint="--offset")
        offsets[name] = (values["X"], values["Y"], values["Z"])
    tools = read_tool_table(tool_table) if tool_table else {}
    for text in tool_length:
        with _option("--tool-length"):
            h, length = parse_tool_length(text)
        tools[h] = length
    vec = parse_vector(tool_vector, "--tool-vector") if tool_vector else None
    with _option("--context"):
        ctx = dict(parse_context(c) for c in context)
    homes: dict = {}
    for text in home:
        name, values = parse_home(text)
        if name in homes:
            raise click.BadParameter(f"{name} is given twice", param_hint="--home")
        homes[name] = values
    return Setup(offsets=offsets, tool_lengths=tools, tool_vector=vec, context=ctx,
                 start=parse_start(start) if start is not None else {}, home=homes)


#: The setup options, in the order they are listed: flag -> (parameter name, click.option arguments).
#: Their values are the keyword arguments of :func:`build_setup`.
SETUP_OPTIONS: dict[str, tuple[str, dict]] = {
    "--offset": ("offset", dict(
        multiple=True, metavar="G5x=X..,Y..,Z..",
        help="Work offset in machine mm (end with 'in' for inches), all of X, Y and Z, e.g. "
             "G54=X100,Y50,Z-300. Repeatable.")),
    "--tool-length": ("tool_length", dict(
        multiple=True, metavar="H=L", help="Tool length (mm) for G43 H<n>, e.g. 1=100.5. Repeatable.")),
    "--tool-table": ("tool_table", dict(
        default=None, type=click.Path(dir_okay=False),
        help="LinuxCNC tool table (.tbl) giving tool lengths (Z column, mm); --tool-length overrides "
             "its entries.")),
    "--tool-vector": ("tool_vector", dict(
        default=None, metavar="X,Y,Z",
        help="Tool vector r (mm) from gauge point to tool tip, overriding (0,0,-length).")),
    "--start": ("start", dict(
        default=None, metavar="X..,Y..,Z..",
        help="Machine axis positions (mm, as G53; end with 'in' for inches) at program start, for the "
             "axes the program has not positioned yet, e.g. Z150. Needs --offset for G54.")),
    "--home": ("home", dict(
        multiple=True, metavar="G28=X..,Y..,Z..",
        help="Stored position G28 or G30 goes to, in machine mm (end with 'in' for inches), any of X, Y, Z. "
             "Without it an axis sent there is unknown until the program positions it again. Repeatable.")),
    "--context": ("context", dict(
        multiple=True, metavar="NAME=VALUE",
        help="Constant context value during the run, read by the calibration's model, e.g. temp=21.5. "
             "Repeatable.")),
}


def setup_options(fn=None, *, leave_out: tuple[str, ...] = ()):
    """Declare the machine setup options (:data:`SETUP_OPTIONS`: work offsets, tool lengths,
    tool table, tool vector, start position, G28/G30 positions, context) on a command, and
    pass the command one ``setup`` argument in their place: the
    :class:`postproc.gcode.path.Setup` that :func:`build_setup` makes of them, before the
    command's body runs, so every command refuses the same bad value the same way.

    ``leave_out``: flags that do not apply to the command (not declared).
    """
    unknown = set(leave_out) - set(SETUP_OPTIONS)
    if unknown:
        raise ValueError(f"not setup options: {sorted(unknown)}")
    chosen = [flag for flag in SETUP_OPTIONS if flag not in leave_out]

    def decorate(fn):
        @functools.wraps(fn)
        def command(*args, **kwargs):
            given = {SETUP_OPTIONS[flag][0]: kwargs.pop(SETUP_OPTIONS[flag][0]) for flag in chosen}
            return fn(*args, setup=build_setup(**given), **kwargs)

        for flag in reversed(chosen):
            name, attrs = SETUP_OPTIONS[flag]
            command = click.option(flag, name, **attrs)(command)
        return command

    return decorate(fn) if fn is not None else decorate


def context_option(help: str | None = None):
    """The ``--context NAME=VALUE`` option alone (as in :data:`SETUP_OPTIONS`), passed to the
    command as a dict of the values parsed (``help``: the command's own wording)."""
    name, attrs = SETUP_OPTIONS["--context"]
    attrs = {**attrs, "help": help or attrs["help"]}
    return click.option("--context", name, callback=lambda ctx, param, value: dict(parse_context(c) for c in value),
                        **attrs)


def limit_options(fn):
    """Declare the bounds on one run's work (:class:`postproc.limits.Limits`) on a command
    that expands and corrects programs, passed to it as one ``limits`` argument."""
    from postproc import limits as lim

    @functools.wraps(fn)
    def command(*args, max_iterations, max_output_lines, max_output_mb, max_arc_turns, **kwargs):
        return fn(*args, limits=lim.Limits(max_iterations, max_output_lines, max_arc_turns, max_output_mb), **kwargs)

    command = click.option(
        "--max-arc-turns", "max_arc_turns", default=lim.DEFAULT_MAX_ARC_TURNS, show_default=True,
        type=click.IntRange(1), help="Refuse a helix (G2/G3 P) of more turns than this.")(command)
    command = click.option(
        "--max-output-mb", "max_output_mb", default=None, type=FiniteFloat(min=0, min_open=True),
        help=f"Refuse a corrected program larger than this (MB) [default: {lim.OUTPUT_GROWTH} times the "
             f"input's size plus {lim.OUTPUT_MB_EXTRA} MB].")(command)
    command = click.option(
        "--max-output-lines", "max_output_lines", default=None, type=click.IntRange(1),
        help=f"Refuse a corrected program longer than this [default: {lim.OUTPUT_GROWTH} times the input's "
             f"lines plus {lim.OUTPUT_LINES_EXTRA:,}].")(command)
    return click.option(
        "--max-iterations", "max_iterations", default=lim.DEFAULT_MAX_ITERATIONS, show_default=True,
        type=click.IntRange(1), help="Refuse a program whose loop passes and subprogram calls exceed this in all "
                                     "(an endless loop).")(command)
