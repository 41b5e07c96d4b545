"""Parsers for option values shared by several commands (they raise click.BadParameter),
and the options declared once for every command that runs a program: how the machine is
set up (:func:`setup_options`) and how the program is read (:func:`program_options`);
:func:`program_setup_options` declares both, for correct, verify and diff."""

from __future__ import annotations

import contextlib
import functools
import math
import re
from dataclasses import dataclass
from pathlib import Path

import click

from postproc.constants import DEFAULT_MAX_CORRECTION_MM, DEFAULT_TOLERANCE_MM
from postproc.errors import PostprocError
from postproc.gcode.dialect import DIALECT_NAMES
from postproc.limits import DEFAULT_MAX_ARC_TURNS, DEFAULT_MAX_ITERATIONS, Limits

# The controllers --dialect names: one entry each in postproc.gcode.dialect (a light module)
DIALECT_CHOICE = click.Choice(list(DIALECT_NAMES), case_sensitive=False)

_AXES = "XYZ"


class FiniteFloat(click.FloatRange):
    """A float option that refuses nan and inf (click's float accepts them, and a
    range check lets nan through); ``min``/``max`` as in :class:`click.FloatRange`.
    Every float option of every command has this type (tests/test_cli_options.py walks them)."""

    name = "number"

    def convert(self, value, param, ctx):
        number = click.FLOAT.convert(value, param, ctx)
        if not math.isfinite(number):
            self.fail(f"{value!r} is not a finite number", param, ctx)
        return super().convert(number, param, ctx)

    def _describe_range(self) -> str:
        """The range in --help; none when unbounded (click would show ``x<=None``)."""
        if self.min is None and self.max is None:
            return ""
        return super()._describe_range()


#: use as ``type=FINITE_FLOAT`` for every float option
FINITE_FLOAT = FiniteFloat()


def parse_vector(text: str, what: str = "vector") -> tuple[float, float, float]:
    """``"0,0,-100"`` -> (0.0, 0.0, -100.0) (mm: a point or a tool vector, each number
    within :data:`MAX_POSITION_MM`)."""
    parts = [p.strip() for p in text.split(",")]
    try:
        values = tuple(float(p) for p in parts)
    except ValueError:
        values = ()
    if len(values) != 3 or not all(math.isfinite(v) for v in values):
        raise click.BadParameter(f"{what} must be three numbers X,Y,Z, got {text!r}")
    if not all(abs(v) <= MAX_POSITION_MM for v in values):
        raise click.BadParameter(f"{what} {text!r} reaches beyond {MAX_POSITION_MM:g} mm: no machine reaches "
                                 "that far")
    return values[0], values[1], values[2]


# G500 and G505..G599: Sinumerik; E<n>: Fadal fixture offsets; G15H<n>: Okuma work coordinates
_OFFSET_NAME = re.compile(r"^(G5[4-9](?:\.[1-3])?|G54\.1P\d+|G5\d\d|E\d+|G15H\d+)$", re.IGNORECASE)


#: Largest position or offset an axis option takes (mm): a kilometre, far beyond any machine.
MAX_POSITION_MM = 1e6


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
        value = float(m.group(2)) * scale
        if not abs(value) <= MAX_POSITION_MM:  # (a 400-digit number reads as inf)
            raise click.BadParameter(f"{text!r}: {axis} {m.group(2)[:12]}{'...' if len(m.group(2)) > 12 else ''} "
                                     f"is beyond {MAX_POSITION_MM:g} mm: no machine reaches that far",
                                     param_hint=param_hint)
        values[axis] = value
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
            " (G500..G599 Sinumerik, E<n> Fadal, G15H<n> Okuma)"
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


def read_tool_table(path: str, column: str = "Z") -> dict[int, float]:
    """Tool lengths (mm) from a LinuxCNC tool table: lines like ``T1 P1 Z100.5 D6 ;comment``
    (``column="D"``: the diameters of the tools that have one)."""
    lengths: dict[int, float] = {}
    try:
        text = Path(path).read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise PostprocError(f"cannot read tool table: {exc.strerror}", path=path) from None
    for lineno, raw in enumerate(text.splitlines(), start=1):
        body = raw.split(";", 1)[0]
        if not body.strip():
            continue
        fields = {}
        for m in re.finditer(r"\S+", body):
            item = m.group()
            letter, value = item[:1].upper(), item[1:]
            try:
                number = float(value)
            except ValueError:
                number = None
            if number is None or not letter.isalpha():
                raise PostprocError(f"tool table field {item!r} is not a letter and a number",
                                    path=path, lineno=lineno, col=m.start() + 1)
            if not math.isfinite(number):
                raise PostprocError(f"tool table field {item!r} is not a finite number",
                                    path=path, lineno=lineno, col=m.start() + 1)
            fields[letter] = number
        if "T" not in fields:
            raise PostprocError("tool table line without a T word", path=path, lineno=lineno,
                                col=len(body) - len(body.lstrip()) + 1)
        tool = fields["T"]
        if tool != int(tool) or tool < 0:
            raise PostprocError(f"tool number T{tool:g} is not a whole number of 0 or more", path=path,
                                lineno=lineno, col=body.upper().index("T") + 1)
        if column == "Z" or column in fields:
            lengths[int(tool)] = fields.get(column, 0.0)
    return lengths


def parse_tool_radius(text: str, flag: str, half: bool) -> tuple[int | None, float]:
    """``"1=3"`` or ``"D1=3"`` -> (1, 3.0); ``"3"`` -> (None, 3.0), for every tool (mm; halved
    when ``half``: a diameter)."""
    key, sep, value = text.rpartition("=")
    try:
        size = float(value)
        if not math.isfinite(size) or size < 0 or (sep and not key.strip().upper().lstrip("DT").isdigit()):
            raise ValueError
    except ValueError:
        raise click.BadParameter(f"{text!r}: expected N=SIZE or SIZE (mm), e.g. 1=3", param_hint=flag) from None
    return (int(key.strip().upper().lstrip("DT")) if sep else None), size / 2 if half else size


@contextlib.contextmanager
def _option(flag: str):
    """Name ``flag`` in a click.BadParameter raised inside that does not name its option."""
    try:
        yield
    except click.BadParameter as exc:
        if exc.param is None and exc.param_hint is None:
            exc.param_hint = flag
        raise


def build_setup(offset=(), tool_length=(), tool_table=None, tool_vector=None, context=(), start=None, home=(),
                var=(), vars_file=None, tool_radius=(), tool_diameter=()):
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
    from postproc.gcode.variables import parse_var, read_vars

    variables = read_vars(vars_file) if vars_file else {}
    for text in var:
        try:
            index, value = parse_var(text)
        except ValueError as exc:
            raise click.BadParameter(str(exc), param_hint="--var") from None
        variables[index] = value
    # cutter radii (postproc.gcode.cutter): the table's diameters, then the options
    radii: dict[int | None, float] = {t: d / 2 for t, d in read_tool_table(tool_table, "D").items()} \
        if tool_table else {}
    radii.update(parse_tool_radius(t, "--tool-diameter", True) for t in tool_diameter)
    radii.update(parse_tool_radius(t, "--tool-radius", False) for t in tool_radius)
    return Setup(offsets=offsets, tool_lengths=tools, tool_vector=vec, context=ctx,
                 start=parse_start(start) if start is not None else {}, home=homes, variables=variables,
                 tool_radii=radii)


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
        help="LinuxCNC tool table (.tbl) giving tool lengths (Z column, mm) and cutter diameters (D column, "
             "mm, for G41/G42); --tool-length, --tool-radius and --tool-diameter override its entries.")),
    "--tool-radius": ("tool_radius", dict(
        multiple=True, metavar="N=R",
        help="Cutter radius (mm) of tool N (LinuxCNC, G41/G42 D<N>) or D register N (Fanuc, Haas); R alone: "
             "every tool. Repeatable.")),
    "--tool-diameter": ("tool_diameter", dict(
        multiple=True, metavar="N=D", help="As --tool-radius, giving the diameter (mm). Repeatable.")),
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
    "--var": ("var", dict(
        multiple=True, metavar="N=VALUE",
        help="Value of a machine-state variable the program reads (Haas/Fanuc #5405, retained #500, "
             "LinuxCNC #5221), e.g. 5405=12.5; recorded in the header. Probe results are never taken. "
             "Repeatable.")),
    "--vars": ("vars_file", dict(
        default=None, type=click.Path(dir_okay=False),
        help="Machine-state variables from a LinuxCNC .var file or a Fanuc/Haas macro-variable listing; "
             "--var overrides its entries.")),
    "--context": ("context", dict(
        multiple=True, metavar="NAME=VALUE",
        help="Constant context value during the run, read by the calibration's model, e.g. temp=21.5. "
             "Repeatable.")),
}


def _declare(table: dict[str, tuple[str, dict]], argument: str, make, leave_out: tuple[str, ...]):
    """A decorator declaring the options of ``table`` (less ``leave_out``) on a command and
    passing it ``argument=make(**their values by field name)`` in their place."""
    unknown = set(leave_out) - set(table)
    if unknown:
        raise ValueError(f"not among these options: {sorted(unknown)}")
    chosen = [flag for flag in table if flag not in leave_out]

    def decorate(fn):
        @functools.wraps(fn)
        def command(*args, **kwargs):
            given = {table[flag][0]: kwargs.pop(table[flag][0]) for flag in chosen}
            return fn(*args, **{argument: make(**given)}, **kwargs)

        for flag in reversed(chosen):
            name, attrs = table[flag]
            command = click.option(flag, name, **attrs)(command)
        return command

    return decorate


def setup_options(fn=None, *, leave_out: tuple[str, ...] = ()):
    """Declare the machine setup options (:data:`SETUP_OPTIONS`: work offsets, tool lengths,
    tool table, tool vector, start position, G28/G30 positions, context) on a command, and
    pass the command one ``setup`` argument in their place: the
    :class:`postproc.gcode.path.Setup` that :func:`build_setup` makes of them, before the
    command's body runs, so every command refuses the same bad value the same way.

    ``leave_out``: flags that do not apply to the command (not declared).
    """
    decorate = _declare(SETUP_OPTIONS, "setup", build_setup, leave_out)
    return decorate(fn) if fn is not None else decorate


def context_option(help: str | None = None):
    """The ``--context NAME=VALUE`` option alone (as in :data:`SETUP_OPTIONS`), passed to the
    command as a dict of the values parsed (``help``: the command's own wording)."""
    name, attrs = SETUP_OPTIONS["--context"]
    attrs = {**attrs, "help": help or attrs["help"]}
    return click.option("--context", name, callback=lambda ctx, param, value: dict(parse_context(c) for c in value),
                        **attrs)


@dataclass(frozen=True)
class Reading:
    """How a program is read, as :data:`PROGRAM_OPTIONS` give it: the controller's dialect,
    canned cycles kept or expanded, the folders searched for subprogram files."""

    dialect: str = "generic"
    cycles: str = "auto"
    subroutine_path: tuple[str, ...] = ()
    max_iterations: int = DEFAULT_MAX_ITERATIONS
    max_arc_turns: int = DEFAULT_MAX_ARC_TURNS

    def limits(self, **output) -> Limits:
        """The bounds on one run's work these set (``output``: the output's, correct only)."""
        return Limits(max_iterations=self.max_iterations, max_arc_turns=self.max_arc_turns, **output)

    def correct_options(self) -> dict:
        """The :class:`postproc.gcode.pipeline.CorrectOptions` fields these set."""
        return {"dialect": self.dialect, "cycles": self.cycles, "subroutine_path": self.subroutine_path,
                "limits": self.limits()}


#: How the program is read, in the order listed: flag -> (field of :class:`Reading`, click.option arguments).
#: A new option of how programs are read (e.g. --var) is one entry here and one field of
#: :class:`Reading`; correct, verify, diff and mirror pockets then all take it.
PROGRAM_OPTIONS: dict[str, tuple[str, dict]] = {
    "--dialect": ("dialect", dict(
        default="generic", show_default=True, type=DIALECT_CHOICE,
        help="Controller the program is for: how it is read (comments, G53 in G91, macros, "
             "program numbers) and written (line length, case, arc rule). generic is what all of them accept.")),
    "--cycles": ("cycles", dict(
        type=click.Choice(["auto", "keep", "expand"]), default="auto", show_default=True,
        help="Canned cycles (G73, G81-G89): auto keeps each one whose correction tilts the hole by no more "
             "than --tolerance (corrected at the hole) and expands the others, with the rest of their "
             "series up to G80, into G0/G1 moves, each corrected; keep keeps them all (refusing a tilted "
             "one); expand expands them all. Sinumerik's CYCLE81/82/89 (and MCALL) are always written as "
             "their moves (refused with keep).")),
    "--subroutine-path": ("subroutine_path", dict(
        multiple=True, type=click.Path(file_okay=False),
        help="Folder searched for o<name> call subroutines (<name>.ngc), M98 subprogram files and "
             "Sinumerik subprograms (<name>.SPF/.MPF), as LinuxCNC's SUBROUTINE_PATH. Repeatable.")),
    "--max-iterations": ("max_iterations", dict(
        default=DEFAULT_MAX_ITERATIONS, show_default=True, type=click.IntRange(1),
        help="Refuse a program whose loop passes and subprogram calls exceed this in all (an endless loop).")),
    "--max-arc-turns": ("max_arc_turns", dict(
        default=DEFAULT_MAX_ARC_TURNS, show_default=True, type=click.IntRange(1),
        help="Refuse a helix (G2/G3 P) of more turns than this.")),
}


def _reading(**given) -> Reading:
    if "dialect" in given:
        given["dialect"] = given["dialect"].lower()
    if "subroutine_path" in given:
        given["subroutine_path"] = tuple(given["subroutine_path"])
    return Reading(**given)


def program_options(fn=None, *, leave_out: tuple[str, ...] = ()):
    """Declare how the program is read (:data:`PROGRAM_OPTIONS`: dialect, canned cycles,
    subroutine path) on a command, and pass the command one ``reading`` argument in their
    place: a :class:`Reading`. ``leave_out``: flags that do not apply to the command."""
    decorate = _declare(PROGRAM_OPTIONS, "reading", _reading, leave_out)
    return decorate(fn) if fn is not None else decorate


def program_setup_options(fn=None, *, leave_out: tuple[str, ...] = ()):
    """:func:`program_options` and :func:`setup_options` together: the one declaration of
    what correct, verify and diff are told about the program and the machine (they pass
    the command ``reading`` and ``setup``). ``leave_out``: flags of either that do not apply."""
    def decorate(fn):
        fn = setup_options(leave_out=tuple(f for f in leave_out if f in SETUP_OPTIONS))(fn)
        return program_options(leave_out=tuple(f for f in leave_out if f in PROGRAM_OPTIONS))(fn)

    return decorate(fn) if fn is not None else decorate


#: How a program is corrected (correct, and verify's in-process correction): flag -> (field of
#: :class:`postproc.gcode.pipeline.CorrectOptions`, click.option arguments).
CORRECTION_OPTIONS: dict[str, tuple[str, dict]] = {
    "--no-expand": ("expand", dict(
        is_flag=True, flag_value=False, default=True,
        help="Refuse parameters, O-words, subprograms and macros instead of expanding them.")),
    "--tolerance": ("tolerance_mm", dict(
        default=DEFAULT_TOLERANCE_MM, show_default=True, type=FiniteFloat(min=1e-5), metavar="MM",
        help="Largest distance (mm) between the emitted and the corrected ideal path.")),
    "--decimals": ("decimals", dict(
        default=None, type=click.IntRange(1, 8),
        help="Decimals of rewritten coordinates [default: 4 in mm, 5 in inch].")),
    "--max-correction": ("max_correction_mm", dict(
        default=DEFAULT_MAX_CORRECTION_MM, show_default=True, type=FiniteFloat(min=0.0), metavar="MM",
        help="Refuse any correction larger than this (mm).")),
    "--extrapolate": ("extrapolate", dict(
        type=click.Choice(["refuse", "clamp", "linear"]), default="refuse", show_default=True,
        help="Targets outside the calibrated volume: refuse, or correct them with the correction at the "
             "nearest point inside (clamp) or the model as is (linear).")),
    "--force": ("force", dict(is_flag=True, help="Correct a program that already carries a postproc header.")),
}


def correction_options(fn=None, *, leave_out: tuple[str, ...] = ()):
    """Declare how a program is corrected (:data:`CORRECTION_OPTIONS`) on a command, and pass
    the command one ``correcting`` argument in their place: the dict of the
    :class:`postproc.gcode.pipeline.CorrectOptions` fields they give."""
    decorate = _declare(CORRECTION_OPTIONS, "correcting", dict, leave_out)
    return decorate(fn) if fn is not None else decorate


def limit_options(fn):
    """Declare the bounds on the corrected program's size on ``correct``; with the reading's
    bounds (``--max-iterations``, ``--max-arc-turns``) they make the one ``limits``
    argument (:class:`postproc.limits.Limits`) passed to it."""
    from postproc import limits as lim

    @functools.wraps(fn)
    def command(*args, max_output_lines, max_output_mb, **kwargs):
        reading = kwargs["reading"]
        return fn(*args, limits=reading.limits(max_output_lines=max_output_lines, max_output_mb=max_output_mb),
                  **kwargs)

    command = click.option(
        "--max-output-mb", "max_output_mb", default=None, type=FiniteFloat(min=0, min_open=True),
        help=f"Refuse a corrected program larger than this (MB) [default: {lim.OUTPUT_GROWTH} times the "
             f"input's size plus {lim.OUTPUT_MB_EXTRA} MB].")(command)
    return click.option(
        "--max-output-lines", "max_output_lines", default=None, type=click.IntRange(1),
        help=f"Refuse a corrected program longer than this [default: {lim.OUTPUT_GROWTH} times the input's "
             f"lines plus {lim.OUTPUT_LINES_EXTRA:,}].")(command)
