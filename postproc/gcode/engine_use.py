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


def accept_residual(engine) -> float:
    """Largest inverse residual (mm) the pipeline accepts from ``engine``."""
    return max(SOLVER_ACCEPT_MM, float(engine.accept_residual_mm))


def prepare_engine(engine, extrapolate: str, context_names, path: str | None = None):
    """The engine as a run uses it: switched to ``extrapolate`` ("linear" continues the
    end slopes of table-based models; see :meth:`Engine.with_extrapolation`), and asked up
    front whether the context values its effects need are given, so a missing
    ``--context`` is refused before any line is processed."""
    if extrapolate == "linear":
        engine = engine.with_extrapolation("linear")
    try:
        engine.check_context(set(PIPELINE_CONTEXT) | set(context_names))
    except PostprocError as exc:
        raise exc.at(path=path) from None
    return engine
