"""Disturbance correction K_dist from the back-wall sensor (seed 003, formulas 1-4).

The copying head reads the back wall at the cutter axis (point A0) but the flat end
of the cutter forms the pocket bottom at its edge (A1 or A2) when the wall is tilted
by an angle alpha to the cutter face. The thickness error is (formula 1)

    E = R_cutter * 360 / (pi * D) * tan(alpha)

with R_cutter the cutter radius (mm), D the blank (shell) diameter (mm) and tan(alpha)
the slope of the sensor signal V (mm) against the table angle B (degrees), formula 2,
taken as the least-squares line ``V = k B + l`` on each segment (formulas 3-4):

    k = (n sum(B V) - sum(B) sum(V)) / (n sum(B^2) - sum(B)^2),   l = (sum(V) - k sum(B)) / n

``k`` is in mm per degree; ``360 / (pi D)`` turns it into the dimensionless slope of
the wall along the circumference (pi D / 360 mm of arc per degree), so E is in mm.

Sign: the seed gives E with the sign of tan(alpha) and adds it to the program as
``Y_c = Y_p + K_dist`` (formula 6), the same way as the feedback correction
``K_fb = T_meas - T_ref - b`` (formula 7): a positive value means the wall came out
that much too thick and the cutter must go that much deeper. ``model="signed"`` (the
default) follows the seed. ``model="overcut"`` uses the flat-end-mill envelope
instead: whichever way the wall tilts, the face edge cuts R |slope| deeper than the
axis point, so ``E = -R |slope|`` (the wall comes out thinner).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from postproc.calibration.csvfile import length_scale, read_csv
from postproc.errors import MeasurementError
from postproc.mirror.maps import CorrectionMap

KDIST_MODELS = ("signed", "overcut")

# Sensor rows are grouped by Z: rows whose Z differs by less than this (mm) are one
# sweep. Encoders read to 1 um; a helical sweep needs --z-bin instead.
ROW_Z_RESOLUTION_MM = 1e-3

# Fewest sensor points in a segment for a least-squares line (two fix a line; the
# third gives a residual to judge the fit by).
MIN_SEGMENT_POINTS = 3

# A segment whose B values span less than this (degrees) cannot give a slope.
MIN_SEGMENT_SPAN_DEG = 1e-6
# Rounding guard when counting whole segments in a range: a range of exactly n segments
# must not lose one to floating-point division.
SEGMENT_COUNT_GUARD = 1e-9


@dataclass
class SensorData:
    """Back-wall sensor sweep: table angle B (deg), height Z (mm), signal V (mm)."""

    b_deg: np.ndarray
    z_mm: np.ndarray
    v_mm: np.ndarray
    path: str = ""
    linenos: np.ndarray | None = None


@dataclass
class SegmentFit:
    """Least-squares line V = k B + l on one segment of one row."""

    z_mm: float
    b_lo: float
    b_hi: float
    n: int
    k_mm_per_deg: float
    l_mm: float
    slope: float  # k * 360 / (pi D): tan of the wall tilt along the circumference
    e_mm: float  # thickness error E (formula 1) for this segment
    rms_mm: float  # residual of the line fit
    first_line: int | None = None


@dataclass
class KdistResult:
    segments: list[SegmentFit]
    kmap: CorrectionMap
    cutter_radius_mm: float
    diameter_mm: float
    segment_deg: float
    model: str


def read_sensor(path) -> SensorData:
    """Read ``B,Z,V`` (``# units: length=mm|um`` for Z and V; B in degrees)."""
    table = read_csv(path)
    scale = length_scale(table)
    b = table.numeric("B")
    z = table.numeric("Z") * scale
    v = table.numeric("V") * scale
    return SensorData(b, z, v, str(path), np.asarray(table.linenos))


def line_fit(b: np.ndarray, v: np.ndarray) -> tuple[float, float]:
    """Formulas (3)-(4): least-squares k, l of V = k B + l (centred for round-off)."""
    n = len(b)
    bm, vm = b.sum() / n, v.sum() / n
    db = b - bm
    k = float(np.dot(db, v - vm) / np.dot(db, db))
    return k, float(vm - k * bm)


def segment_edges(b_lo: float, b_hi: float, segment_deg: float) -> np.ndarray:
    """Edges from b_lo in steps of segment_deg; a short last piece joins its neighbour."""
    n = max(1, int(np.floor((b_hi - b_lo) / segment_deg + SEGMENT_COUNT_GUARD)))
    edges = b_lo + segment_deg * np.arange(n + 1)
    edges[-1] = b_hi
    return edges


def fit_kdist(
    data: SensorData,
    *,
    cutter_radius_mm: float,
    diameter_mm: float,
    segment_deg: float,
    z_bin_mm: float | None = None,
    model: str = "signed",
    apply_axis: str = "Y",
    sign: float = 1.0,
) -> KdistResult:
    """Segment fits and the K_dist map ``[B, Z, K]`` (value = E of the segment, mm).

    Map nodes, per row: the first segment's start, each segment's centre, and the
    last segment's end (the end nodes repeat the end segments' E, so the
    map covers the measured range and the seed's "constant on each segment" holds at
    the ends). With one row the map has the single coordinate B.
    """
    if cutter_radius_mm <= 0 or diameter_mm <= 0 or segment_deg <= 0:
        raise MeasurementError("cutter radius, diameter and segment length must be positive",
                               path=data.path, hint="e.g. --cutter-radius 10 --diameter 2000 --segment-deg 5")
    if model not in KDIST_MODELS:
        raise MeasurementError(f"unknown K_dist model {model!r}", hint=f"one of {', '.join(KDIST_MODELS)}")
    per_deg = 360.0 / (np.pi * diameter_mm)
    rows = _rows(data, z_bin_mm)
    edges = segment_edges(float(data.b_deg.min()), float(data.b_deg.max()), segment_deg)
    segments: list[SegmentFit] = []
    nodes, values = [], []
    for z_row, idx in rows:
        b, v = data.b_deg[idx], data.v_mm[idx]
        cell = np.clip(np.searchsorted(edges, b, side="right") - 1, 0, len(edges) - 2)
        row_segments = []
        for s in range(len(edges) - 1):
            sel = cell == s
            if not np.any(sel):
                continue
            bs, vs = b[sel], v[sel]
            first = int(data.linenos[idx[sel][0]]) if data.linenos is not None else None
            if len(bs) < MIN_SEGMENT_POINTS or np.ptp(bs) < MIN_SEGMENT_SPAN_DEG:
                raise MeasurementError(
                    f"segment B {edges[s]:.3f}..{edges[s + 1]:.3f} deg at Z={z_row:.3f} has "
                    f"{len(bs)} point(s) over {np.ptp(bs):.4f} deg: too few for a line",
                    path=data.path, lineno=first,
                    hint=f"use a longer --segment-deg (at least {MIN_SEGMENT_POINTS} distinct B per segment)",
                )
            k, l_mm = line_fit(bs, vs)
            slope = k * per_deg
            e = cutter_radius_mm * slope if model == "signed" else -cutter_radius_mm * abs(slope)
            rms = float(np.sqrt(np.mean((vs - (k * bs + l_mm)) ** 2)))
            row_segments.append(SegmentFit(z_row, float(edges[s]), float(edges[s + 1]), len(bs), k, l_mm,
                                           slope, e, rms, first))
        segments += row_segments
        mids = [0.5 * (sg.b_lo + sg.b_hi) for sg in row_segments]
        b_row = [row_segments[0].b_lo, *mids, row_segments[-1].b_hi]
        e_row = [row_segments[0].e_mm] + [sg.e_mm for sg in row_segments] + [row_segments[-1].e_mm]
        for bb, ee in zip(b_row, e_row, strict=True):
            nodes.append((bb, z_row))
            values.append(ee)
    nodes_arr = np.asarray(nodes)
    values_arr = np.asarray(values)
    nodes_arr, keep = _dedupe(nodes_arr)
    values_arr = values_arr[keep]
    if len(rows) == 1:
        kmap = CorrectionMap("kdist", ("B",), nodes_arr[:, :1], values_arr, apply_axis=apply_axis, sign=sign)
    else:
        kmap = CorrectionMap("kdist", ("B", "Z"), nodes_arr, values_arr, apply_axis=apply_axis, sign=sign)
    return KdistResult(segments, kmap, cutter_radius_mm, diameter_mm, segment_deg, model)


def _dedupe(nodes: np.ndarray):
    """Drop an end node that falls on a segment centre (a one-segment row of 2 points...)."""
    _, keep = np.unique(np.round(nodes, 9), axis=0, return_index=True)
    keep = np.sort(keep)
    return nodes[keep], keep


def _rows(data: SensorData, z_bin_mm: float | None) -> list[tuple[float, np.ndarray]]:
    z = data.z_mm
    if z_bin_mm is not None:
        if z_bin_mm <= 0:
            raise MeasurementError("--z-bin must be positive", path=data.path)
        key = np.floor((z - z.min()) / z_bin_mm + 0.5).astype(int)
    else:
        key = np.round(z / ROW_Z_RESOLUTION_MM).astype(np.int64)
    rows = []
    for kval in np.unique(key):
        idx = np.flatnonzero(key == kval)
        rows.append((float(np.mean(z[idx])), idx))
    if all(len(idx) < MIN_SEGMENT_POINTS for _, idx in rows):
        raise MeasurementError(
            f"{len(rows)} distinct Z values with fewer than {MIN_SEGMENT_POINTS} points each: "
            "the sweep is not in rows of constant Z",
            path=data.path,
            hint="group heights into rows with --z-bin MM (e.g. the Z step between sweeps)",
        )
    return rows


def kdist_comments(res: KdistResult, source: str) -> list[str]:
    return [
        f"kdist: E = R*360/(pi*D)*tan(alpha), R={res.cutter_radius_mm:g} mm, D={res.diameter_mm:g} mm, "
        f"segments {res.segment_deg:g} deg, model {res.model}",
        f"source: {Path(source).name}",
        "value: thickness excess (mm); positive = cut deeper by that much",
    ]
