"""Feedback correction and pocket-to-pocket self-tuning (seed 003, formulas 7-11).

The first pocket is machined in two passes: a semi-finish pass that leaves the
allowance ``b`` (the wall is meant to come out ``T_ref + b`` thick), then an
ultrasonic thickness map ``[B, Z, T]``, then the finish pass with the feedback
correction (formula 7, 8)::

    K_fb = T_semi - T_ref - b          Y_c = Y_p + K_fb (+ K_dist, formula 11)

A positive ``K_fb`` means "the wall came out that much too thick: cut deeper". The
same correction is reused for the next pockets (formula 9) as long as the thickness
measured after each finish pass stays inside ``[T_min, T_max]``; when a pocket leaves
the band, the next pocket gets a new semi-finish pass and ``K_fb`` is learned again
from it (formula 10).

Coordinates: thickness maps are measured in machine coordinates (B in degrees as
the table reads, Z in mm). Each pocket has an origin ``(B0, Z0)``; corrections are
kept in pocket-local coordinates ``(B - B0, Z - Z0)``, so a correction learned on
pocket j is applied on pocket i at the same place inside the pocket, and the pocket
program is written in those local coordinates (run with a work offset per pocket).

When a K_dist map is given it is applied to the semi-finish passes too, so that
``K_fb`` learns only what K_dist does not explain; the finish pass of pocket i then
adds ``K_fb`` (from pocket j) and pocket i's own K_dist (formula 11).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from postproc.calibration.csvfile import length_scale, read_csv
from postproc.errors import MeasurementError, PostprocError
from postproc.mirror.maps import ConstantCorrection, CorrectionMap, SumCorrection

PLAN_MAGIC = "postproc mirror plan v1"

# Thickness nodes whose Z differs by less than this (mm) are one row for smoothing:
# gauge positions are read to 1 um.
ROW_Z_TOL_MM = 1e-3


@dataclass
class ThicknessMap:
    """Ultrasonic thickness ``[B, Z, T]``: B degrees, Z and T mm (machine coordinates)."""

    b_deg: np.ndarray
    z_mm: np.ndarray
    t_mm: np.ndarray
    path: str = ""
    linenos: np.ndarray | None = None

    @property
    def nodes(self) -> np.ndarray:
        return np.column_stack([self.b_deg, self.z_mm])


def read_thickness(path) -> ThicknessMap:
    """Read ``B,Z,T`` (``# units: length=mm|um`` for Z and T)."""
    table = read_csv(path)
    table.require_rows("thickness rows", "give one B,Z,T measurement per row after the header")
    scale = length_scale(table)
    return ThicknessMap(table.numeric("B"), table.numeric("Z") * scale, table.numeric("T") * scale,
                        str(path), np.asarray(table.linenos))


@dataclass
class Band:
    t_ref: float
    t_min: float
    t_max: float

    def __post_init__(self) -> None:
        if not self.t_min <= self.t_ref <= self.t_max:
            raise PostprocError(
                f"the band [{self.t_min}, {self.t_max}] must contain T_ref {self.t_ref}",
                hint="e.g. --t-ref 2.0 --band 1.98,2.02 (mm)",
            )

    def check(self, thk: ThicknessMap) -> tuple[bool, str]:
        """(inside, description of the worst point)."""
        lo, hi = float(thk.t_mm.min()), float(thk.t_mm.max())
        inside = lo >= self.t_min and hi <= self.t_max
        if inside:
            return True, f"T {lo:.4f}..{hi:.4f} inside [{self.t_min:.4f}, {self.t_max:.4f}]"
        i = int(np.argmax(thk.t_mm)) if hi > self.t_max else int(np.argmin(thk.t_mm))
        line = f" ({Path(thk.path).name}:{int(thk.linenos[i])})" if thk.linenos is not None else ""
        return False, (f"T {thk.t_mm[i]:.4f} at B={thk.b_deg[i]:.3f} Z={thk.z_mm[i]:.3f}{line} "
                       f"outside [{self.t_min:.4f}, {self.t_max:.4f}]")


def kfb_values(semi: ThicknessMap, t_ref: float, allowance: float) -> np.ndarray:
    """Formula (7): K_fb = T_semi - T_ref - b at each measured node (mm)."""
    return semi.t_mm - t_ref - allowance


def kfb_map(semi: ThicknessMap, *, t_ref: float, allowance: float, b0: float, z0: float,
            apply_axis: str = "Y", sign: float = 1.0, name: str = "kfb",
            outside: str = "refuse", smooth: int = 1) -> CorrectionMap:
    """K_fb as a correction map in pocket-local coordinates ``(B - B0, Z - Z0)``.

    ``smooth``: odd number of neighbouring nodes along B averaged in each Z row (the
    seed's smoothing of the thickness signal before K_fb); 1 = none.
    """
    nodes = np.column_stack([semi.b_deg - b0, semi.z_mm - z0])
    from postproc.mirror.maps import _check_duplicates

    linenos = semi.linenos if semi.linenos is not None else np.arange(1, len(nodes) + 1)
    _check_duplicates(nodes, linenos, semi.path)
    values = kfb_values(semi, t_ref, allowance)
    if smooth != 1:
        values = smooth_rows(nodes, values, smooth, semi.path)
    return CorrectionMap(name, ("B", "Z"), nodes, values,
                         apply_axis=apply_axis, sign=sign, outside=outside, path=semi.path,
                         linenos=linenos)


def smooth_rows(nodes: np.ndarray, values: np.ndarray, window: int, path: str = "") -> np.ndarray:
    """Centred moving average of ``window`` nodes along B within each row of equal Z.

    Near the row ends the window shrinks symmetrically (the end node keeps its own
    value), so a linear trend along the row is left unchanged.
    """
    if window < 1 or window % 2 == 0:
        raise MeasurementError(f"smoothing window {window} must be an odd number of nodes", path=path,
                               hint="e.g. --smooth 3 (each node averaged with one neighbour each side)")
    half = window // 2
    out = values.copy()
    rows = np.round(nodes[:, 1] / ROW_Z_TOL_MM).astype(np.int64)
    for key in np.unique(rows):
        idx = np.flatnonzero(rows == key)
        idx = idx[np.argsort(nodes[idx, 0])]
        v = values[idx]
        for k in range(len(idx)):
            h = min(half, k, len(idx) - 1 - k)
            out[idx[k]] = v[k - h:k + h + 1].mean()
    return out


# -- the plan ------------------------------------------------------------------------


@dataclass
class Pocket:
    """One pocket of the plan: origin and the thickness maps measured so far."""

    name: str
    b0: float
    z0: float
    semi: str | None = None  # thickness after a semi-finish pass (path)
    finish: str | None = None  # thickness after the finish pass (path)
    lineno: int | None = None


@dataclass
class Decision:
    """What the self-tuning says for one pocket.

    ``semi_pass``: this pocket gets (or got) a semi-finish pass and K_fb is learned
    from it; ``k_from``: the pocket whose semi-finish map gives the K_fb used in this
    pocket's finish pass; ``next``: the action still to do ("" when the pocket is done);
    ``band_ok``: whether its finish thickness is inside the band (None: not measured).
    """

    pocket: Pocket
    semi_pass: bool
    reason: str
    k_from: str | None = None
    next: str = ""
    band_ok: bool | None = None
    band_note: str = ""
    finish_stats: dict = field(default_factory=dict)


def read_plan(path) -> list[Pocket]:
    """``pocket,B0,Z0,semi,finish`` (``semi``/``finish``: thickness files, may be empty).

    ``path`` may be a directory holding ``plan.csv``. Relative file names are taken
    from the plan's directory.
    """
    p = Path(path)
    if p.is_dir():
        p = p / "plan.csv"
    table = read_csv(p)
    if not table.comments or table.comments[0].strip() != PLAN_MAGIC:
        raise MeasurementError(f"not a mirror plan (first line is not '# {PLAN_MAGIC}')", path=str(p),
                               lineno=1, col=1, hint=f"start the file with '# {PLAN_MAGIC}'")
    scale = length_scale(table)
    names = table.text("pocket")
    b0 = table.numeric("B0")
    z0 = table.numeric("Z0", default=0.0) * scale
    semi = table.text("semi") if table.has("semi") else [""] * len(names)
    fin = table.text("finish") if table.has("finish") else [""] * len(names)
    out = []
    seen: dict[str, int] = {}
    for i, name in enumerate(names):
        name = name.strip()
        if not name or name in seen:
            raise MeasurementError(f"pocket name {name!r} is empty or repeats line {seen.get(name)}",
                                   path=str(p), lineno=table.linenos[i], col=1)
        seen[name] = table.linenos[i]
        files: list[str | None] = []
        for cell, col in ((semi[i], "semi"), (fin[i], "finish")):
            cell = cell.strip()
            if not cell:
                files.append(None)
                continue
            f = Path(cell) if Path(cell).is_absolute() else p.parent / cell
            if not f.is_file():
                raise MeasurementError(f"{col} thickness file {cell!r} not found", path=str(p),
                                       lineno=table.linenos[i],
                                       hint="names are relative to the plan's directory; leave the cell "
                                            "empty if that pass is not measured yet")
            files.append(str(f))
        out.append(Pocket(name, float(b0[i]), float(z0[i]), files[0], files[1], table.linenos[i]))
    if not out:
        raise MeasurementError("the plan lists no pockets", path=str(p))
    return out


def self_tune(pockets: list[Pocket], band: Band, allowance: float, plan_path: str = "") -> list[Decision]:
    """Replay formula (10) over the pockets in order; stop at the first pocket not finished.

    Returns one decision per pocket up to and including the next one to machine.
    """
    decisions = _replay(pockets, band, allowance, plan_path)
    done = len(decisions)
    later = next((pk for pk in pockets[done:] if pk.semi or pk.finish), None)
    if later is not None and decisions[-1].next:
        raise MeasurementError(
            f"pocket {later.name} has measurements, "
            f"but pocket {decisions[-1].pocket.name} before it is not finished",
            path=plan_path, lineno=later.lineno,
            hint="list the pockets in machining order and give every pass's thickness map",
        )
    return decisions


def _replay(pockets: list[Pocket], band: Band, allowance: float, plan_path: str) -> list[Decision]:
    decisions: list[Decision] = []
    source: Pocket | None = None
    relearn_reason = "first pocket: learn K_fb"
    for pk in pockets:
        needed = source is None or relearn_reason != ""
        if source is None or needed or pk.semi is not None:
            reason = relearn_reason if needed else "a semi-finish map was measured: learn K_fb again"
            if pk.semi is None:
                if pk.finish is not None:
                    raise MeasurementError(
                        f"pocket {pk.name} has a finish measurement but no semi-finish one, and the "
                        f"self-tuning called for a semi-finish pass first ({reason})",
                        path=plan_path, lineno=pk.lineno,
                        hint="add the semi-finish thickness map of this pocket to the plan",
                    )
                decisions.append(Decision(pk, True, reason, None,
                                          f"semi-finish pass (allowance {allowance:g} mm), then measure T"))
                return decisions
            source = pk
            dec = Decision(pk, True, reason, pk.name)
        else:
            dec = Decision(pk, False, f"previous pocket inside the band: reuse K_fb of pocket {source.name}",
                           source.name)
        relearn_reason = ""
        if pk.finish is None:
            dec.next = f"finish pass with K_fb from pocket {source.name}, then measure T"
            decisions.append(dec)
            return decisions
        thk = read_thickness(pk.finish)
        ok, note = band.check(thk)
        err = thk.t_mm - band.t_ref
        dec.band_ok, dec.band_note = ok, note
        dec.finish_stats = {"mean_um": 1e3 * float(err.mean()), "max_abs_um": 1e3 * float(np.abs(err).max()),
                            "rms_um": 1e3 * float(np.sqrt(np.mean(err**2)))}
        if not ok:
            relearn_reason = f"pocket {pk.name} left the band: {note}"
        decisions.append(dec)
    return decisions


def pocket_corrections(dec: Decision, pockets: dict[str, Pocket], *, band: Band, allowance: float,
                       apply_axis: str, sign: float, kdist: CorrectionMap | None = None,
                       outside: str = "refuse", smooth: int = 1) -> tuple[SumCorrection | None, SumCorrection | None]:
    """(semi-finish correction, finish correction) for the pocket of ``dec``, local coordinates.

    The semi-finish correction is the allowance (``-b`` in the cut-deeper sense) plus the
    pocket's K_dist; the finish correction is K_fb (from ``dec.k_from``) plus K_dist.
    The finish correction is None while K_fb is unknown (semi-finish not measured).
    """
    pk = dec.pocket
    dist = []
    if kdist is not None:
        # K_dist is measured in machine B, Z: in pocket-local coordinates it is shifted by -origin.
        if kdist.apply_axis != apply_axis or kdist.sign != sign:
            raise PostprocError(
                f"the K_dist map cuts deeper along {'+' if kdist.sign > 0 else '-'}{kdist.apply_axis}, "
                f"the pockets along {'+' if sign > 0 else '-'}{apply_axis}",
                path=kdist.path,
                hint="make both with the same --thinner-direction",
            )
        local = replace(kdist.shifted({"B": -pk.b0, "Z": -pk.z0}), name=f"kdist@{pk.name}", outside=outside)
        dist = [local]
    semi = SumCorrection(f"semi:{pk.name}",
                         [ConstantCorrection("allowance", apply_axis, -allowance, sign), *dist])
    if dec.k_from is None:
        return semi, None
    src = pockets[dec.k_from]
    kfb = kfb_map(read_thickness(src.semi), t_ref=band.t_ref, allowance=allowance, b0=src.b0, z0=src.z0,
                  apply_axis=apply_axis, sign=sign, name=f"kfb@{src.name}", outside=outside, smooth=smooth)
    return semi, SumCorrection(f"finish:{pk.name}", [kfb, *dist])
