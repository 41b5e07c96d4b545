"""What the correction pipeline takes from an engine: the residual its solver stands
for, linear extrapolation, the context its effects need (checked up front), and the
engine calls of a run with their safety checks (:class:`EngineCalls`)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING

import numpy as np

from postproc.constants import MM_PER_INCH, SOLVER_ACCEPT_MM
from postproc.errors import (
    CorrectionTooLargeError,
    OutOfVolumeError,
    PostprocError,
    SafetyError,
    SolverError,
)
from postproc.gcode.emitter import _unit_decimals, round_err
from postproc.gcode.options import CorrectOptions, CorrectReport
from postproc.gcode.places import PathArray, file_of, line_list, pick
from postproc.gcode.segment import Curve, subdivide
from postproc.gcode.vplan import FloatArray, IntArray

if TYPE_CHECKING:
    from postproc.engine.base import Engine

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


class EngineCalls:
    """A run's calls of the engine: the corrected points of nominal ones, with every
    safety check (calibrated volume, solver residual, added maps, the largest
    correction) and the figures they keep in the report; the rounding each unit's words
    are written with, checked against the tolerance."""

    def __init__(self, engine: Engine, options: CorrectOptions, report: CorrectReport, rotary: set[str],
                 context: Mapping[str, float], accept_residual_mm: float, path: str | None = None) -> None:
        self.engine = engine
        self.opt = options
        self.report = report
        self.path = path
        self.rotary = rotary  # the rotary axes the program names (the interpreter's set, filled as it reads)
        self.setup_context = dict(context)
        self.accept_residual_mm = accept_residual_mm
        self.units_checked: set[float] = set()

    def rotary_at(self, rot: Sequence[dict[str, float]], rows: IntArray) -> list[dict[str, float]]:
        """The rotary positions (``rot``, by row) of ``rows``, for :meth:`corrected`; none
        where the program names no rotary axis (the engine's context then has none)."""
        return [rot[i] for i in rows.tolist()] if self.rotary else []

    def context(self, dirs: FloatArray, rotary: Sequence[dict[str, float]]) -> dict[str, FloatArray]:
        ctx: dict[str, FloatArray] = {"dirx": dirs[:, 0], "diry": dirs[:, 1], "dirz": dirs[:, 2]}
        for a in sorted(self.rotary):
            ctx[a] = np.array([d.get(a, 0.0) for d in rotary])
        for k, v in self.setup_context.items():
            ctx[k] = np.full(len(dirs), float(v))
        return ctx

    def corrected(self, q_nom: FloatArray, r: FloatArray, dirs: FloatArray, rotary: Sequence[dict[str, float]],
                  lineno: IntArray, files: PathArray | None = None) -> FloatArray:
        """Corrected gauge positions for nominal gauge positions (all safety checks);
        ``lineno``, ``files``: the line of each and its file (None: the program's own,
        :mod:`postproc.gcode.places`), for a refusal."""
        eng = self.engine
        path = self.path
        p = q_nom + r
        ctx = self.context(dirs, rotary)
        inside = eng.inside(q_nom)
        p_eval = p
        if not inside.all():
            bad = np.flatnonzero(~inside)
            if self.opt.extrapolate == "refuse":
                first = q_nom[bad[0]]
                own = file_of(files, int(bad[0]), path)
                raise OutOfVolumeError(
                    f"target outside the calibrated volume at lines {line_list(lineno, files, bad, own, path)}"
                    f": commanded ({first[0]:.3f}, {first[1]:.3f}, "
                    f"{first[2]:.3f}) mm, volume {eng.volume_mm[0].tolist()} .. {eng.volume_mm[1].tolist()} mm",
                    path=own, lineno=int(lineno[bad[0]]),
                    hint="check --offset/--tool-length, or allow it with --extrapolate clamp|linear")
            self.report.extrapolated_points += len(bad)
            if self.opt.extrapolate == "clamp":
                q_eval = np.clip(q_nom, eng.volume_mm[0], eng.volume_mm[1])
                p_eval = q_eval + r
        try:
            res = eng.correction(p_eval, r, ctx)
        except PostprocError as exc:
            raise exc.at(path=file_of(files, 0, path), lineno=int(lineno[0]) if len(lineno) else None) from None
        delta = np.asarray(res.q, dtype=float)
        resid = np.asarray(res.residual_mm, dtype=float)
        bad = ~np.isfinite(delta).all(axis=1) | ~(resid <= self.accept_residual_mm)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            solver = f" {self.report.solver}" if self.report.solver else ""
            raise SolverError(
                f"the {eng.method}{solver} inverse did not converge (residual {resid[i]:.3g} mm, "
                f"accepted up to {self.accept_residual_mm:.3g} mm)",
                path=file_of(files, i, path), lineno=int(lineno[i]),
                hint="the calibration may be unusable here; check it with 'postproc check'")
        if len(resid):
            self.report.max_residual_mm = max(self.report.max_residual_mm, float(resid.max()))
        ctx_added = dict(ctx, lineno=lineno) if self.opt.added else ctx
        for add in self.opt.added:
            try:
                d = np.asarray(add.delta(p, ctx_added), dtype=float)
            except PostprocError as exc:
                # a map names the point it refused (point_index); name its program line
                at = getattr(exc, "point_index", None)
                if at is not None and 0 <= at < len(lineno):
                    raise exc.at(path=file_of(files, at, path), lineno=int(lineno[at])) from None
                raise exc.at(path=path) from None
            if d.shape != delta.shape or not np.isfinite(d).all():
                raise SolverError(f"correction map {add.name!r} gave no finite correction here",
                                  path=file_of(files, 0, path), lineno=int(lineno[0]))
            delta = delta + d
        size = np.linalg.norm(delta, axis=1)
        if len(size):
            i = int(np.argmax(size))
            if size[i] > self.opt.max_correction_mm:
                raise CorrectionTooLargeError(
                    f"correction of {size[i]:.4f} mm exceeds --max-correction {self.opt.max_correction_mm:g} mm",
                    path=file_of(files, i, path), lineno=int(lineno[i]),
                    hint="a correction this large suggests wrong units or a wrong calibration; "
                         "raise --max-correction only if it is real")
            self.report.max_correction_mm = max(self.report.max_correction_mm, float(size[i]))
        return q_nom + delta

    def check_rounding(self, unit: float, lineno: int, path: str | None = None) -> None:
        """Refuse when rounding the words to their decimals alone exceeds the tolerance
        (naming line ``lineno`` of ``path``, the program's own when None)."""
        err = self.round_err(unit)
        if err >= self.opt.tolerance_mm:
            d = _unit_decimals(self.opt, unit)
            raise SafetyError(
                f"words written with {d} decimals in {'inch' if unit == MM_PER_INCH else 'mm'} are rounded by up "
                f"to {err:.3g} mm, more than --tolerance {self.opt.tolerance_mm:g} mm",
                path=path or self.path, lineno=lineno,
                hint=f"give more --decimals or a --tolerance above {err:.3g} mm")
        self.units_checked.add(unit)

    def round_err(self, unit: float) -> float:
        return round_err(self.opt, unit)

    def subdivide(self, curves: list[Curve], s_init: list[FloatArray], unit: float
                   ) -> list[tuple[FloatArray, FloatArray]]:
        rerr = self.round_err(unit)
        line_ids = np.array([c.arc is None for c in curves])
        Q0 = np.array([c.q0 for c in curves], dtype=float)
        Q1 = np.array([c.q1 for c in curves], dtype=float)
        Rr = np.array([c.r for c in curves], dtype=float)
        # the curves' files, in an expanded program (None: all the program's own)
        paths = None if all(c.path is None for c in curves) else np.array([c.path for c in curves], dtype=object)

        def evaluate(cid: np.ndarray, s: np.ndarray) -> np.ndarray:
            nom = np.empty((len(s), 3))
            dirs = np.empty((len(s), 3))
            is_line = line_ids[cid]
            if is_line.any():
                c = cid[is_line]
                nom[is_line] = Q0[c] + (Q1[c] - Q0[c]) * s[is_line, None]
                dd = np.sign(Q1[c] - Q0[c])
                carried = np.array([curves[j].dirs for j in c]).reshape(-1, 3)
                dirs[is_line] = np.where(dd == 0, carried, dd)
            if (~is_line).any():
                for j in np.unique(cid[~is_line]).tolist():
                    sel = cid == j
                    nom[sel] = curves[j].nominal(s[sel])
                    dirs[sel] = curves[j].directions(s[sel])
            rot = [curves[j].rotary for j in cid.tolist()]
            ln = np.array([curves[j].lineno for j in cid.tolist()])
            return self.corrected(nom, Rr[cid], dirs, rot, ln, pick(paths, cid))

        try:
            return subdivide(curves, s_init, evaluate, self.opt.tolerance_mm - rerr)
        except SolverError as exc:
            if self.accept_residual_mm > self.opt.tolerance_mm:
                exc.hint = (f"the {self.report.solver or self.engine.method} solver's answers scatter by up to "
                            f"its residual (largest so far {self.report.max_residual_mm * 1000:.3g} um), more than "
                            f"--tolerance {self.opt.tolerance_mm:g} mm allows: raise --tolerance above that "
                            "residual, or use a calibration with the newton solver")
            raise exc.at(path=self.path) from None
