"""The controller table formats ``postproc export`` writes, as a registry.

A format is one :class:`TableFormat` entry: its name (the ``--format`` choice), the
``module:function`` that builds its :class:`~postproc.metrology.controllers.base.Export`
from the axes and the :class:`Settings` (imported when the format is used), the
settings it takes beyond the ones every format takes, and whether it writes a folder
of files (one per joint) or one file. ``export`` lists the choices, checks the options
given against the format and calls it from here: a new format is one :func:`register`
call and its builder, nothing in the command.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from postproc.metrology.controllers.axis import AxisErrors
    from postproc.metrology.controllers.base import Export

#: settings a format may take, by the ``export`` option that gives each
SETTING_OPTIONS = {
    "step": "--step",
    "reference": "--reference",
    "return": "--return",
    "parameters": "--parameters",
    "detection_unit": "--detection-unit",
    "comp_type": "--comp-type",
    "axis_names": "--axis-name",
}


@dataclass(frozen=True)
class Settings:
    """What ``export`` was given, checked and in mm: the table spacing (None: the
    calibration's own), the reference point and reference return direction (+1 / -1) by
    axis, the control's parameter tape, the detection unit (None: the format's
    default), LinuxCNC's COMP_FILE_TYPE, the controller's names of the axes and the
    calibration's name."""

    step_mm: float | None = None
    reference_mm: dict[str, float] = field(default_factory=dict)
    return_direction: dict[str, int] = field(default_factory=dict)
    parameters: str | None = None
    detection_unit_mm: float | None = None
    comp_type: int = 0
    axis_names: dict[str, str] = field(default_factory=dict)
    name: str = "calibration"


@dataclass(frozen=True)
class TableFormat:
    """One controller table format: ``builder`` is ``"module:function"``, the function
    taking ``(axis_errors, settings)`` and returning the Export; ``takes``: the settings
    of :data:`SETTING_OPTIONS` it reads; ``folder``: it writes one file per axis into a
    folder, not one file."""

    name: str
    builder: str
    takes: frozenset[str]
    folder: bool = False

    def build(self, axis_errors: list[AxisErrors], settings: Settings) -> Export:
        module, attr = self.builder.split(":")
        fn: Callable[[list[AxisErrors], Settings], Export] = getattr(importlib.import_module(module), attr)
        return fn(axis_errors, settings)

    def unread(self, given: set[str]) -> list[str]:
        """The settings of ``given`` this format does not read, in :data:`SETTING_OPTIONS`' order."""
        return [s for s in SETTING_OPTIONS if s in given and s not in self.takes]


def readers_of(setting: str) -> list[str]:
    """The names of the formats that read ``setting``."""
    return [f.name for f in FORMATS.values() if setting in f.takes]


#: format name -> TableFormat, in the order registered (the order of the choices)
FORMATS: dict[str, TableFormat] = {}


def register(fmt: TableFormat) -> TableFormat:
    """Add ``fmt`` (or replace the format of that name)."""
    unknown = fmt.takes - set(SETTING_OPTIONS)
    if unknown:
        raise ValueError(f"format {fmt.name}: unknown settings {sorted(unknown)}")
    FORMATS[fmt.name] = fmt
    return fmt


def unregister(name: str) -> None:
    """Remove format ``name`` (for formats registered for a while, e.g. in tests)."""
    FORMATS.pop(name, None)


_HERE = "postproc.metrology.controllers"
register(TableFormat("linuxcnc", f"{_HERE}.linuxcnc:from_settings",
                     frozenset({"step", "comp_type", "axis_names"}), folder=True))
register(TableFormat("fanuc", f"{_HERE}.fanuc:from_settings",
                     frozenset({"step", "reference", "return", "parameters", "detection_unit", "axis_names"})))
register(TableFormat("siemens", f"{_HERE}.siemens:from_settings", frozenset({"step", "reference", "axis_names"})))
register(TableFormat("beckhoff", f"{_HERE}.beckhoff:from_settings", frozenset()))
