"""Axis error tables of a machine in the formats.md files, through the project's own
readers and writers (:mod:`postproc.engine.parametric_tables`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from postproc.engine.parametric_tables import (
    AXES,
    AxisTables,
    Squareness,
    format_squareness,
    format_tables,
    read_squareness,
    read_tables,
)
from postproc.fileio import atomic_write_texts
from postproc.simulate.machine import AxisErrors


def to_axis_tables(tables: dict[str, AxisErrors]) -> AxisTables:
    """Machine tables -> :class:`AxisTables` (an axis without a table gets zeros)."""
    pos, err = {}, {}
    for ax in AXES:
        t = tables.get(ax)
        pos[ax] = t.position if t is not None else np.array([0.0, 1.0])
        err[ax] = t.values if t is not None else np.zeros((2, 6))
    return AxisTables(pos, err)


def from_axis_tables(tables: AxisTables) -> dict[str, AxisErrors]:
    return {ax: AxisErrors(tables.position_mm[ax], tables.errors[ax]) for ax in AXES}


def axis_errors_text(tables: dict[str, AxisErrors], squareness: dict[str, float],
                     comments: list[str] | None = None) -> tuple[str, str]:
    """(tables text, squareness text) in the formats.md form, mm and rad."""
    return (format_tables(to_axis_tables(tables), comments=comments),
            format_squareness(Squareness(**squareness), comments=comments))


def write_axis_errors(tables_path, squareness_path, tables: dict[str, AxisErrors],
                      squareness: dict[str, float], comments: list[str] | None = None) -> None:
    text, sq_text = axis_errors_text(tables, squareness, comments)
    atomic_write_texts({squareness_path: sq_text, tables_path: text})


def read_axis_errors(path: Path, where: str = "") -> dict[str, AxisErrors]:
    return from_axis_tables(read_tables(path))


def read_squareness_values(path: Path, where: str = "") -> dict[str, float]:
    return read_squareness(path).as_dict()
