"""What the correction pipeline takes from an engine: the residual its solver stands
for, linear extrapolation, and the context its effects need (checked up front)."""

from __future__ import annotations

from postproc.constants import SOLVER_TOL_MM
from postproc.errors import PostprocError

# A solver answer is accepted up to ten times its own stopping tolerance (float noise
# in the residual itself); still a thousand times below the default path tolerance.
# An engine whose solver stands for larger residuals says so in ``accept_residual_mm``
# (the parametric astatic solver: one grid step); the larger of the two applies.
SOLVER_ACCEPT_MM = 10 * SOLVER_TOL_MM
# Context columns the pipeline itself supplies: approach directions always, rotary
# positions when the program moves them (checked when the first inverse is called).
PIPELINE_CONTEXT = ("dirx", "diry", "dirz", "A", "B", "C")


def engine_attr(engine, name: str):
    """``engine.name``, or that of the base engine a composed engine wraps; None if neither."""
    value = getattr(engine, name, None)
    if value is None and getattr(engine, "base", None) is not None:
        value = getattr(engine.base, name, None)
    return value


def accept_residual(engine) -> float:
    """Largest inverse residual (mm) the pipeline accepts from ``engine``."""
    own = engine_attr(engine, "accept_residual_mm")
    return max(SOLVER_ACCEPT_MM, float(own)) if own is not None else SOLVER_ACCEPT_MM


def prepare_engine(engine, extrapolate: str, context_names, path: str | None = None):
    """The engine as a run uses it.

    - ``extrapolate="linear"``: an engine with ``with_options`` (parametric) is switched
      to linear extrapolation of its functions (by default it holds their end
      values); a composed engine gets its base switched. Static, interval and grid
      engines extrapolate with their model as it is (see docs/gcode.md).
    - An engine with ``check_context`` (a base engine plus effects) is asked up front
      whether the context values its effects need are given, so a missing
      ``--context`` is refused before any line is processed.
    """
    if extrapolate == "linear":
        if hasattr(engine, "with_options"):
            engine = engine.with_options(extrapolate="linear")
        elif hasattr(getattr(engine, "base", None), "with_options") and hasattr(engine, "effects"):
            engine = type(engine)(engine.base.with_options(extrapolate="linear"), engine.effects)
    check = getattr(engine, "check_context", None)
    if check is not None:
        try:
            check(set(PIPELINE_CONTEXT) | set(context_names))
        except PostprocError as exc:
            raise exc.at(path=path) from None
    return engine
