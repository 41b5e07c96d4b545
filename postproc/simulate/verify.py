"""Run NC programs through a virtual machine and measure how far the tool point
strays from the nominal path.

The nominal path is the original program's functional-point path: the end points of
straight moves, and arcs cut into chords that stay within :data:`NOMINAL_CHORD_MM` of
them. A program (original or corrected) is sampled along every move, its
commanded positions ``q = points - tool`` go through ``machine.forward`` and the
deviation of each actual point is its distance from the nominal polyline, not from
the sample of the same index: a corrected program is split and moved, so its samples
are not the original's. Statistics are over feed moves (G1, G2, G3); rapids are
left out, their path between end points being the controller's choice.

That distance is one-sided: a program that stops early or skips a stretch leaves
every point it does reach on the path. So the other direction is measured too: the
distance of each nominal sample (the original program sampled like the run) from
the *actual* path, the polyline of the run's actual points, sampled along straight
moves at the run step and along arcs in chords within :data:`NOMINAL_CHORD_MM`. The
headline maximum is the larger of the two (a Hausdorff-type distance).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial import cKDTree

from postproc.effects.base import DIR_COLUMNS
from postproc.gcode.directions import MACHINE_STEP_MM
from postproc.gcode.places import PathArray
from postproc.simulate.machine import Machine

#: Commanded motions smaller than this between two samples are float noise, carried as
#: no motion (as :func:`postproc.gcode.path.motion_signs` does).
MOTION_EPS_MM = 1e-9

if TYPE_CHECKING:
    from postproc.gcode.path import ProgramPath

#: Chord tolerance of the nominal path (mm): arcs are cut into chords that bulge from
#: the arc by at most this much, the most a deviation can be overstated by; a hundred
#: times below the micrometre that verify reports. Straight moves need no samples.
NOMINAL_CHORD_MM = 1e-5

#: Longest piece of the nominal path in the nearest-segment index (mm). Long moves are
#: cut into such pieces so that the candidate search radius (distance + half a piece)
#: stays small; it does not change any distance.
INDEX_PIECE_MM = 2.0

#: Nearest piece midpoints measured first for each point; enough that the K-th is
#: almost always far enough to rule out the rest (else a radius search settles it).
NEAREST_K = 16

#: Threads of the k-nearest query (-1: every core); the answer does not depend on it.
QUERY_WORKERS = -1

#: Points queried at once against the nominal path (bounds the candidate lists' memory).
QUERY_CHUNK = 100_000

#: Sampling step of the program runs (mm): the verify --max-step default.
RUN_STEP_MM = 0.5

#: How many of the worst program lines a report lists.
WORST_LINES = 5


def point_segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance (N,) of points p from segments [a, b] (all (N, 3))."""
    ab = b - a
    den = np.sum(ab * ab, axis=1)
    safe = np.where(den > 0, den, 1.0)
    t = np.clip(np.sum((p - a) * ab, axis=1) / safe, 0.0, 1.0)
    t = np.where(den > 0, t, 0.0)
    return np.linalg.norm(p - (a + t[:, None] * ab), axis=1)


class Polyline:
    """Segments between consecutive points, with a fast nearest-segment query.

    ``keep`` (bool per segment) leaves segments out; segments longer than
    ``piece_mm`` are indexed as several pieces (the answer still names the segment).
    """

    def __init__(self, points, keep=None, piece_mm: float = INDEX_PIECE_MM) -> None:
        pts = np.asarray(points, dtype=float)
        a, b = pts[:-1], pts[1:]
        idx = np.arange(len(a))
        if keep is not None:
            idx = idx[np.asarray(keep, dtype=bool)]
        if len(idx) == 0:
            raise ValueError("a path needs at least one segment")
        a, b = a[idx], b[idx]
        n_pieces = np.maximum(1, np.ceil(np.linalg.norm(b - a, axis=1) / piece_mm).astype(int))
        owner = np.repeat(np.arange(len(a)), n_pieces)
        k = np.arange(len(owner)) - np.repeat(np.cumsum(n_pieces) - n_pieces, n_pieces)
        frac0 = (k / n_pieces[owner])[:, None]
        frac1 = ((k + 1) / n_pieces[owner])[:, None]
        d = b[owner] - a[owner]
        self.a, self.b = a[owner] + frac0 * d, a[owner] + frac1 * d
        self.index = idx[owner]
        self.half_len = 0.5 * float(np.max(np.linalg.norm(self.b - self.a, axis=1)))
        self.tree = cKDTree(0.5 * (self.a + self.b))

    def nearest(self, p) -> tuple[np.ndarray, np.ndarray]:
        """(distance (N,), segment index (N,)) of the nearest segment to each point.

        Exact: a piece whose midpoint is at distance m from p is at least m - h from it
        (h: half the longest piece). The pieces of the K nearest midpoints are measured;
        a point whose K-th midpoint is not far enough to rule out all others is asked
        again with four times as many (overlapping passes put many pieces near a point).
        """
        p = np.asarray(p, dtype=float)
        if len(p) > QUERY_CHUNK:
            parts = [self.nearest(p[i:i + QUERY_CHUNK]) for i in range(0, len(p), QUERY_CHUNK)]
            return np.concatenate([d for d, _ in parts]), np.concatenate([s for _, s in parts])
        best = np.full(len(p), np.inf)
        seg = np.zeros(len(p), dtype=int)
        todo = np.arange(len(p))
        n = len(self.a)
        k = NEAREST_K
        while len(todo):
            k = min(k, n)
            q = p[todo]
            # threads only pay on large queries (the later, unsure ones are few)
            dk, ik = self.tree.query(q, k=k, workers=QUERY_WORKERS if len(q) * k > 200_000 else 1)
            dk, ik = dk.reshape(len(todo), k), ik.reshape(len(todo), k)
            dist = point_segment_distance(np.repeat(q, k, axis=0), self.a[ik.ravel()],
                                          self.b[ik.ravel()]).reshape(len(todo), k)
            j = np.argmin(dist, axis=1)
            rows = np.arange(len(todo))
            better = dist[rows, j] < best[todo]
            best[todo[better]] = dist[rows, j][better]
            seg[todo[better]] = ik[rows, j][better]
            sure = (dk[:, -1] - self.half_len >= best[todo]) | (k == n)
            todo = todo[~sure]
            k *= 4
        return best, self.index[seg]


def polyline_distance(points, poly, piece_mm: float = INDEX_PIECE_MM) -> np.ndarray:
    """Distance (N,) of each point from the polyline through ``poly`` (exact)."""
    poly = np.asarray(poly, dtype=float)
    points = np.asarray(points, dtype=float)
    if len(poly) == 1:
        return np.linalg.norm(points - poly[0], axis=1)
    return Polyline(poly, piece_mm=piece_mm).nearest(points)[0]


def _max(d: np.ndarray) -> float:
    return float(d.max()) if len(d) else 0.0


def _rms(d: np.ndarray) -> float:
    return float(np.sqrt(np.mean(d**2))) if len(d) else 0.0


def _empty_floats() -> np.ndarray:
    return np.zeros(0)


def _empty_ints() -> np.ndarray:
    return np.zeros(0, dtype=int)


@dataclass
class Run:
    """One program run on the machine: where the point went and how far from nominal.

    ``deviation_mm``: each actual point's distance from the nominal path (all run
    samples; statistics over feed ones). ``nominal_to_actual_mm``: each nominal feed
    sample's distance from the actual path (empty when not measured).
    """

    label: str
    actual_mm: np.ndarray
    deviation_mm: np.ndarray
    nominal_line: np.ndarray  # original-program line of the nearest nominal segment
    rapid: np.ndarray
    arclength_mm: np.ndarray
    nominal_to_actual_mm: np.ndarray = field(default_factory=_empty_floats)
    nominal_sample_line: np.ndarray = field(default_factory=_empty_ints)  # line of each nominal sample
    nominal_arclength_mm: np.ndarray = field(default_factory=_empty_floats)
    # the file of each nominal_line and nominal_sample_line where it is not the program's
    # own (a subprogram's, the program read expanded; None for its own lines), or None
    # when all are its own (:mod:`postproc.gcode.places`)
    nominal_file: PathArray | None = None
    nominal_sample_file: PathArray | None = None

    @property
    def feed(self) -> np.ndarray:
        return ~self.rapid

    @property
    def actual_to_nominal_max_mm(self) -> float:
        """Largest distance of an actual feed point from the nominal path."""
        return _max(self.deviation_mm[self.feed])

    @property
    def nominal_to_actual_max_mm(self) -> float:
        """Largest distance of a nominal feed sample from the actual path."""
        return _max(self.nominal_to_actual_mm)

    @property
    def nominal_to_actual_rms_mm(self) -> float:
        return _rms(self.nominal_to_actual_mm)

    @property
    def max_mm(self) -> float:
        """Two-sided maximum: the larger of the two directions."""
        return max(self.actual_to_nominal_max_mm, self.nominal_to_actual_max_mm)

    @property
    def rms_mm(self) -> float:
        """RMS distance of the actual feed points from the nominal path."""
        return _rms(self.deviation_mm[self.feed])

    def worst_places(self, n: int = WORST_LINES) -> list[tuple[int, str | None, float]]:
        """The ``n`` original program lines with the largest feed deviation, either
        direction: (line, file, deviation), ``file`` the subprogram's file the line is of
        (None: the program's own)."""
        d = np.concatenate([self.deviation_mm[self.feed], self.nominal_to_actual_mm])
        lines = np.concatenate([self.nominal_line[self.feed], self.nominal_sample_line])
        if not len(d):
            return []
        files = _files_of([(self.nominal_file, self.feed, int(np.count_nonzero(self.feed))),
                           (self.nominal_sample_file, slice(None), len(self.nominal_sample_line))])
        order = np.argsort(-d, kind="stable")
        out: dict[tuple[int, str | None], float] = {}
        for i in order:
            key = (int(lines[i]), None if files is None else files[i])
            if key not in out:
                out[key] = float(d[i])
                if len(out) == n:
                    break
        return [(ln, f, dev) for (ln, f), dev in out.items()]

    def worst_lines(self, n: int = WORST_LINES) -> list[tuple[int, float]]:
        """The ``n`` original program lines with the largest feed deviation, either
        direction: (line, deviation). The lines of an expanded program can be of its
        subprograms' files: :meth:`worst_places` gives the file of each."""
        return [(ln, dev) for ln, _f, dev in self.worst_places(n)]

    def to_dict(self) -> dict:
        return {"label": self.label, "samples": int(len(self.deviation_mm)),
                "feed_samples": int(np.count_nonzero(self.feed)),
                "max_mm": self.max_mm, "rms_mm": self.rms_mm,
                "actual_to_nominal": {"max_mm": self.actual_to_nominal_max_mm, "rms_mm": self.rms_mm,
                                      "samples": int(np.count_nonzero(self.feed))},
                "nominal_to_actual": {"max_mm": self.nominal_to_actual_max_mm,
                                      "rms_mm": self.nominal_to_actual_rms_mm,
                                      "samples": int(len(self.nominal_to_actual_mm))},
                "worst_lines": [{"line": ln, **({} if f is None else {"file": f}), "deviation_mm": d}
                                for ln, f, d in self.worst_places()]}


def _files_of(parts) -> PathArray | None:
    """The files of the rows of several parts, each ``(files, rows, count)``: its rows'
    files (None: all its own) picked by ``rows``, ``count`` of them; None when all are
    the program's own."""
    if all(files is None for files, _rows, _n in parts):
        return None
    return np.concatenate([np.full(n, None, dtype=object) if files is None else np.asarray(files, dtype=object)[rows]
                           for files, rows, n in parts])


def program_lines(path: str) -> list[str]:
    """The text of the lines of the program file at ``path`` (index 0 = line 1), without
    their endings or a byte order mark, numbered as the reader numbers them: a line ends
    only at LF, CRLF or a lone CR (``str.splitlines`` also splits at a form feed, which is
    a blank inside a G-code line, and so would shift every line after it)."""
    from postproc.fileio import read_lines
    from postproc.gcode.source import open_source

    with open_source(path) as fh:
        lines = [ln.rstrip("\r\n") for ln in read_lines(fh, path)]
    if lines and lines[0].startswith("\ufeff"):
        lines[0] = lines[0][1:]
    return lines


@dataclass
class VerifyReport:
    runs: list[Run] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    #: text of the original program's lines (index 0 = line 1), to show the worst ones
    source_lines: list[str] = field(default_factory=list)
    #: text of the lines of the subprograms' files shown so far, by file
    file_lines: dict[str, list[str]] = field(default_factory=dict, repr=False)

    def line_text(self, lineno: int, file: str | None = None) -> str:
        """The text of line ``lineno`` of the original program, or of the subprogram's
        ``file`` it is a line of (read from that file, as the program was read
        expanded); empty where there is no such line, or the file cannot be read."""
        lines = self.source_lines if file is None else self._lines_of(file)
        if 1 <= lineno <= len(lines):
            return lines[lineno - 1].strip()
        return ""

    def _lines_of(self, file: str) -> list[str]:
        if file not in self.file_lines:
            from postproc.errors import PostprocError

            try:
                self.file_lines[file] = program_lines(file)
            except (PostprocError, OSError):
                self.file_lines[file] = []
        return self.file_lines[file]

    def to_dict(self) -> dict:
        runs = []
        for r in self.runs:
            d = r.to_dict()
            for w in d["worst_lines"]:
                w["text"] = self.line_text(w["line"], w.get("file"))
            runs.append(d)
        return {"runs": runs, "notes": list(self.notes)}


@dataclass
class NominalPath:
    """The functional-point path of a program: move end points, and arcs as fine chords."""

    points_mm: np.ndarray
    lineno: np.ndarray
    rapid: np.ndarray
    files: PathArray | None = None  # the file of each sample's line, as ProgramPath.files

    def __len__(self) -> int:
        return len(self.points_mm)


def nominal_path(source, setup, chord_mm: float = NOMINAL_CHORD_MM, *, dialect: str = "generic",
                 subroutine_path=(), limits=None) -> NominalPath:
    """Nominal path of a program (path or text) for measuring deviations against.

    Straight moves contribute their end points only (a straight segment is exact);
    arcs are cut into chords bulging at most ``chord_mm`` from them
    (:func:`postproc.gcode.path.sample_program`).
    """
    from postproc.gcode.path import sample_program

    pp = sample_program(source, setup, chord_mm=chord_mm, dialect=dialect, subroutine_path=subroutine_path,
                        limits=limits)
    return NominalPath(pp.points_mm, pp.lineno, pp.rapid, pp.files)


def actual_path_samples(source, setup, max_step_mm: float = RUN_STEP_MM,
                        chord_mm: float = NOMINAL_CHORD_MM, *, dialect: str = "generic",
                        subroutine_path=(), limits=None) -> ProgramPath:
    """A program (path or text) sampled to draw its actual path as a polyline.

    Straight moves every ``max_step_mm``; arcs also cut into chords within ``chord_mm``
    of them, so that the polyline of the actual points does not cut the corners of
    arcs by the sagitta of a ``max_step_mm`` chord
    (:func:`postproc.gcode.path.sample_program`).
    """
    from postproc.gcode.path import sample_program

    return sample_program(source, setup, step_mm=max_step_mm, chord_mm=chord_mm, dialect=dialect,
                          subroutine_path=subroutine_path, limits=limits)


def machine_directions(q, initial) -> np.ndarray:
    """Approach direction (N, 3) of each axis into each commanded sample ``q`` (N, 3),
    as the machine takes it; ``initial`` (3,): the direction into the first sample.

    An axis reverses when its commanded position has moved back by more than
    :data:`MACHINE_STEP_MM` from the farthest point it reached, however small the
    motion that follows, as a controller's backlash compensation does; where it stands
    the direction is carried. Less is no motion: the machine does not resolve it, and it
    is the rounding noise of a sampled path (an arc of a huge radius computes its points
    to about 1e-16 times its radius).
    """
    q = np.asarray(q, dtype=float)
    out = np.empty_like(q)
    if not len(q):
        return out
    out[0] = initial
    d = np.diff(q, axis=0)
    n = len(d)
    if not n:
        return out
    for k in range(3):
        s = np.sign(np.where(np.abs(d[:, k]) > MOTION_EPS_MM, d[:, k], 0.0))
        # monotone runs of the commanded motion (standing samples carry the direction)
        idx = np.where(s != 0, np.arange(n), -1)
        np.maximum.accumulate(idx, out=idx)
        c = np.where(idx >= 0, s[np.maximum(idx, 0)], 0.0)
        starts = np.flatnonzero(np.r_[True, c[1:] != c[:-1]])
        ends = np.r_[starts[1:], n]
        rdir = c[starts]
        # a run that moves the axis by more than a step reverses it, once it has
        # moved a step from where it began (the farthest point the axis reached)
        real = (rdir != 0) & (np.abs(q[ends, k] - q[starts, k]) > MACHINE_STEP_MM)
        last = np.where(real, np.arange(len(starts)), -1)
        np.maximum.accumulate(last, out=last)
        after = np.where(last >= 0, rdir[np.maximum(last, 0)], float(initial[k]))
        before = np.r_[float(initial[k]), after[:-1]]
        run = np.repeat(np.arange(len(starts)), ends - starts)
        moved = np.abs(q[1:, k] - q[starts[run], k]) > MACHINE_STEP_MM
        out[1:, k] = np.where(real[run] & moved, rdir[run], before[run])
    return out


def machine_run(machine: Machine, path) -> np.ndarray:
    """Actual functional-point positions of a sampled program path on the machine; the
    approach directions are those of the commanded samples (:func:`machine_directions`)."""
    q = np.asarray(path.points_mm) - np.asarray(path.tool_mm)
    ctx = {k: np.asarray(v) for k, v in (path.context or {}).items()}
    if len(q) and all(c in ctx for c in DIR_COLUMNS):
        dirs = machine_directions(q, [float(ctx[c][0]) for c in DIR_COLUMNS])
        ctx.update({c: dirs[:, k] for k, c in enumerate(DIR_COLUMNS)})
    return machine.forward(q, path.tool_mm, ctx)


def nominal_polyline(path) -> Polyline:
    """The nominal path's feed segments (a segment belongs to the move it ends in)."""
    rapid = np.asarray(path.rapid, dtype=bool)
    keep = ~rapid[1:]
    if not keep.any():
        keep = np.ones(len(rapid) - 1, dtype=bool)
    return Polyline(path.points_mm, keep)


def _arclength(points) -> np.ndarray:
    pts = np.asarray(points, dtype=float)
    if not len(pts):
        return np.zeros(0)
    return np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))]


def actual_polyline(machine: Machine, fine_path) -> Polyline:
    """The actual path of a run (``fine_path``: :func:`actual_path_samples`) as feed segments.

    A segment belongs to the move it ends in; a run without feed moves keeps all its
    segments, and a single point is a segment of zero length.
    """
    actual = machine_run(machine, fine_path)
    if len(actual) == 0:
        raise ValueError("a run without samples has no actual path")
    if len(actual) == 1:
        return Polyline(np.vstack([actual, actual]))
    keep = ~np.asarray(fine_path.rapid, dtype=bool)[1:]
    return Polyline(actual, keep if keep.any() else None)


def evaluate_run(label: str, machine: Machine, path, nominal, nominal_lines: np.ndarray,
                 reference=None, fine_path=None, nominal_files: PathArray | None = None) -> Run:
    """Run ``path`` on ``machine`` and measure it against the ``nominal`` path.

    ``nominal_lines``: the line of each point of the nominal path, ``nominal_files`` the
    file of each (:attr:`NominalPath.files`; None: all the program's own).

    With ``reference`` (the original program sampled, a ``ProgramPath``) and
    ``fine_path`` (the run program by :func:`actual_path_samples`), the other
    direction is measured too: each nominal feed sample of ``reference`` against
    the actual path.
    """
    actual = machine_run(machine, path)
    dist, seg = nominal.nearest(actual)
    run = Run(label, actual, dist, np.asarray(nominal_lines)[seg + 1],
              np.asarray(path.rapid, dtype=bool), _arclength(path.points_mm),
              nominal_file=None if nominal_files is None else np.asarray(nominal_files, dtype=object)[seg + 1])
    if reference is not None and fine_path is not None and len(fine_path):
        ref_feed = ~np.asarray(reference.rapid, dtype=bool)
        ref_pts = np.asarray(reference.points_mm)
        run.nominal_to_actual_mm, _ = actual_polyline(machine, fine_path).nearest(ref_pts[ref_feed])
        run.nominal_sample_line = np.asarray(reference.lineno)[ref_feed]
        ref_files = getattr(reference, "files", None)
        run.nominal_sample_file = None if ref_files is None else np.asarray(ref_files, dtype=object)[ref_feed]
        run.nominal_arclength_mm = _arclength(ref_pts)[ref_feed]
    return run


def plot_deviation(report: VerifyReport, ax=None, *, title: str = ""):
    """Deviation (um) along the program, one curve per run; returns the axes."""
    if ax is None:
        from matplotlib.figure import Figure  # no pyplot: no GUI backend, no global state

        ax = Figure(figsize=(10, 4)).subplots()
    for run in report.runs:
        d = np.where(run.feed, run.deviation_mm * 1000.0, np.nan)
        (line,) = ax.plot(run.arclength_mm, d, lw=0.8,
                          label=f"{run.label}: max {run.max_mm * 1000:.1f} um (two-sided), "
                                f"RMS {run.rms_mm * 1000:.1f} um")
        if len(run.nominal_to_actual_mm):
            ax.plot(run.nominal_arclength_mm, run.nominal_to_actual_mm * 1000.0, lw=0.8, ls=":",
                    color=line.get_color(), label=f"{run.label}: nominal -> actual path")
    ax.set_xlabel("path length along the program (mm)")
    ax.set_ylabel("deviation from nominal path (um)")
    ax.set_yscale("symlog", linthresh=1.0)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(loc="best", fontsize="small")
    if title:
        ax.set_title(title)
    return ax
