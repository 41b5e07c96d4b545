"""LinuxCNC joint compensation files (``[JOINT_n] COMP_FILE`` / ``COMP_FILE_TYPE``).

The file holds one ``nominal forward reverse`` triplet per line, in machine units,
nominals ascending; LinuxCNC interpolates linearly between nominals and takes at
most 256 triplets per joint (docs/src/config/ini-config.adoc, [JOINT_n]). The loader
(src/emc/motion/usrmotintf.cc, ``usrmotLoadComp``) reads lines with
``sscanf("%lf %lf %lf")`` and stops at the first line that is not three numbers, so
the file carries no comment. Its meaning, from that loader:

- type 0: forward and reverse are the *actual* positions reached moving in + and in
  -; the loader stores ``nominal - forward`` and ``nominal - reverse``;
- type 1: forward and reverse are those trims themselves, ``nominal - actual``.

Each triplet goes to motion as ``EMCMOT_SET_JOINT_COMP`` (src/emc/motion/command.c),
which drops an entry whose nominal is not above the previous one ("joint %d:
compensation values must increase"): the nominals must be strictly increasing, so
positions that print alike (31.4 from a runs file in mm and 31.400000000000002 from a
table converted from um) are one node.

With a COMP_FILE, LinuxCNC ignores ``BACKLASH``; set it to 0 all the same, so that
removing the file later does not bring back a second backlash compensation.
"""

from __future__ import annotations

import numpy as np

from postproc.errors import CalibrationError, MeasurementError
from postproc.metrology.controllers.axis import AxisErrors, equidistant, mm
from postproc.metrology.controllers.base import Export
from postproc.metrology.controllers.formats import Settings
from postproc.metrology.controllers.roundtrip import check_round_trip

#: LinuxCNC's limit: 256 triplets per joint (ini-config, COMP_FILE).
MAX_TRIPLETS = 256
DEFAULT_JOINTS = {"X": "0", "Y": "1", "Z": "2"}
#: Decimals of every number in the file (mm): a nanometre, finer than any scale.
DECIMALS = 6
#: Resolution of a value read back: forward and reverse are each rounded to DECIMALS,
#: and type 0 takes a difference of two rounded numbers.
RESOLUTION_MM = 10.0 ** -DECIMALS


def export_linuxcnc(axis_errors: list[AxisErrors], *, comp_type: int = 0, step: float | None = None,
                    joints: dict[str, str] | None = None) -> Export:
    joints = {**DEFAULT_JOINTS, **(joints or {})}
    files: dict[str, str] = {}
    exp = Export(files)
    notes = exp.notes
    for e in axis_errors:
        nodes = e.nodes(merge_mm=RESOLUTION_MM) if step is None else equidistant(e.lo, e.hi, step)[0]
        if len(nodes) > MAX_TRIPLETS:
            raise CalibrationError(
                f"axis {e.axis}: {len(nodes)} table positions; LinuxCNC takes at most {MAX_TRIPLETS} per joint",
                hint="give a coarser --step",
            )
        up, down = e.up(nodes), e.down(nodes)
        if comp_type == 0:
            fwd, rev = nodes + up, nodes + down
        else:
            fwd, rev = -up, -down
        name = f"joint{joints[e.axis]}_{e.axis}.comp"
        text = "".join(f"{mm(n, DECIMALS)} {mm(f, DECIMALS)} {mm(r, DECIMALS)}\n"
                       for n, f, r in zip(nodes, fwd, rev, strict=True))
        # round trip: LinuxCNC's loader reads the text back; every node, both directions
        nom, got_up, got_down, errors = linuxcnc_loader(text, comp_type)
        if errors:
            raise CalibrationError(f"round trip of the linuxcnc table of {e.axis}: LinuxCNC would say "
                                   f"{errors[0]}; nothing written", hint="report it with the calibration file")
        check_round_trip(e.axis, "linuxcnc", nom, {"+": got_up, "-": got_down}, {"+": e.up(nom), "-": e.down(nom)},
                         RESOLUTION_MM)
        files[name] = text
        exp.columns.add((e.axis, e.column[:2]))
        if e.backlash:
            exp.backlash.add(e.axis)
        err = e.linear_error(nodes, up, down)
        notes.append(f"{e.axis}: {name}: {len(nodes)} triplets over {nodes[0]:.3f}..{nodes[-1]:.3f} mm, "
                     f"positioning {e.column}{' and backlash' if e.backlash else ''}; linear interpolation "
                     f"between them stays within {err * 1000:.3f} um of the calibration")
        notes.append(f"  [JOINT_{joints[e.axis]}] COMP_FILE = {name}   COMP_FILE_TYPE = {comp_type}   BACKLASH = 0")
    notes.append("LinuxCNC ignores BACKLASH when a COMP_FILE is given; set it to 0 anyway. Units: mm "
                 "([TRAJ] LINEAR_UNITS = mm). The table applies once the joint is homed.")
    return exp


def read_linuxcnc(text: str, comp_type: int, path: str = "") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(nominal, error moving +, error moving -) in mm, read as LinuxCNC's loader does:
    triplets until the first line that is not three numbers; an entry LinuxCNC would
    drop (nominal not increasing) is an error."""
    nom, up, down, errors = linuxcnc_loader(text, comp_type, path)
    if errors:
        raise MeasurementError(errors[0], path=path)
    return nom, up, down


def linuxcnc_loader(text: str, comp_type: int, path: str = "") -> tuple[np.ndarray, np.ndarray, np.ndarray, list]:
    """What LinuxCNC keeps of a comp file: (nominal, error moving +, error moving -, the
    loader's complaints). usrmotLoadComp reads triplets until the first line that is not
    three numbers; motion's SET_JOINT_COMP drops an entry whose nominal is not above the
    last one kept, with "compensation values must increase"."""
    rows: list[tuple[float, float, float]] = []
    errors: list[str] = []
    for line in text.splitlines():
        parts = line.split()
        try:
            nom, fwd, rev = (float(v) for v in parts) if len(parts) == 3 else (None, None, None)
        except ValueError:
            break
        if nom is None or fwd is None or rev is None:
            break
        if rows and nom <= rows[-1][0]:
            errors.append(f"line {len(rows) + len(errors) + 1}: nominal {nom:g} is not above {rows[-1][0]:g}: "
                          "compensation values must increase")
            continue
        rows.append((nom, fwd, rev))
    if len(rows) < 2:
        raise MeasurementError("fewer than 2 compensation triplets", path=path)
    a = np.array(rows)
    trim_f, trim_r = (a[:, 0] - a[:, 1], a[:, 0] - a[:, 2]) if comp_type == 0 else (a[:, 1], a[:, 2])
    return a[:, 0], -trim_f, -trim_r, errors


def from_settings(axis_errors: list[AxisErrors], s: Settings) -> Export:
    """:func:`export_linuxcnc` with ``export``'s settings (the registered builder)."""
    return export_linuxcnc(axis_errors, comp_type=s.comp_type, step=s.step_mm, joints=s.axis_names)
