"""Measurements as the diagnostics see them: arrays plus where each row came from."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from postproc.effects.base import DIR_COLUMNS

# Repeated points are rows whose commanded point and tool vector agree within this (mm):
# a tracker resolves about a micrometre; distinct points of a campaign differ by far more.
REPEAT_POSITION_MM = 1e-3
# A context column with at most this many distinct values is discrete (load steps, a
# spindle on/off flag): repeats must agree on it exactly ...
DISCRETE_VALUES = 5
# ... a continuous one (temperature, humidity) may differ within a group by up to this
# fraction of its range over the campaign (the sensor's noise, logged per shot).
CONTEXT_SPLIT_FRACTION = 0.02
# ... or by up to this many times its row-to-row scatter in file order (robust sigma of
# consecutive differences), whichever is larger.
CONTEXT_NOISE_FACTOR = 5.0
# Rows at the same point whose times differ by at most this (seconds, between
# consecutive shots) are repeats: warm-up drifts have time constants of tens of
# minutes, so a minute moves the machine by a few percent of the drift at most.
REPEAT_TIME_S = 60.0


# A context column present in fewer than this fraction of the rows is sparse: warned
# about, with the count, and interpolated in time where a time column exists.
MIN_PRESENT_FRACTION = 0.8
# A continuous column whose value stays the same for at least this many consecutive rows
# (median run, in time order) was logged by sample and hold, not per shot: its steps
# are the logging interval, not the quantity.
HELD_RUN_ROWS = 4


def _runs(v: np.ndarray) -> np.ndarray:
    """Indices of the first row of each run of equal consecutive values."""
    return np.r_[0, np.nonzero(v[1:] != v[:-1])[0] + 1]


def screen_columns(ctx: dict[str, np.ndarray]) -> tuple[dict[str, np.ndarray], list[dict]]:
    """Context columns checked before use: (columns to use, notes).

    A column missing in some rows (empty cells, NaN) or logged by sample and hold is
    interpolated in time, linearly between the rows (or the sample times) where it was
    logged, when a time column ``t`` exists (a discrete setting, a few values such as
    load steps, is held from its last logged value instead); without ``t`` a column with
    gaps is not used. A note with the count is made for each column handled, and for
    any column present in fewer than MIN_PRESENT_FRACTION of the rows.
    """
    out, notes = {}, []
    t = ctx.get("t")
    if t is not None and not np.all(np.isfinite(t)):
        t = None  # a time column with gaps orders nothing: as if there were none
    order = np.argsort(t, kind="stable") if t is not None else None
    for name, v in ctx.items():
        v = np.asarray(v, dtype=float)
        n = len(v)
        present = np.isfinite(v)
        k = int(present.sum())
        if name in DIR_COLUMNS or name == "t" or n == 0:
            out[name] = v
            continue
        # a setting (load steps) takes a few values, each logged many times
        levels = len(np.unique(v[present]))
        discrete = levels <= DISCRETE_VALUES and levels <= k / 2
        note = {"column": name, "rows": n, "present": k, "used": True}
        if k < n:
            if t is None or k < 2:
                why = "no time column to interpolate it" if t is None else "fewer than 2 logged values"
                notes.append({**note, "kind": "sparse", "used": False,
                              "message": f"{name} is present in {k} of {n} rows: not used ({why})"})
                continue
            ts, vs, ps = t[order], v[order], present[order]
            if discrete:
                last = np.maximum.accumulate(np.where(ps, np.arange(n), 0))
                filled = np.where(ps | (np.cumsum(ps) > 0), vs[last], vs[np.argmax(ps)])
                how = "held from its last logged value"
            else:
                filled = np.interp(ts, ts[ps], vs[ps])
                how = "interpolated linearly in time between them"
            v = np.empty(n)
            v[order] = filled
            sparse = k < MIN_PRESENT_FRACTION * n
            notes.append({**note, "kind": "sparse" if sparse else "gaps",
                          "message": f"{name} is present in {k} of {n} rows"
                                     f"{' (fewer than ' + format(MIN_PRESENT_FRACTION, '.0%') + ')' if sparse else ''}: "
                                     f"{how}; an effect fitted on it rests on {k} readings"})
        elif t is not None and not discrete and n >= 2 * HELD_RUN_ROWS:
            vs, ts = v[order], t[order]
            first = _runs(vs)
            lengths = np.diff(np.r_[first, n])
            if len(first) > 1 and float(np.median(lengths)) >= HELD_RUN_ROWS:
                # each value was read at the first row that shows it, then held
                v = np.empty(n)
                v[order] = np.interp(ts, ts[first], vs[first])
                step = float(np.median(np.diff(ts[first])))
                notes.append({**note, "kind": "held", "changes": len(first),
                              "message": f"{name} is piecewise constant: {len(first)} values over {n} rows "
                                         f"(sample and hold, about every {step / 60:.0f} min): interpolated "
                                         "linearly in time between the readings"})
        out[name] = v
    return out, notes


def _split_by_gaps(groups: np.ndarray, values: np.ndarray, gap: float) -> np.ndarray:
    """Groups split where, sorted by ``values``, consecutive members differ by more than ``gap``."""
    order = np.lexsort((values, groups))
    new = np.ones(len(order), dtype=bool)
    same = groups[order][1:] == groups[order][:-1]
    close = np.diff(values[order]) <= gap
    new[1:] = ~(same & close)
    out = np.empty(len(groups), dtype=int)
    out[order] = np.cumsum(new) - 1
    return out


@dataclass
class Dataset:
    """q, m, r (N, 3) mm; ``ctx`` name -> (N,) (approach directions as dirx/diry/dirz)."""

    q: np.ndarray
    m: np.ndarray
    r: np.ndarray
    ctx: dict[str, np.ndarray] = field(default_factory=dict)
    sources: np.ndarray | None = None  # (N,) file path of each row
    linenos: np.ndarray | None = None  # (N,) file line of each row (0 when unknown)
    paths: list[str] = field(default_factory=list)
    column_notes: list[dict] = field(default_factory=list)  # context columns checked (screen_columns)

    def __len__(self) -> int:
        return len(self.q)

    @classmethod
    def from_measurements(cls, items) -> Dataset:
        items = list(items)
        common = set.intersection(*(set(m.context_full()) for m in items)) if items else set()
        ctx = {k: np.concatenate([np.asarray(m.context_full()[k], dtype=float) for m in items])
               for k in sorted(common)}
        ctx, notes = screen_columns(ctx)
        sources = np.concatenate([np.full(len(m), m.path, dtype=object) for m in items])
        linenos = np.concatenate([
            np.asarray(m.linenos, dtype=int) if m.linenos is not None else np.zeros(len(m), dtype=int)
            for m in items
        ])
        return cls(
            q=np.vstack([m.q for m in items]).astype(float),
            m=np.vstack([m.m for m in items]).astype(float),
            r=np.vstack([m.r for m in items]).astype(float),
            ctx=ctx, sources=sources, linenos=linenos, paths=[m.path for m in items], column_notes=notes,
        )

    def subset(self, idx) -> Dataset:
        return Dataset(
            q=self.q[idx], m=self.m[idx], r=self.r[idx],
            ctx={k: v[idx] for k, v in self.ctx.items()},
            sources=None if self.sources is None else self.sources[idx],
            linenos=None if self.linenos is None else self.linenos[idx],
            paths=self.paths, column_notes=self.column_notes,
        )

    def with_m(self, m: np.ndarray) -> Dataset:
        out = self.subset(slice(None))
        out.m = m
        return out

    def to_measurements(self):
        """A Measurements object for the method fitters (context split back into dir columns)."""
        from postproc.calibration.measurements import Measurements

        direction = None
        if any(c in self.ctx for c in DIR_COLUMNS):
            direction = np.column_stack([self.ctx.get(c, np.zeros(len(self))) for c in DIR_COLUMNS])
        context = {k: v for k, v in self.ctx.items() if k not in DIR_COLUMNS}
        return Measurements(q=self.q, m=self.m, r=self.r, direction=direction, context=context,
                            path=",".join(self.paths))

    def repeat_groups(self) -> np.ndarray:
        """(N,) group id: repeated shots of one point.

        Rows are repeats when their commanded point and tool vector agree within
        REPEAT_POSITION_MM, their approach directions and every discrete context column
        (a few values, e.g. load steps) are equal, and every continuous context column
        differs by no more than CONTEXT_SPLIT_FRACTION of its range over the campaign
        (temperature logged per shot with its sensor noise does not split a group).
        Time ``t`` is compared with a tolerance: shots at one point a few seconds
        apart are repeats (REPEAT_TIME_S).
        """
        if len(self) == 0:
            return np.zeros(0, dtype=int)
        pos = np.round(np.hstack([self.q, self.r]) / REPEAT_POSITION_MM)
        exact, loose = [], []
        for k, v in sorted(self.ctx.items()):
            if k == "t":
                continue
            if k in DIR_COLUMNS or len(np.unique(v)) <= DISCRETE_VALUES:
                exact.append(v[:, None])
            else:
                loose.append(v)
        key = np.hstack([pos, *exact]) if exact else pos
        _, inverse = np.unique(key, axis=0, return_inverse=True)
        groups = inverse.ravel()
        for v in loose:
            # the column's own row-to-row scatter (a sensor's noise) never splits a group
            jitter = CONTEXT_NOISE_FACTOR * 1.4826 * float(np.median(np.abs(np.diff(v)))) if len(v) > 1 else 0.0
            groups = _split_by_gaps(groups, v, max(CONTEXT_SPLIT_FRACTION * float(np.ptp(v)), jitter))
        if "t" in self.ctx:
            groups = _split_by_gaps(groups, self.ctx["t"], REPEAT_TIME_S)
        return groups

    def place(self, i: int) -> str:
        src = "" if self.sources is None else str(self.sources[i])
        line = 0 if self.linenos is None else int(self.linenos[i])
        return f"{src}:{line}" if line else (src or f"row {i + 1}")
