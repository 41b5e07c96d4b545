"""Measurements as the diagnostics see them: arrays plus where each row came from."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from postproc.effects.base import DIR_COLUMNS

# Repeated points are rows whose commanded point, tool vector and context agree to
# this many decimals (mm, or the context column's own unit): text files round-trip
# numbers far finer than this, distinct points differ by far more.
REPEAT_DECIMALS = 6
# Rows at the same point whose times differ by at most this (seconds, between
# consecutive shots) are repeats: warm-up drifts have time constants of tens of
# minutes, so a minute moves the machine by a few percent of the drift at most.
REPEAT_TIME_S = 60.0
# ... or within this many of the campaign's median time steps between rows (shots of one
# point taken one after the other, in a campaign slower than a shot a minute).
REPEAT_TIME_STEPS = 3.0


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

    def __len__(self) -> int:
        return len(self.q)

    @classmethod
    def from_measurements(cls, items) -> Dataset:
        items = list(items)
        common = set.intersection(*(set(m.context_full()) for m in items)) if items else set()
        ctx = {k: np.concatenate([np.asarray(m.context_full()[k], dtype=float) for m in items])
               for k in sorted(common)}
        sources = np.concatenate([np.full(len(m), m.path, dtype=object) for m in items])
        linenos = np.concatenate([
            np.asarray(m.linenos, dtype=int) if m.linenos is not None else np.zeros(len(m), dtype=int)
            for m in items
        ])
        return cls(
            q=np.vstack([m.q for m in items]).astype(float),
            m=np.vstack([m.m for m in items]).astype(float),
            r=np.vstack([m.r for m in items]).astype(float),
            ctx=ctx, sources=sources, linenos=linenos, paths=[m.path for m in items],
        )

    def subset(self, idx) -> Dataset:
        return Dataset(
            q=self.q[idx], m=self.m[idx], r=self.r[idx],
            ctx={k: v[idx] for k, v in self.ctx.items()},
            sources=None if self.sources is None else self.sources[idx],
            linenos=None if self.linenos is None else self.linenos[idx],
            paths=self.paths,
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
        """(N,) group id: rows with the same commanded point, tool vector and context.

        Time ``t`` is compared with a tolerance: shots at one point a few seconds
        apart are repeats (REPEAT_TIME_S).
        """
        cols = [self.q, self.r] + [v[:, None] for k, v in sorted(self.ctx.items()) if k != "t"]
        key = np.round(np.hstack(cols), REPEAT_DECIMALS)
        _, inverse = np.unique(key, axis=0, return_inverse=True)
        groups = inverse.ravel()
        if "t" not in self.ctx or len(self) == 0:
            return groups
        t = self.ctx["t"]
        order = np.lexsort((t, groups))
        new = np.ones(len(order), dtype=bool)
        same = groups[order][1:] == groups[order][:-1]
        # a slow campaign's consecutive shots are farther apart: a few of its row steps still count
        steps = np.diff(np.sort(t))
        steps = steps[steps > 0]
        window = max(REPEAT_TIME_S, REPEAT_TIME_STEPS * float(np.median(steps))) if len(steps) else REPEAT_TIME_S
        close = np.diff(t[order]) <= window
        new[1:] = ~(same & close)
        out = np.empty(len(self), dtype=int)
        out[order] = np.cumsum(new) - 1
        return out

    def place(self, i: int) -> str:
        src = "" if self.sources is None else str(self.sources[i])
        line = 0 if self.linenos is None else int(self.linenos[i])
        return f"{src}:{line}" if line else (src or f"row {i + 1}")
