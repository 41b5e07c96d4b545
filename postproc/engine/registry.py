"""The calibration methods: for each ``--method`` name its engine class, its fitters and
the options they take.

A method is one :func:`register` call with a :class:`Method`: import paths of the engine
class and of its fitters (so that ``postproc correct`` imports only the engine it uses, and
``postproc fit --help`` none), and the options of its fitters (:class:`FitOption`).
``postproc fit`` and ``postproc check`` take their method choices, method options and the
checks of which option goes with which method from here: a new method is its module and
one ``register`` call.
"""

from __future__ import annotations

import importlib
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from postproc.errors import CalibrationError

#: kinds of option value (:attr:`FitOption.type`)
OPTION_TYPES = ("float", "text", "choice", "flag")


@dataclass(frozen=True)
class FitOption:
    """One option of a method's fitters, declared once for the library and the command line.

    ``keyword``: the fitter's keyword argument; ``flag``: the command-line option;
    ``type``: one of :data:`OPTION_TYPES`; ``help``: the command line's help text;
    ``default``: the value the fitter takes when the option is not given (None: found
    from the data); ``choices``: the values of a "choice"; ``minimum``: the smallest
    value of a "float"; ``multiple``: repeatable, passed as a list; ``tables``: the
    method's fitter from axis error tables takes it too; ``error_phrase``: words of a
    CalibrationError of the fitter that mean this option's value does not fit the data
    (the command line reports it as a usage error of the option).
    """

    keyword: str
    flag: str
    type: str
    help: str
    default: Any = None
    choices: tuple[str, ...] = ()
    minimum: float | None = None
    metavar: str | None = None
    multiple: bool = False
    tables: bool = False
    error_phrase: str | None = None

    def __post_init__(self) -> None:
        if self.type not in OPTION_TYPES:
            raise ValueError(f"option {self.flag}: type {self.type!r} is not one of {', '.join(OPTION_TYPES)}")
        if (self.type == "choice") != bool(self.choices):
            raise ValueError(f"option {self.flag}: choices go with type 'choice' and only with it")
        if not self.flag.startswith("--"):
            raise ValueError(f"option {self.flag}: a flag starts with --")


@dataclass(frozen=True)
class Method:
    """A calibration method.

    ``engine``: "module:Class" of its engine; ``fitter``: "module:function" fitting it
    from point measurements, called as ``fit(measurements, **options)`` and returning a
    FitResult; ``from_tables``: the method is also made from axis error tables (by
    :func:`postproc.metrology.tables_fit.tables_fitter`, which reads the files: a
    reader of measurement files sits above the engines); ``options``: what the
    fitters take; ``refit``: "module:function" giving, for an engine of this method, the
    fitter options that fit the same model again (its partition, its grid step), so that
    ``postproc check`` cross-validates that model; ``fold_options``: options added when
    fitting one training fold of a cross-validation.
    """

    name: str
    engine: str
    fitter: str | None = None
    from_tables: bool = False
    options: tuple[FitOption, ...] = ()
    refit: str | None = None
    fold_options: Mapping[str, Any] = field(default_factory=dict)


#: method name -> Method, in the order they were registered (the order of the choices)
METHODS: dict[str, Method] = {}
#: method name -> "module:EngineClass" (every method)
ENGINES: dict[str, str] = {}
#: method name -> "module:function" fitting an engine from point measurements
FITTERS: dict[str, str] = {}

#: ``postproc fit`` without --method: the method for point measurements (axis error
#: tables take the method that has a tables fitter)
DEFAULT_POINTS_METHOD = "static"


def register(method: Method) -> Method:
    """Add ``method`` (or replace the one of that name). An option keyword shared with
    another method must be declared the same way (one flag, one type)."""
    for other in METHODS.values():
        if other.name == method.name:
            continue
        for a in method.options:
            for b in other.options:
                if (a.keyword == b.keyword) != (a.flag == b.flag):
                    raise ValueError(f"method {method.name}: option {a.keyword} ({a.flag}) clashes with "
                                     f"{b.keyword} ({b.flag}) of method {other.name}")
                if a.flag == b.flag and (a.type, a.choices, a.multiple) != (b.type, b.choices, b.multiple):
                    raise ValueError(f"method {method.name}: option {a.flag} is declared otherwise by "
                                     f"method {other.name}")
    METHODS[method.name] = method
    ENGINES[method.name] = method.engine
    if method.fitter:
        FITTERS[method.name] = method.fitter
    else:
        FITTERS.pop(method.name, None)
    return method


def unregister(name: str) -> None:
    """Remove method ``name`` (for methods registered for a while, e.g. in tests)."""
    METHODS.pop(name, None)
    ENGINES.pop(name, None)
    FITTERS.pop(name, None)


def fit_methods() -> list[str]:
    """Methods that can be fitted from point measurements (``postproc fit --method``)."""
    return [name for name, m in METHODS.items() if m.fitter]


def tables_methods() -> list[str]:
    """Methods that can be made from axis error tables."""
    return [name for name, m in METHODS.items() if m.from_tables]


def fit_options() -> dict[str, tuple[FitOption, list[str]]]:
    """Every fit option by flag, with the methods whose fitters take it (in registration order)."""
    out: dict[str, tuple[FitOption, list[str]]] = {}
    for m in METHODS.values():
        for opt in m.options:
            out.setdefault(opt.flag, (opt, []))[1].append(m.name)
    return out


def option_flag(keyword: str) -> str:
    """The command-line flag of fitter option ``keyword`` (``--`` + keyword when none declares it)."""
    for m in METHODS.values():
        for opt in m.options:
            if opt.keyword == keyword:
                return opt.flag
    return "--" + keyword.replace("_", "-")


def _load(spec: str):
    module, _, attr = spec.partition(":")
    return getattr(importlib.import_module(module), attr)


def engine_class(method: str):
    try:
        spec = ENGINES[method]
    except KeyError:
        raise CalibrationError(
            f"unknown calibration method {method!r}",
            hint=f"known methods: {', '.join(sorted(ENGINES))}",
        ) from None
    return _load(spec)


def fitter(method: str):
    try:
        spec = FITTERS[method]
    except KeyError:
        raise CalibrationError(
            f"no fitter for method {method!r}", hint=f"choose one of: {', '.join(sorted(FITTERS))}"
        ) from None
    return _load(spec)


def refit_options(engine) -> dict:
    """The fitter options that fit ``engine``'s model again (its partition, its grid step);
    ``{}`` for a method that declares none."""
    m = METHODS.get(engine.method)
    return _load(m.refit)(engine) if m is not None and m.refit else {}


def fold_options(method: str) -> dict:
    """Options added to the fitter's when it fits one training fold of a cross-validation."""
    m = METHODS.get(method)
    return dict(m.fold_options) if m is not None else {}


# -- the methods --------------------------------------------------------------------

register(Method("static", "postproc.engine.static:StaticEngine", "postproc.engine.static:fit"))

register(Method(
    "interval", "postproc.engine.interval:IntervalEngine", "postproc.engine.interval:fit",
    refit="postproc.engine.interval:refit_options",
    options=(
        FitOption("intervals", "--intervals", "text", metavar="SPEC",
                  help="Interval method: partition, e.g. 'X=0,100,200,315;Y=3;Z=2' (edges, or a count per axis)."),
        FitOption("border_blend_mm", "--border-blend", "float", default=1.0, minimum=0, metavar="MM",
                  error_phrase="border blend",
                  help="Interval method: width of the zone blending neighbouring cells at each border "
                       "(default 1 mm; 0: the seed's pure piecewise model)."),
    )))

register(Method(
    "grid", "postproc.engine.grid:GridEngine", "postproc.engine.grid:fit",
    refit="postproc.engine.grid:refit_options",
    # a training fold leaves lattice nodes without points: fill them from their
    # neighbours (the held-out points then test that fill)
    fold_options={"fill_missing": True},
    options=(
        FitOption("step", "--step", "text", metavar="MM",
                  help="Grid method: grid step u1,u2,u3 in mm (default: the lattice step of the data)."),
        FitOption("screw_pitch", "--screw-pitch", "text", multiple=True, metavar="AXIS=P",
                  help="Declared lead-screw pitch (mm) of an axis, to warn about grid steps that alias it."),
        FitOption("model", "--grid-model", "choice", default="trilinear", choices=("trilinear", "cell"),
                  help="Grid method: trilinear tangent field (default, continuous) or the seed's "
                       "piecewise-affine cells."),
        FitOption("fill_missing", "--fill-missing", "flag", default=False,
                  help="Grid method: fill lattice nodes without measurements from their neighbours "
                       "(listed as a warning) instead of refusing the grid."),
    )))

register(Method(
    "parametric", "postproc.engine.parametric:ParametricEngine", "postproc.engine.parametric_fit:fit",
    from_tables=True,
    options=(
        FitOption("knot_spacing", "--knot-spacing", "float", metavar="MM",
                  help="Parametric identification: B-spline knot spacing (default: from the data)."),
        FitOption("order", "--order", "choice", default="first", choices=("first", "second", "exact"), tables=True,
                  help="Parametric: forward-model order stored in the calibration (default: first)."),
        FitOption("solver", "--solver", "choice", default="newton", choices=("newton", "astatic"), tables=True,
                  help="Parametric: inverse solver stored in the calibration (default: newton)."),
    )))

register(Method("identity", "postproc.engine.identity:IdentityEngine"))
